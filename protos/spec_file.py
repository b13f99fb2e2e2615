"""``behaviors.json``: the behavior specs a run met, as the trainer records them and the stub's
``mirror`` task replays them (format documented in docs/mirror.md).

The file is plain JSON, versioned by ``format_version``; a reader refuses a newer major version.
It uses the spec types of ``protos.types`` (one data model): a behavior is its fully qualified
name (``Name?team=N``), its ``BehaviorSpec``, plus what the protocol shows about it (observation
compressions, agents, groups, whether it sends action masks) and what is known only sometimes
(``decision_period``, ``max_step``: ``null`` when the trainer could not see them; edit the file
to set them).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType, brain_name_of

FORMAT_VERSION = 1
COMPRESSIONS = ("none", "png")  # ObservationProto.compression_type NONE 0, PNG 1
# dimension_properties a hand-written entry gets, by rank, as Unity's sensors send them: a vector
# (NONE), an entity list (VARIABLE_SIZE, NONE), a C x H x W camera (NONE, TRANSLATIONAL_EQUIVARIANCE x 2)
_DEFAULT_PROPERTIES = {1: [1], 2: [4, 1], 3: [1, 2, 2]}


class SpecFileError(ValueError):
    """A behaviors.json that cannot be read: the message names the file and the bad entry."""


@dataclass(frozen=True)
class BehaviorRecord:
    """One behavior (one team of it) as a simulator presented it."""

    name: str  # fully qualified: Name?team=N
    spec: BehaviorSpec
    compressions: tuple[str, ...]  # per observation: "none" or "png"
    agents: int  # agents of this behavior in one simulator
    agents_per_area: int | None = None  # agents / num_areas when that divides, else None
    groups_per_area: int = 0  # distinct non-zero group ids per area (0: no groups)
    action_mask: bool = False  # the simulator sent action masks
    decision_period: int | None = None  # control steps between decisions, when known
    max_step: int | None = None  # control steps before an episode is interrupted, when known

    @property
    def brain_name(self) -> str:
        return brain_name_of(self.name)[0]

    @property
    def team_id(self) -> int:
        return brain_name_of(self.name)[1]


@dataclass(frozen=True)
class SpecFile:
    behaviors: tuple[BehaviorRecord, ...]
    num_areas: int = 1  # the num_areas the simulator was asked for when the spec was captured
    environment_parameters: tuple[str, ...] = ()  # keys the trainer sent
    stats: tuple[str, ...] = ()  # custom stats keys the simulator sent
    source: str = ""  # --env of the capture
    format_version: int = FORMAT_VERSION
    extra: dict = field(default_factory=dict, compare=False)

    def behavior(self, name: str) -> BehaviorRecord | None:
        return next((b for b in self.behaviors if b.name == name), None)

    @property
    def brain_names(self) -> tuple[str, ...]:
        """Behavior names without ``?team=``, in file order, each once."""
        return tuple(dict.fromkeys(b.brain_name for b in self.behaviors))

    # ------------------------------------------------------------------------------------
    def as_dict(self) -> dict[str, Any]:
        return {
            "format_version": self.format_version,
            "source": self.source,
            "num_areas": self.num_areas,
            "behaviors": [_behavior_as_dict(b) for b in self.behaviors],
            "environment_parameters": list(self.environment_parameters),
            "stats": list(self.stats),
        }

    def dumps(self) -> str:
        return json.dumps(self.as_dict(), indent=2) + "\n"

    @staticmethod
    def loads(text: str, where: str = "behaviors.json") -> "SpecFile":
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as error:
            raise SpecFileError(f"{where} is not valid JSON ({error}).") from None
        return SpecFile.from_dict(raw, where)

    @staticmethod
    def load(path: str) -> "SpecFile":
        """Read ``path``; SpecFileError for a missing or malformed file."""
        try:
            with open(path, encoding="utf-8") as f:
                text = f.read()
        except OSError as error:
            raise SpecFileError(f"cannot read the behavior spec file {path!r} ({error.strerror}).") from None
        return SpecFile.loads(text, path)

    @staticmethod
    def from_dict(raw: Any, where: str = "behaviors.json") -> "SpecFile":
        if not isinstance(raw, dict):
            raise SpecFileError(f"{where}: expected a JSON object with 'format_version' and 'behaviors'.")
        version = raw.get("format_version")
        if not isinstance(version, int) or version < 1 or version > FORMAT_VERSION:
            raise SpecFileError(f"{where}: format_version {version!r} is not supported (this version reads "
                                f"1..{FORMAT_VERSION}); capture the spec again with this mlagents-like.")
        behaviors = raw.get("behaviors")
        if not isinstance(behaviors, list) or not behaviors:
            raise SpecFileError(f"{where}: 'behaviors' must be a non-empty list.")
        records = tuple(_behavior_from_dict(b, f"{where}: behaviors[{i}]") for i, b in enumerate(behaviors))
        names = [b.name for b in records]
        if len(set(names)) != len(names):
            raise SpecFileError(f"{where}: a behavior name appears twice in 'behaviors' ({', '.join(names)}).")
        num_areas = _int(raw.get("num_areas", 1), f"{where}: num_areas", minimum=1)
        return SpecFile(
            behaviors=records, num_areas=num_areas,
            environment_parameters=tuple(map(str, raw.get("environment_parameters") or ())),
            stats=tuple(map(str, raw.get("stats") or ())), source=str(raw.get("source", "")),
            format_version=version,
        )


def _behavior_as_dict(b: BehaviorRecord) -> dict[str, Any]:
    return {
        "name": b.name,
        "observations": [
            {"name": o.name, "shape": list(o.shape),
             "dimension_properties": [int(p) for p in o.dimension_property],
             "observation_type": ObservationType(o.observation_type).name.lower(), "compression": c}
            for o, c in zip(b.spec.observation_specs, b.compressions)
        ],
        "actions": {"continuous": b.spec.action_spec.continuous_size,
                    "discrete_branches": list(b.spec.action_spec.discrete_branches)},
        "agents": b.agents,
        "agents_per_area": b.agents_per_area,
        "groups_per_area": b.groups_per_area,
        "action_mask": b.action_mask,
        "decision_period": b.decision_period,
        "max_step": b.max_step,
    }


def _behavior_from_dict(raw: Any, where: str) -> BehaviorRecord:
    if not isinstance(raw, dict):
        raise SpecFileError(f"{where}: expected an object.")
    name = raw.get("name")
    if not isinstance(name, str) or not name or not brain_name_of(name)[0]:
        raise SpecFileError(f"{where}: 'name' must be a behavior name such as 'Walker?team=0'.")
    if "?team=" not in name:
        name = f"{name}?team=0"
    where = f"{where} ({name})"
    observations, compressions = [], []
    for index, obs in enumerate(raw.get("observations") or []):
        at = f"{where}: observations[{index}]"
        if not isinstance(obs, dict):
            raise SpecFileError(f"{at}: expected an object with 'shape'.")
        shape = obs.get("shape")
        if not isinstance(shape, list) or not shape or not all(isinstance(d, int) and d > 0 for d in shape):
            raise SpecFileError(f"{at}: 'shape' must be a list of positive integers, got {shape!r}.")
        props = obs.get("dimension_properties") or _DEFAULT_PROPERTIES.get(len(shape), [0] * len(shape))
        try:
            dims = tuple(DimensionProperty(int(p)) for p in props)
            obs_type = ObservationType[str(obs.get("observation_type", "default")).upper()]
        except (KeyError, ValueError, TypeError):
            raise SpecFileError(f"{at}: bad 'dimension_properties' {props!r} or 'observation_type' "
                                f"{obs.get('observation_type')!r} (default or goal_signal).") from None
        if len(dims) != len(shape):
            raise SpecFileError(f"{at}: 'dimension_properties' needs one entry per dimension of {shape}.")
        compression = str(obs.get("compression", "none")).lower()
        if compression not in COMPRESSIONS or (compression == "png" and len(shape) != 3):
            raise SpecFileError(f"{at}: 'compression' must be one of {', '.join(COMPRESSIONS)} "
                                "(png only for rank-3 C x H x W cameras).")
        observations.append(ObservationSpec(tuple(shape), dims, obs_type, str(obs.get("name", ""))))
        compressions.append(compression)
    if not observations:
        raise SpecFileError(f"{where}: 'observations' must list at least one observation.")
    actions = raw.get("actions") or {}
    continuous = _int(actions.get("continuous", 0), f"{where}: actions.continuous", minimum=0)
    branches = actions.get("discrete_branches") or []
    if not isinstance(branches, list) or not all(isinstance(s, int) and s > 0 for s in branches):
        raise SpecFileError(f"{where}: actions.discrete_branches must be a list of positive integers.")
    if continuous == 0 and not branches:
        raise SpecFileError(f"{where}: 'actions' has neither continuous actions nor discrete branches.")
    agents = _int(raw.get("agents", 1), f"{where}: agents", minimum=1)
    per_area = raw.get("agents_per_area")
    return BehaviorRecord(
        name=name, spec=BehaviorSpec(tuple(observations), ActionSpec(continuous, tuple(branches))),
        compressions=tuple(compressions), agents=agents,
        agents_per_area=None if per_area is None else _int(per_area, f"{where}: agents_per_area", minimum=1),
        groups_per_area=_int(raw.get("groups_per_area", 0) or 0, f"{where}: groups_per_area", minimum=0),
        action_mask=bool(raw.get("action_mask", False)),
        decision_period=_optional_int(raw.get("decision_period"), f"{where}: decision_period"),
        max_step=_optional_int(raw.get("max_step"), f"{where}: max_step", minimum=0),
    )


def _int(value: Any, where: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise SpecFileError(f"{where} must be an integer >= {minimum}, got {value!r}.")
    return value


def _optional_int(value: Any, where: str, minimum: int = 1) -> int | None:
    return None if value is None else _int(value, where, minimum)
