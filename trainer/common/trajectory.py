"""The trajectory the rollout hands every trainer: one agent's consecutive experiences, and its
teammates' columns beside them (POCA)."""
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
