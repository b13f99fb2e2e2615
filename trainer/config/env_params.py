"""Environment parameters: samplers, curriculum lessons and their YAML structuring (docs/configuration.md,
"environment_parameters"; seeds: docs/protocol.md, "Sampler seeds").

A parameter is always stored as a curriculum. A plain number or a sampler becomes a one-lesson
curriculum whose lesson is named after the parameter; ``configuration.yaml`` shows that form.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass, field
from typing import Any, ClassVar, Collection, Mapping, Union

from trainer.config.strict import (
    check_known_keys,
    describe_value,
    join_path,
    require_mapping,
    structure,
    suggestion,
    to_choice,
    to_float,
    to_str,
)
from trainer.errors import ConfigError

logger = logging.getLogger("mlagents_like")


@dataclass(frozen=True)
class ConstantSampler:
    """A fixed float. Sent over the side channel as a FLOAT, not as a sampler."""

    value: float = 0.0
    seed: int = -1
    sampler_type: ClassVar[str] = "constant"

    def __str__(self) -> str:
        return f"Float: value={self.value}"


@dataclass(frozen=True)
class UniformSampler:
    """Uniform on [min_value, max_value]. Side-channel sampler type 0."""

    min_value: float = 0.0
    max_value: float = 1.0
    seed: int = -1
    sampler_type: ClassVar[str] = "uniform"

    def __str__(self) -> str:
        return f"Uniform sampler: min={self.min_value}, max={self.max_value}"


@dataclass(frozen=True)
class GaussianSampler:
    """Normal(mean, st_dev). Side-channel sampler type 1."""

    mean: float = 1.0
    st_dev: float = 1.0
    seed: int = -1
    sampler_type: ClassVar[str] = "gaussian"

    def __str__(self) -> str:
        return f"Gaussian sampler: mean={self.mean}, stddev={self.st_dev}"


@dataclass(frozen=True)
class MultiRangeUniformSampler:
    """Uniform over a union of intervals ((min0, max0), (min1, max1), ...). Side-channel type 2."""

    intervals: tuple[tuple[float, float], ...] = ((0.0, 1.0),)
    seed: int = -1
    sampler_type: ClassVar[str] = "multirangeuniform"

    def __str__(self) -> str:
        return f"MultiRangeUniform sampler: intervals={[list(pair) for pair in self.intervals]}"


@dataclass(frozen=True)
class HmmSampler:
    """``count`` label sequences of ``length`` drawn from a hidden Markov model (the runner thesis'
    level generator, ``unity_stub_env.hmm``; docs/stub-tasks.md, "Seed projects"): the model file
    ``model`` (written by ``unity-stub-env hmm train``; a relative path is read from the working
    directory) or one trained on the inline ``corpus`` lines with ``states`` states (fast method,
    5 restarts). Drawn once per seed with the alias sampler and sent as plain float parameters
    ``KEY.count``, ``KEY.length``, ``KEY.labels`` and ``KEY.0`` … ``KEY.{count*length-1}`` (label
    codes = positions in the model's sorted labels; docs/protocol.md, "Label sequences")."""

    model: str = ""
    corpus: tuple[str, ...] = ()
    states: int = 5
    length: int = 20
    count: int = 1
    seed: int = -1
    sampler_type: ClassVar[str] = "hmm"

    def __str__(self) -> str:
        source = f"model={self.model}" if self.model else f"corpus of {len(self.corpus)} lines, states={self.states}"
        return f"HMM sampler: {source}, {self.count} sequence(s) of length {self.length}"


MAX_HMM_VALUES = 100_000  # count * length: each value is one side-channel message of ~20 bytes

Sampler = Union[ConstantSampler, UniformSampler, GaussianSampler, MultiRangeUniformSampler, HmmSampler]
SAMPLER_TYPES: dict[str, type] = {
    cls.sampler_type: cls
    for cls in (UniformSampler, GaussianSampler, MultiRangeUniformSampler, ConstantSampler, HmmSampler)
}
MEASURES = ("progress", "reward")


@dataclass(frozen=True)
class CompletionCriteria:
    """When a lesson is done. ``threshold`` is a fraction of max_steps for ``progress``."""

    behavior: str
    measure: str = field(default="reward", metadata={"choices": MEASURES})
    min_lesson_length: int = 0
    signal_smoothing: bool = True
    threshold: float = 0.0
    require_reset: bool = False
    required_keys: ClassVar[tuple[str, ...]] = ("behavior",)


@dataclass(frozen=True)
class Lesson:
    name: str
    value: Sampler
    completion_criteria: CompletionCriteria | None = None


@dataclass(frozen=True)
class EnvironmentParameterSettings:
    """The ordered lessons of one parameter; a plain value is a one-lesson curriculum."""

    curriculum: tuple[Lesson, ...]


# ---------------------------------------------------------------------------------------------
# YAML -> dataclasses


def structure_sampler(raw: Any, path: str) -> Sampler:
    """A number (constant) or ``{sampler_type, sampler_parameters}`` → sampler, with range checks."""
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        return ConstantSampler(value=float(raw))
    raw = require_mapping(raw, path, "a number or {sampler_type, sampler_parameters}")
    if not raw:
        raise ConfigError(f"'{path}' must be a number or {{sampler_type, sampler_parameters}}, got an empty mapping.")
    check_known_keys(raw, ("sampler_type", "sampler_parameters"), path)
    if "sampler_type" not in raw:
        raise ConfigError(f"'{join_path(path, 'sampler_type')}' is required but missing.")
    kind = to_choice(raw["sampler_type"], join_path(path, "sampler_type"), tuple(SAMPLER_TYPES))
    params_path = join_path(path, "sampler_parameters")
    params = require_mapping(raw.get("sampler_parameters"), params_path)
    hooks = {"intervals": _structure_intervals, "corpus": _structure_corpus}
    sampler = structure(SAMPLER_TYPES[kind], params, params_path, hooks)
    if isinstance(sampler, HmmSampler):
        _check_hmm_sampler(sampler, params_path)
    if isinstance(sampler, UniformSampler) and sampler.min_value > sampler.max_value:
        raise ConfigError(
            f"'{params_path}': min_value {sampler.min_value} is greater than max_value {sampler.max_value}."
        )
    if isinstance(sampler, GaussianSampler) and sampler.st_dev < 0:
        raise ConfigError(f"'{params_path}.st_dev' must be >= 0, got {sampler.st_dev}.")
    return sampler


def _structure_corpus(raw: Any, path: str) -> tuple[str, ...]:
    if isinstance(raw, str):
        raw = raw.splitlines()
    if not isinstance(raw, list) or not all(isinstance(line, str) for line in raw):
        raise ConfigError(f"'{path}' must be a list of sequences, each a string of labels separated by "
                          f"spaces, got {describe_value(raw)}.")
    return tuple(raw)


def _check_hmm_sampler(sampler: HmmSampler, path: str) -> None:
    """Exactly one of model/corpus, sane sizes, and a model that loads (so a bad one stops the run
    before anything is launched)."""
    if bool(sampler.model) == bool(sampler.corpus):
        raise ConfigError(f"'{path}' needs exactly one of 'model' (a file written by 'unity-stub-env hmm "
                          "train') or 'corpus' (a list of label sequences).")
    for key in ("length", "count", "states"):
        if getattr(sampler, key) < 1:
            raise ConfigError(f"'{path}.{key}' must be >= 1, got {getattr(sampler, key)}.")
    if sampler.count * sampler.length > MAX_HMM_VALUES:
        raise ConfigError(f"'{path}': count * length = {sampler.count * sampler.length} values is more than "
                          f"{MAX_HMM_VALUES} (each is one side-channel message); send fewer or shorter sequences.")
    from unity_stub_env import HmmError

    try:
        hmm_model(sampler)
    except HmmError as error:
        raise ConfigError(f"'{path}': {error}") from None


def hmm_model(sampler: HmmSampler):
    """The ``unity_stub_env.hmm.Hmm`` of an hmm sampler (loaded or trained; HmmError if it cannot be)."""
    return _hmm_model(sampler.model, sampler.corpus, sampler.states)


@functools.lru_cache(maxsize=16)
def _hmm_model(model: str, corpus: tuple[str, ...], states: int):
    from unity_stub_env import Hmm, parse_corpus, train_hmm

    if model:
        return Hmm.load(model)
    return train_hmm(parse_corpus("\n".join(corpus), "the sampler's corpus"), num_states=states, restarts=5, seed=0)


@functools.lru_cache(maxsize=16)
def hmm_sequences(sampler: HmmSampler):
    """int64 [count, length]: the label codes the sampler sends (the same for the same seed)."""
    import numpy as np

    return hmm_model(sampler).sample_codes(sampler.count, sampler.length, np.random.default_rng(sampler.seed))


def _structure_intervals(raw: Any, path: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"'{path}' must be a non-empty list of [min, max] pairs, got {describe_value(raw)}.")
    intervals = []
    for i, pair in enumerate(raw):
        item_path = f"{path}[{i}]"
        if not isinstance(pair, list) or len(pair) != 2:
            raise ConfigError(f"'{item_path}' must be a [min, max] pair, got {describe_value(pair)}.")
        low, high = to_float(pair[0], item_path), to_float(pair[1], item_path)
        if low > high:
            raise ConfigError(f"'{item_path}': minimum {low} is greater than maximum {high}.")
        intervals.append((low, high))
    return tuple(intervals)


def structure_completion_criteria(raw: Any, path: str) -> CompletionCriteria:
    hooks = {"behavior": lambda v, p: to_str(v, p)}
    criteria = structure(CompletionCriteria, raw, path, hooks)
    if criteria.measure == "progress" and not 0.0 <= criteria.threshold <= 1.0:
        raise ConfigError(
            f"'{path}.threshold' must be in [0, 1] when measure is progress, got {criteria.threshold}."
        )
    if criteria.min_lesson_length < 0:
        raise ConfigError(f"'{path}.min_lesson_length' must be >= 0, got {criteria.min_lesson_length}.")
    return criteria


def structure_lesson(raw: Any, path: str) -> Lesson:
    raw = require_mapping(raw, path, "a lesson {name, value, completion_criteria}")
    if len(raw) == 1 and "name" not in raw and isinstance(next(iter(raw.values())), Mapping):
        # The upgrade script (and old example configs) write '- Lesson0: {value, ...}'. The
        # reference loader rejects it; we read it as '- {name: Lesson0, value, ...}'.
        only, body = next(iter(raw.items()))
        logger.warning(
            "'%s' is written as '%s: {...}'; reading it as a lesson named '%s'. "
            "Write 'name: %s' beside 'value' to silence this warning.", path, only, only, only,
        )
        raw = {"name": str(only), **body}
    check_known_keys(raw, ("name", "value", "completion_criteria"), path)
    for key in ("name", "value"):
        if raw.get(key) is None:
            raise ConfigError(f"'{join_path(path, key)}' is required but missing.")
    criteria_raw = raw.get("completion_criteria")
    criteria = None
    if criteria_raw is not None:
        criteria = structure_completion_criteria(criteria_raw, join_path(path, "completion_criteria"))
    return Lesson(
        name=to_str(raw["name"], join_path(path, "name")),
        value=structure_sampler(raw["value"], join_path(path, "value")),
        completion_criteria=criteria,
    )


def structure_parameter(name: str, raw: Any, path: str) -> EnvironmentParameterSettings:
    """One parameter in any of the three forms of docs/configuration.md, "environment_parameters", checked as
    a lesson chain."""
    if not (isinstance(raw, Mapping) and "curriculum" in raw):
        return EnvironmentParameterSettings((Lesson(name=name, value=structure_sampler(raw, path)),))
    check_known_keys(raw, ("curriculum",), path)
    lessons_raw = raw["curriculum"]
    curriculum_path = join_path(path, "curriculum")
    if not isinstance(lessons_raw, list) or not lessons_raw:
        raise ConfigError(f"'{curriculum_path}' must be a non-empty list of lessons, got {describe_value(lessons_raw)}.")
    lessons = [structure_lesson(item, f"{curriculum_path}[{i}]") for i, item in enumerate(lessons_raw)]
    for i, lesson in enumerate(lessons[:-1]):
        if lesson.completion_criteria is None:
            raise ConfigError(
                f"'{curriculum_path}[{i}]' (lesson '{lesson.name}') is not the last lesson and needs completion_criteria."
            )
    if lessons[-1].completion_criteria is not None:
        logger.warning(
            "The final lesson '%s' of environment parameter '%s' has completion_criteria; they are ignored.",
            lessons[-1].name,
            name,
        )
        lessons[-1] = dataclasses.replace(lessons[-1], completion_criteria=None)
    return EnvironmentParameterSettings(tuple(lessons))


def structure_environment_parameters(
    raw: Any,
    path: str = "environment_parameters",
    behavior_names: Collection[str] | None = None,
) -> dict[str, EnvironmentParameterSettings]:
    """The whole ``environment_parameters`` block. ``behavior_names``: if given, every curriculum
    criterion must name one of them."""
    raw = require_mapping(raw, path)
    params = {str(name): structure_parameter(str(name), value, join_path(path, name)) for name, value in raw.items()}
    if behavior_names is not None:
        _check_criteria_behaviors(params, behavior_names, path)
    return params


def _check_criteria_behaviors(
    params: Mapping[str, EnvironmentParameterSettings], behavior_names: Collection[str], path: str
) -> None:
    for name, settings in params.items():
        for i, lesson in enumerate(settings.curriculum):
            criteria = lesson.completion_criteria
            if criteria is not None and criteria.behavior not in behavior_names:
                where = f"{path}.{name}.curriculum[{i}].completion_criteria.behavior"
                raise ConfigError(
                    f"'{where}' names behavior '{criteria.behavior}', which is not configured."
                    f"{suggestion(criteria.behavior, behavior_names)} "
                    f"Configured behaviors: {', '.join(behavior_names)}."
                )


# ---------------------------------------------------------------------------------------------
# dataclasses -> YAML, seeds


def sampler_as_dict(sampler: Sampler) -> dict:
    """``{sampler_type, sampler_parameters: {seed, ...}}`` as configuration.yaml writes it."""
    parameters: dict[str, Any] = {"seed": sampler.seed}
    for f in dataclasses.fields(sampler):
        if f.name != "seed":
            value = getattr(sampler, f.name)
            parameters[f.name] = ([list(pair) for pair in value] if f.name == "intervals"
                                  else list(value) if f.name == "corpus" else value)
    return {"sampler_type": sampler.sampler_type, "sampler_parameters": parameters}


def environment_parameters_as_dict(params: Mapping[str, EnvironmentParameterSettings]) -> dict:
    """The expanded one-lesson-curriculum form of docs/configuration.md, "environment_parameters", key order
    as the reference writes it."""
    out = {}
    for name, settings in params.items():
        lessons = []
        for lesson in settings.curriculum:
            criteria = lesson.completion_criteria
            lessons.append(
                {
                    "value": sampler_as_dict(lesson.value),
                    "name": lesson.name,
                    "completion_criteria": None if criteria is None else dataclasses.asdict(criteria),
                }
            )
        out[name] = {"curriculum": lessons}
    return out


def assign_seeds(
    params: Mapping[str, EnvironmentParameterSettings], run_seed: int
) -> dict[str, EnvironmentParameterSettings]:
    """A copy where every lesson value with seed -1 gets ``run_seed + offset`` (docs/protocol.md, "Sampler seeds").

    The offset starts at 0 and grows by 1 for each such value, constants included, in parameter
    order and then lesson order. Values with an explicit seed keep it and use no offset.
    """
    offset = 0
    seeded: dict[str, EnvironmentParameterSettings] = {}
    for name, settings in params.items():
        lessons = []
        for lesson in settings.curriculum:
            if lesson.value.seed == -1:
                lesson = dataclasses.replace(lesson, value=dataclasses.replace(lesson.value, seed=run_seed + offset))
                offset += 1
            lessons.append(lesson)
        seeded[name] = EnvironmentParameterSettings(tuple(lessons))
    return seeded


__all__ = [
    "ConstantSampler",
    "UniformSampler",
    "GaussianSampler",
    "MultiRangeUniformSampler",
    "HmmSampler",
    "hmm_sequences",
    "Sampler",
    "CompletionCriteria",
    "Lesson",
    "EnvironmentParameterSettings",
    "structure_environment_parameters",
    "environment_parameters_as_dict",
    "sampler_as_dict",
    "assign_seeds",
]
