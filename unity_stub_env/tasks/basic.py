"""``basic``: ML-Agents' Basic example, a 1-D corridor with a small and a large goal.

Each agent stands on integer positions 0..19 and starts at 10. One discrete branch of 3:
0 = stay, 1 = step left (-1), 2 = step right (+1); positions are clipped to 0..19.
Every step costs -0.01. Reaching position 7 (small goal) adds +0.1 and ends the episode;
reaching position 17 (large goal) adds +1.0 and ends it. After ``max_step`` = 100 steps
the episode is interrupted. Observation: one-hot of the position, float32 [20].
Action mask: "left" is forbidden at position 0 and "right" at position 19 (the walls).

Optimal episode return, by hand: walk right 7 times (10 -> 17):
    7 * (-0.01) + 1.0 = 0.93        (the small goal gives at best 3 * (-0.01) + 0.1 = 0.07)
"""
from __future__ import annotations

import numpy as np

from protos.types import (
    ActionSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
    StatsAggregationMethod,
)
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep

NUM_POSITIONS = 20
START_POSITION = 10
SMALL_GOAL = 7
LARGE_GOAL = 17
STEP_REWARD = -0.01
SMALL_GOAL_REWARD = 0.1
LARGE_GOAL_REWARD = 1.0
OPTIMAL_RETURN = 7 * STEP_REWARD + LARGE_GOAL_REWARD  # 0.93, see the module docstring

_MOVE_OF_ACTION = np.array([0, -1, 1], dtype=np.int64)  # stay, left, right

# Everything a step needs, looked up by position (one numpy call each instead of a chain of
# them: with one agent the per-call cost is the whole step). Built with the same float32
# additions the step used to do, so rewards are bit-for-bit what they were.
_POSITIONS = np.arange(NUM_POSITIONS)
_CHOICES = np.arange(3, dtype=np.int64)  # .take(..., mode="clip") clamps any action into 0..2
_NEXT_POSITION = np.minimum(np.maximum(_POSITIONS[:, None] + _MOVE_OF_ACTION[None, :], 0),
                            NUM_POSITIONS - 1)  # [position, action] -> position after the move
_REWARD_AT = np.full(NUM_POSITIONS, STEP_REWARD, dtype=np.float32)
_REWARD_AT[SMALL_GOAL] += SMALL_GOAL_REWARD
_REWARD_AT[LARGE_GOAL] += LARGE_GOAL_REWARD
_GOAL_AT = np.isin(_POSITIONS, [SMALL_GOAL, LARGE_GOAL])
_LARGE_AT = _POSITIONS == LARGE_GOAL
_MASK_AT = np.zeros((NUM_POSITIONS, 3), dtype=bool)  # "left" at the left wall, "right" at the right
_MASK_AT[0, 1] = _MASK_AT[NUM_POSITIONS - 1, 2] = True


class BasicTask(Task):
    name = "basic"
    behavior_name = "Basic"
    observation_specs = (
        ObservationSpec((NUM_POSITIONS,), (DimensionProperty.NONE,), ObservationType.DEFAULT,
                        "VectorSensor_size20"),
    )
    action_spec = ActionSpec(continuous_size=0, discrete_branches=(3,))
    agents_per_area = 1
    max_step = 100
    decision_period = 1
    sets_reward = False
    description = f"1-D corridor; optimal return {OPTIMAL_RETURN:.2f} (7 steps right)."

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        self.position = np.full(self.num_agents, START_POSITION, dtype=np.int64)
        self.episode_step = np.zeros(self.num_agents, dtype=np.int64)
        self._eye = np.eye(NUM_POSITIONS, dtype=np.float32)

    def reset(self, mask: np.ndarray | None = None) -> None:
        agents = self.all_agents(mask)
        self.position[agents] = START_POSITION
        self.episode_step[agents] = 0

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 20]]: one-hot of each agent's position."""
        return [self._eye[self.position]]

    def action_mask(self) -> np.ndarray:
        """bool [n, 3]: True where the move would walk into a wall."""
        return _MASK_AT[self.position]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """discrete int [n, 1] in {0, 1, 2} -> one corridor step for every agent (actions outside
        0..2 are clamped into it)."""
        choice = _CHOICES.take(np.asarray(discrete).reshape(self.num_agents, -1)[:, 0], mode="clip")
        self.position = _NEXT_POSITION[self.position, choice]
        self.episode_step += 1
        reached = _GOAL_AT[self.position]
        interrupted = self.episode_step >= self.max_step if self.max_step > 0 else np.zeros_like(reached)
        interrupted &= ~reached
        done = reached | interrupted
        return TaskStep(_REWARD_AT[self.position], done, interrupted, self._episode_stats(done))

    def _episode_stats(self, done: np.ndarray) -> list:
        if not done.any():
            return []
        final = self.position[done]
        stats = [("Basic/Large Goal Reached", float(hit), StatsAggregationMethod.AVERAGE)
                 for hit in _LARGE_AT[final].tolist()]
        stats.append(("Basic/Last Final Position", float(final[-1]), StatsAggregationMethod.MOST_RECENT))
        return stats
