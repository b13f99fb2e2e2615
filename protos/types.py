"""The data model every room of the trainer speaks: behavior specs and per-step agent data.

These are the types of ``mlagents_envs.base_env`` (BehaviorSpec, ActionSpec, DecisionSteps,
TerminalSteps, ActionTuple), with its names and behaviour (DecisionSteps and TerminalSteps are
read-only mappings from agent id to one agent's step): the trainer, the stub and the
``mlagents_like_envs`` API share this one data model. Steps are frozen dataclasses over numpy
arrays, built once per message by the codec.

Shapes (n = number of agents in the batch):
  DecisionSteps.obs[i]        float32 [n, *observation_specs[i].shape]
  DecisionSteps.reward        float32 [n]
  DecisionSteps.agent_id      int64   [n]   (episode ids, unique within one env connection)
  DecisionSteps.action_mask   list of bool [n, branch_size] per discrete branch (True = masked) or None
  DecisionSteps.group_id      int32   [n]
  DecisionSteps.group_reward  float32 [n]
  TerminalSteps.*             the same, plus interrupted bool [n] (max_step_reached)
  ActionTuple.continuous      float32 [n, continuous_size]
  ActionTuple.discrete        int32   [n, len(discrete_branches)]
"""
from __future__ import annotations

import enum
import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Iterator, NamedTuple

import numpy as np


class DimensionProperty(enum.IntFlag):
    UNSPECIFIED = 0
    NONE = 1
    TRANSLATIONAL_EQUIVARIANCE = 2
    VARIABLE_SIZE = 4


class ObservationType(enum.IntEnum):
    DEFAULT = 0
    GOAL_SIGNAL = 1


class StatsAggregationMethod(enum.IntEnum):
    AVERAGE = 0
    MOST_RECENT = 1
    SUM = 2
    HISTOGRAM = 3


class ObservationSpec(NamedTuple):
    shape: tuple[int, ...]
    dimension_property: tuple[DimensionProperty, ...]
    observation_type: ObservationType
    name: str


_FLOAT32, _INT32 = np.dtype(np.float32), np.dtype(np.int32)  # compared with a dtype: no conversion per call


def _as(values, dtype: np.dtype) -> np.ndarray:
    """``values`` as an array of ``dtype``, converted only when it is another."""
    values = np.asarray(values)
    return values if values.dtype == dtype else values.astype(dtype)


class ActionTuple:
    """Actions of n agents: ``continuous`` float32 [n, c] and ``discrete`` int32 [n, b].

    Either part may be given later (``add_continuous`` / ``add_discrete``, as in mlagents_envs);
    the part not given is then an [n, 0] array. Other dtypes are converted on the way in."""

    __slots__ = ("_continuous", "_discrete")
    discrete_dtype = np.int32

    def __init__(self, continuous: np.ndarray | None = None, discrete: np.ndarray | None = None) -> None:
        # the trainer builds two per decision step, both parts given: no [n, 0] placeholder made
        # only to be replaced
        self._continuous: np.ndarray | None = None if continuous is None else _as(continuous, _FLOAT32)
        self._discrete: np.ndarray | None = None if discrete is None else _as(discrete, _INT32)
        if self._continuous is None and self._discrete is not None:
            self._continuous = np.zeros((len(self._discrete), 0), dtype=np.float32)
        elif self._discrete is None and self._continuous is not None:
            self._discrete = np.zeros((len(self._continuous), 0), dtype=np.int32)

    @property
    def continuous(self) -> np.ndarray | None:
        return self._continuous

    @property
    def discrete(self) -> np.ndarray | None:
        return self._discrete

    def add_continuous(self, continuous: np.ndarray) -> None:
        self._continuous = _as(continuous, _FLOAT32)
        if self._discrete is None:
            self._discrete = np.zeros((len(self._continuous), 0), dtype=np.int32)

    def add_discrete(self, discrete: np.ndarray) -> None:
        self._discrete = _as(discrete, _INT32)
        if self._continuous is None:
            self._continuous = np.zeros((len(self._discrete), 0), dtype=np.float32)

    def __repr__(self) -> str:
        return f"ActionTuple(continuous={self._continuous!r}, discrete={self._discrete!r})"


class ActionSpec(NamedTuple):
    continuous_size: int
    discrete_branches: tuple[int, ...]

    def __str__(self) -> str:
        return f"Continuous: {self.continuous_size}, Discrete: {self.discrete_branches}"

    @property
    def discrete_size(self) -> int:
        return len(self.discrete_branches)

    def is_discrete(self) -> bool:
        """Only discrete actions (an older API's question, kept for ported scripts)."""
        return self.discrete_size > 0 and self.continuous_size == 0

    def is_continuous(self) -> bool:
        """Only continuous actions."""
        return self.discrete_size == 0 and self.continuous_size > 0

    def empty_action(self, n_agents: int) -> ActionTuple:
        """All-zero actions for ``n_agents`` agents."""
        return ActionTuple(
            np.zeros((n_agents, self.continuous_size), dtype=np.float32),
            np.zeros((n_agents, self.discrete_size), dtype=np.int32),
        )

    def random_action(self, n_agents: int) -> ActionTuple:
        """Uniform actions from numpy's global generator: continuous in [-1, 1), each discrete
        branch uniform over its options (so ``np.random.seed`` makes them repeatable)."""
        continuous = np.random.uniform(-1.0, 1.0, size=(n_agents, self.continuous_size))
        discrete = np.zeros((n_agents, self.discrete_size), dtype=np.int32)
        for branch, size in enumerate(self.discrete_branches):
            discrete[:, branch] = np.random.randint(0, size, size=n_agents, dtype=np.int32)
        return ActionTuple(continuous, discrete)

    @staticmethod
    def create_continuous(continuous_size: int) -> "ActionSpec":
        return ActionSpec(continuous_size, ())

    @staticmethod
    def create_discrete(discrete_branches: tuple[int, ...]) -> "ActionSpec":
        return ActionSpec(0, tuple(discrete_branches))

    @staticmethod
    def create_hybrid(continuous_size: int, discrete_branches: tuple[int, ...]) -> "ActionSpec":
        return ActionSpec(continuous_size, tuple(discrete_branches))


class BehaviorSpec(NamedTuple):
    observation_specs: tuple[ObservationSpec, ...]
    action_spec: ActionSpec


class _ByAgentId(Mapping):
    """Read access by agent id (``steps[agent_id]``, ``agent_id in steps``, iteration over the
    ids) on top of the batched arrays; the id → row index is built on first use."""

    @functools.cached_property
    def agent_id_to_index(self) -> dict[int, int]:
        return {agent: row for row, agent in enumerate(self.agent_id.tolist())}

    def _row(self, agent_id: int) -> int:
        try:
            return self.agent_id_to_index[agent_id]
        except (KeyError, TypeError):
            raise KeyError(f"agent_id {agent_id} is not present in the {type(self).__name__}") from None

    def __len__(self) -> int:
        return len(self.agent_id)

    def __iter__(self) -> Iterator[int]:
        yield from self.agent_id


class DecisionStep(NamedTuple):
    """One agent's row of a DecisionSteps."""

    obs: list[np.ndarray]
    reward: float
    agent_id: int
    action_mask: list[np.ndarray] | None
    group_id: int
    group_reward: float


class TerminalStep(NamedTuple):
    """One agent's row of a TerminalSteps."""

    obs: list[np.ndarray]
    reward: float
    interrupted: bool
    agent_id: int
    group_id: int
    group_reward: float


@dataclass(frozen=True, eq=False)
class DecisionSteps(_ByAgentId):
    obs: list[np.ndarray]
    reward: np.ndarray
    agent_id: np.ndarray
    action_mask: list[np.ndarray] | None
    group_id: np.ndarray
    group_reward: np.ndarray

    def __getitem__(self, agent_id: int) -> DecisionStep:
        row = self._row(agent_id)
        return DecisionStep(
            obs=[o[row] for o in self.obs],
            reward=self.reward[row],
            agent_id=agent_id,
            action_mask=None if self.action_mask is None else [m[row] for m in self.action_mask],
            group_id=self.group_id[row],
            group_reward=self.group_reward[row],
        )

    @staticmethod
    def empty(spec: BehaviorSpec) -> "DecisionSteps":
        return DecisionSteps(
            obs=[np.zeros((0, *o.shape), dtype=np.float32) for o in spec.observation_specs],
            reward=np.zeros(0, dtype=np.float32),
            agent_id=np.zeros(0, dtype=np.int64),
            action_mask=None,
            group_id=np.zeros(0, dtype=np.int32),
            group_reward=np.zeros(0, dtype=np.float32),
        )


@dataclass(frozen=True, eq=False)
class TerminalSteps(_ByAgentId):
    obs: list[np.ndarray]
    reward: np.ndarray
    interrupted: np.ndarray
    agent_id: np.ndarray
    group_id: np.ndarray
    group_reward: np.ndarray

    def __getitem__(self, agent_id: int) -> TerminalStep:
        row = self._row(agent_id)
        return TerminalStep(
            obs=[o[row] for o in self.obs],
            reward=self.reward[row],
            interrupted=self.interrupted[row],
            agent_id=agent_id,
            group_id=self.group_id[row],
            group_reward=self.group_reward[row],
        )

    @staticmethod
    def empty(spec: BehaviorSpec) -> "TerminalSteps":
        return TerminalSteps(
            obs=[np.zeros((0, *o.shape), dtype=np.float32) for o in spec.observation_specs],
            reward=np.zeros(0, dtype=np.float32),
            interrupted=np.zeros(0, dtype=bool),
            agent_id=np.zeros(0, dtype=np.int64),
            group_id=np.zeros(0, dtype=np.int32),
            group_reward=np.zeros(0, dtype=np.float32),
        )


def brain_name_of(behavior_name: str) -> tuple[str, int]:
    """Split a fully qualified behavior name ``Name?team=3`` into (brain name, team id)."""
    if "?" not in behavior_name:
        return behavior_name, 0
    name, query = behavior_name.split("?", 1)
    team = 0
    for part in query.split("&"):
        key, _, value = part.partition("=")
        if key == "team":
            try:
                team = int(value)
            except ValueError:
                team = 0
    return name, team


@dataclass
class StepResult:
    """Everything one env produced in one exchange, decoded once."""

    specs: dict[str, BehaviorSpec] = field(default_factory=dict)  # specs first seen in this message
    steps: dict[str, tuple[DecisionSteps, TerminalSteps]] = field(default_factory=dict)
    side_channel: bytes = b""
    # per behavior of ``specs``: each observation's compression ("none" or "png"), as its first agent sent it
    compressions: dict[str, tuple[str, ...]] = field(default_factory=dict)
    # behaviors some of whose agents were left out for NaN/Inf: {behavior: trainer.protocol.codec.Dropped}
    dropped: dict = field(default_factory=dict)
