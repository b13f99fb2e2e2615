"""``mlagents-like-learn CONFIG --check --spec FILE``: the trainer YAML against a game's behavior
specs (a behaviors.json, docs/mirror.md), without a simulator and without training.

What the YAML alone gets wrong (batch_size > buffer_size, sequence_length > batch_size, unknown
keys, ...) the loader refuses before this runs, with its usual one-line message and exit 2.

``spec_problems`` returns one line per problem; ``run_check`` prints them and gives the exit code
(0: none, 2: some). What is checked is listed in docs/mirror.md ("Checking a YAML").
"""
from __future__ import annotations

import logging
import sys

from protos.spec_file import SpecFile, SpecFileError
from trainer.config.settings import ENCODER_MIN_SIZE, RunOptions, TrainerSettings
from trainer.errors import ConfigError

logger = logging.getLogger("mlagents_like")


def spec_problems(options: RunOptions, spec: SpecFile) -> list[str]:
    """Every mismatch between ``options`` (the loaded YAML with the flags) and ``spec``."""
    problems: list[str] = []
    config = options.config_path or "the configuration"
    brains = spec.brain_names
    for brain in brains:
        if brain not in options.behaviors:
            fallback = ("would train with default_settings" if options.default_settings is not None
                        else "has no settings (the run would stop at it)" if options.config_path
                        else "would train with the built-in defaults")
            problems.append(f"behavior '{brain}' is in the spec but not under 'behaviors' in {config}: it "
                            f"{fallback}; add 'behaviors.{brain}' (or fix the name).")
    for name in options.behaviors:
        if name not in brains:
            problems.append(f"'behaviors.{name}' in {config} names no behavior of the spec (it has "
                            f"{', '.join(brains)}): renamed in the scene?")
    for brain in brains:
        settings = options.behaviors.get(brain) or options.default_settings or TrainerSettings()
        problems += _settings_problems(brain, settings, spec)
    for name, parameter in options.environment_parameters.items():
        for index, lesson in enumerate(parameter.curriculum):
            criteria = lesson.completion_criteria
            if criteria is not None and criteria.behavior not in brains:
                problems.append(f"'environment_parameters.{name}.curriculum[{index}].completion_criteria."
                                f"behavior' names '{criteria.behavior}', which is not a behavior of the spec "
                                f"({', '.join(brains)}).")
    areas = options.env_settings.num_areas
    if areas > spec.num_areas:
        for record in spec.behaviors:
            per_area = record.agents_per_area or record.agents
            problems.append(f"--num-areas {areas} x {per_area} agent(s) of '{record.name}' = {areas * per_area} "
                            f"agents, but the spec saw {record.agents} ({spec.num_areas} area(s)): the game "
                            f"may not hold that many; capture the spec with --num-areas {areas}.")
    return problems


def _settings_problems(brain: str, ts: TrainerSettings, spec: SpecFile) -> list[str]:
    where = f"behaviors.{brain}"
    found = []
    hp = ts.hyperparameters  # batch_size > buffer_size and sequence_length > batch_size: the loader refuses them
    memory = ts.network_settings.memory
    if memory is not None:
        if memory.sequence_length > ts.time_horizon:
            found.append(f"'{where}.network_settings.memory.sequence_length' ({memory.sequence_length}) is "
                         f"longer than time_horizon ({ts.time_horizon}): every sequence is mostly padding; "
                         f"use a sequence_length <= time_horizon.")
        if hp.batch_size % memory.sequence_length:  # (longer than batch_size: the loader refuses it)
            found.append(f"'{where}.hyperparameters.batch_size' ({hp.batch_size}) is not a multiple of "
                         f"memory.sequence_length ({memory.sequence_length}): it is rounded down to "
                         f"{hp.batch_size - hp.batch_size % memory.sequence_length}.")
    encoder = ts.network_settings.vis_encode_type
    minimum = ENCODER_MIN_SIZE.get(encoder, 1)
    for record in spec.behaviors:
        if record.brain_name != brain:
            continue
        for obs in record.spec.observation_specs:
            if len(obs.shape) == 3 and min(obs.shape[1:]) < minimum:
                found.append(f"'{where}.network_settings.vis_encode_type' {encoder} needs cameras of at least "
                             f"{minimum}x{minimum}, but '{record.name}' observation '{obs.name}' is "
                             f"{obs.shape[1]}x{obs.shape[2]} (C, H, W = {list(obs.shape)}); choose "
                             f"{_encoders_for(min(obs.shape[1:]))} or a larger camera.")
        break
    return found


def _encoders_for(side: int) -> str:
    return " or ".join(name for name, size in ENCODER_MIN_SIZE.items() if size <= side)


def check_spec_path(options: RunOptions) -> str:
    """The spec file of a --check: --spec FILE, else the FILE of --env stub:mirror=FILE."""
    from trainer.envs.launcher import mirror_spec_path

    path = options.spec_path or mirror_spec_path(options.env_settings.env_path)
    if path is None:
        raise ConfigError("--check needs the game's behavior specs: --spec FILE (a behaviors.json) or "
                          "--env stub:mirror=FILE; capture one with --capture-spec FILE --env BUILD.")
    return path


def run_check(options: RunOptions, out=None) -> int:
    """Print one line per problem (or one OK line) to ``out`` (stdout); 0 if none, else 2."""
    out = out or sys.stdout
    path = check_spec_path(options)
    try:
        spec = SpecFile.load(path)
    except SpecFileError as error:
        raise ConfigError(str(error)) from None
    problems = spec_problems(options, spec)
    for problem in problems:
        print(f"{path}: {problem}", file=out)
    if not problems:
        print(f"{path}: {options.config_path or 'the default settings'} fits the {len(spec.behaviors)} "
              f"behavior(s) of the spec ({', '.join(b.name for b in spec.behaviors)}).", file=out)
    return 2 if problems else 0
