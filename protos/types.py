"""The data model every room of the trainer speaks: behavior specs and per-step agent data.

These mirror the names ML-Agents users know from ``mlagents_envs.base_env`` (BehaviorSpec,
DecisionSteps, TerminalSteps, ActionTuple) so a newcomer can map one onto the other, but they
are plain frozen dataclasses over numpy arrays, built once per message by the codec.

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
from dataclasses import dataclass, field
from typing import NamedTuple

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


@dataclass(frozen=True)
class ActionSpec:
    continuous_size: int
    discrete_branches: tuple[int, ...]

    @property
    def discrete_size(self) -> int:
        return len(self.discrete_branches)

    def empty_action(self, n: int) -> "ActionTuple":
        return ActionTuple(
            np.zeros((n, self.continuous_size), dtype=np.float32),
            np.zeros((n, self.discrete_size), dtype=np.int32),
        )


@dataclass(frozen=True)
class BehaviorSpec:
    observation_specs: tuple[ObservationSpec, ...]
    action_spec: ActionSpec


class ActionTuple(NamedTuple):
    continuous: np.ndarray  # float32 [n, continuous_size]
    discrete: np.ndarray  # int32 [n, num_branches]


@dataclass(frozen=True)
class DecisionSteps:
    obs: list[np.ndarray]
    reward: np.ndarray
    agent_id: np.ndarray
    action_mask: list[np.ndarray] | None
    group_id: np.ndarray
    group_reward: np.ndarray

    def __len__(self) -> int:
        return len(self.agent_id)

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


@dataclass(frozen=True)
class TerminalSteps:
    obs: list[np.ndarray]
    reward: np.ndarray
    interrupted: np.ndarray
    agent_id: np.ndarray
    group_id: np.ndarray
    group_reward: np.ndarray

    def __len__(self) -> int:
        return len(self.agent_id)

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
