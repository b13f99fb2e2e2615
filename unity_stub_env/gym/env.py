"""``StubEnv``: one agent of a stub task as a Gymnasium 1.x ``Env`` (``unity_stub_env/<Task>-v0``).

The scene holds exactly one agent (``agents_per_area=1``) for tasks whose agents are independent
copies (ball3d's 12 plates, dodge's 14 characters ...). One ``step`` is one decision: the task's
decision period of control steps (ball3d: 5 x 0.02 s). ``terminated``: the episode ended by the
task's rule; ``truncated``: the task's own ``max_step`` interrupted it (no TimeLimit wrapper is
added). Keyword arguments other than the options below are environment parameters, as the
EnvironmentParameters side channel would set them (ball3d: ``mass``, ``scale``, ``gravity``).
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from unity_stub_env.gym import spaces
from unity_stub_env.gym.render import SceneFrames, can_render
from unity_stub_env.gym.scene import Scene


class StubEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, task: str, render_mode: str | None = None, decision_period: int | None = None,
                 seed: int = 0, **env_params: float) -> None:
        from unity_stub_env.tasks import TASKS

        if task in TASKS and TASKS[task].agents_interact:
            raise ValueError(f"Task {task!r} has agents that play together; use its PettingZoo form "
                             "(unity_stub_env.gym.parallel_env) or its vector form (gymnasium.make_vec)")
        self.scene = Scene(task, num_areas=1, agents_per_area=1, seed=seed, decision_period=decision_period,
                           env_params=env_params)
        self.observation_space = spaces.observation_space(self.scene.observation_specs)
        self.action_space = spaces.action_space(self.scene.action_spec)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r} is not supported; use one of {self.metadata['render_modes']}")
        if render_mode is not None and not can_render(self.scene.task):
            raise ValueError(f"Task {task!r} is not a MuJoCo scene and has no frames; leave render_mode unset")
        self.render_mode = render_mode
        self._frames = SceneFrames(self.scene, render_mode)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:  # the rebuilt task has a new MjModel
            self._frames.drop()
        observations = self.scene.reset(seed)
        return spaces.observations(self.scene.observation_specs, observations, 0), {}

    def step(self, action):
        continuous, discrete = spaces.task_actions(self.scene.action_spec, action, 1)
        result = self.scene.step(continuous, discrete)
        observations = result.final_observations if result.ended[0] else result.observations
        obs = spaces.observations(self.scene.observation_specs, observations, 0)
        return obs, float(result.rewards[0]), bool(result.terminated[0]), bool(result.truncated[0]), {}

    def render(self):
        return self._frames.frame()

    def close(self) -> None:
        self._frames.drop()
