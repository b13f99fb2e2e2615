"""The trajectory handed over by the rollout, and the PPO update buffer.

The update buffer keeps one growing list of arrays per field and concatenates them only when an
update starts, so appending a trajectory costs no copy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class Trajectory:
    """T consecutive experiences of one agent (cut at time_horizon or at the end of its episode)."""

    obs: list[np.ndarray]  # per observation, float32 [T, *shape]: what the agent saw when it acted
    next_obs: list[np.ndarray]  # per observation, float32 [*shape]: after the last step (terminal or current)
    rewards: np.ndarray  # float32 [T]: reward that arrived after action t (already including group_reward)
    continuous_actions: np.ndarray  # float32 [T, c]: raw (unclamped) samples
    discrete_actions: np.ndarray  # int [T, b]
    log_probs: np.ndarray  # float32 [T, c + b]
    action_masks: np.ndarray | None  # bool [T, sum(branches)], True = masked; None = nothing masked
    done: bool  # the trajectory ends its episode
    interrupted: bool  # the episode ended by max_step_reached: bootstrap anyway
    episode: Any = None  # identifies the agent's episode across its trajectories (per-episode sums)
    memories: np.ndarray | None = None  # float32 [T, memory_size]: each action's input memory (LSTM)
    group: "GroupColumns | None" = None  # the agent's teammates (rollout.GroupTracker; POCA), else None

    def __len__(self) -> int:
        return int(self.rewards.shape[0])


@dataclass
class GroupColumns:
    """What an agent's teammates did beside each of its T steps, M teammate slots (padding where
    ``present`` is False): the same step's observation, action and individual reward of each
    teammate, and at the end the teammates' observations after the last step and whether all of
    them were done then."""

    obs: list[np.ndarray]  # per observation, float32 [T, M, *shape]
    continuous_actions: np.ndarray  # float32 [T, M, c]
    discrete_actions: np.ndarray  # int [T, M, b]
    present: np.ndarray  # bool [T, M]
    rewards: np.ndarray  # float32 [T, M]: each teammate's own reward for that step (0 where absent)
    next_obs: list[np.ndarray]  # per observation, float32 [M2, *shape]: the teammates after the last step
    next_present: np.ndarray  # bool [M2]
    all_done: bool  # every teammate's episode had ended at the last step (True without teammates)

    @property
    def width(self) -> int:
        return int(self.present.shape[1])

class UpdateBuffer:
    """Experiences waiting for the next PPO update: field name -> list of [T, ...] arrays."""

    def __init__(self) -> None:
        self._fields: dict[str, list[np.ndarray]] = {}
        self._length = 0

    def __len__(self) -> int:
        return self._length

    def append(self, fields: dict[str, np.ndarray]) -> None:
        """Add one trajectory's arrays; every array shares the same leading length T."""
        lengths = {name: len(array) for name, array in fields.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"fields of one trajectory disagree on length: {lengths}")
        if self._fields and set(fields) != set(self._fields):
            raise ValueError(f"fields {sorted(fields)} differ from buffered fields {sorted(self._fields)}")
        for name, array in fields.items():
            self._fields.setdefault(name, []).append(array)
        self._length += next(iter(lengths.values()), 0)

    def rewrite(self, name: str, fn) -> None:
        """Replace every buffered array of field ``name`` by ``fn(array)`` (same leading length;
        POCA pads its teammate columns when a wider group arrives)."""
        arrays = self._fields.get(name)
        if arrays is not None:
            arrays[:] = [fn(array) for array in arrays]

    @property
    def field_names(self) -> list[str]:
        return list(self._fields)

    def concatenated(self) -> dict[str, np.ndarray]:
        """All buffered experiences, field name -> array [len(self), ...]."""
        return {name: np.concatenate(arrays, axis=0) for name, arrays in self._fields.items()}

    def clear(self) -> None:
        self._fields = {}
        self._length = 0
