"""A stub scene stepped in-process with Unity's decision-step semantics, in numpy arrays.

``Scene`` owns one task (all its agents) and an ``Academy`` whose terminal infos are kept as
arrays instead of being encoded for a message: the same decision period, reward rule
(``Task.sets_reward``), group rewards and reset-on-the-spot of finished agents as the socket path
(``unity_stub_env.academy``), with no protobuf in between. Every env form in this package
(single-agent, vector, PettingZoo) is a view on a Scene.

Environment parameters are numbers: each key becomes a constant sampler, as if the trainer had
sent it over the EnvironmentParameters side channel; a task ignores keys it does not read, as
Unity does.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unity_stub_env.academy import Academy
from unity_stub_env.tasks import EnvironmentParameters, make_task


@dataclass
class SceneStep:
    """One decision step of all n agents.

    observations: per sensor float32 [n, ...], the observation each agent acts on next (for an
    agent whose episode ended: the first of its new episode); rewards, group_rewards float32 [n]:
    what the step earned (an ended agent: its last episode's final reward); terminated,
    truncated bool [n] (truncated: interrupted at the task's max_step); final_observations: per
    sensor [n, ...], valid at the rows that ended, or None when none did.
    """

    observations: list[np.ndarray]
    rewards: np.ndarray
    group_rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    final_observations: list[np.ndarray] | None

    @property
    def ended(self) -> np.ndarray:
        return self.terminated | self.truncated


class _ArrayAcademy(Academy):
    """An Academy that keeps each finished agent's terminal observations and rewards as arrays."""

    def start_decision(self) -> None:
        n = self.task.num_agents
        self.ended = np.zeros(n, dtype=bool)
        self.ended_interrupted = np.zeros(n, dtype=bool)
        self.final_reward = np.zeros(n, dtype=np.float32)
        self.final_group_reward = np.zeros(n, dtype=np.float32)
        self.final_observations: list[np.ndarray] | None = None

    def _queue_terminal_infos(self, done: np.ndarray, interrupted: np.ndarray) -> None:
        observations = self.task.observe()
        if self.final_observations is None:
            self.final_observations = [np.zeros_like(o) for o in observations]
        for final, obs in zip(self.final_observations, observations):
            final[done] = obs[done]
        self.ended |= done
        self.ended_interrupted[done] = interrupted[done]
        self.final_reward[done] = self.pending_reward[done]
        self.final_group_reward[done] = self.pending_group_reward[done]


def environment_parameters(values: dict[str, float]) -> EnvironmentParameters:
    """Constant samplers for ``values``; TypeError names a key whose value is not a number."""
    params = EnvironmentParameters()
    for key, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(f"Environment parameter {key!r} must be a number, got {value!r} "
                            f"({type(value).__name__}); pass it as a keyword argument, e.g. {key}=1.0")
        params.set(key, lambda value=float(value): value)
    return params


class Scene:
    """One task, all its agents stepped together; ``reset`` and ``step`` as Unity's Academy runs them."""

    def __init__(self, task: str, num_areas: int = 1, seed: int = 0, agents_per_area: int | None = None,
                 decision_period: int | None = None, env_params: dict[str, float] | None = None) -> None:
        self.task_name = task
        self._options = dict(num_areas=num_areas, agents_per_area=agents_per_area)
        self._decision_period = decision_period
        self.env_params = environment_parameters(env_params or {})
        self._build(seed)

    def _build(self, seed: int) -> None:
        self.task = make_task(self.task_name, seed=int(seed), env_params=self.env_params, **self._options)
        self.academy = _ArrayAcademy(self.task, self._decision_period)
        self.num_agents = self.task.num_agents
        self.observation_specs = self.task.observation_specs
        self.action_spec = self.task.action_spec

    def reset(self, seed: int | None = None) -> list[np.ndarray]:
        """Every agent begins a new episode; a seed rebuilds the task with it (same seed, same episodes)."""
        if seed is not None:
            self._build(seed)
        else:
            self.academy.environment_reset()
        return self.task.observe()

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> SceneStep:
        """Actions of all agents (float32 [n, c], int32 [n, b]), then one decision period."""
        academy = self.academy
        academy.continuous[:] = continuous
        academy.discrete[:] = discrete
        academy.start_decision()
        academy.advance()
        ended = academy.ended
        rewards = np.where(ended, academy.final_reward, academy.pending_reward)
        group_rewards = np.where(ended, academy.final_group_reward, academy.pending_group_reward)
        # what an agent that ended earned since its reset stays pending for its next decision, as
        # Unity reports it with the new episode's first request
        academy.pending_reward[~ended] = 0.0
        academy.pending_group_reward[~ended] = 0.0
        academy.pending_stats.clear()
        interrupted = academy.ended_interrupted
        return SceneStep(self.task.observe(), rewards, group_rewards, ended & ~interrupted, ended & interrupted,
                         academy.final_observations)
