"""``StubVectorEnv``: every agent of a stub scene as one ``gymnasium.vector.VectorEnv``, stepped
as one batch (one ``Task.step`` per control step for all agents, no per-agent Python).

``gymnasium.make_vec("unity_stub_env/Ball3D-v0", num_envs=12)`` is one 3DBall area of 12 plates;
``num_envs`` may be any count for tasks whose agents are independent, a multiple of the agents per
area for the others (``num_areas`` areas). Sub-env i is agent i.

Finished agents start their next episode within the same step, as Unity resets them
(``AutoresetMode.SAME_STEP``): the returned observation is the new episode's first and
``infos["final_obs"]`` (with the mask ``infos["_final_obs"]``) holds the last one of the
episode that ended.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from unity_stub_env.gym import spaces
from unity_stub_env.gym.render import SceneFrames, can_render
from unity_stub_env.gym.scene import Scene


class StubVectorEnv(VectorEnv):
    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, task: str, num_envs: int | None = None, num_areas: int | None = None,
                 render_mode: str | None = None, decision_period: int | None = None, seed: int = 0,
                 **env_params: float) -> None:
        from unity_stub_env.tasks import TASKS

        if task not in TASKS:
            raise KeyError(f"Unknown task {task!r}; known tasks: {', '.join(sorted(TASKS))}")
        per_area = TASKS[task].agents_per_area
        agents_per_area = None
        if num_envs is not None and num_areas is not None:
            raise ValueError("Give num_envs (agents) or num_areas (areas), not both")
        if num_envs is not None:
            if TASKS[task].agents_interact:
                if num_envs % per_area:
                    raise ValueError(f"num_envs={num_envs}: task {task!r} has {per_area} agents per area that "
                                     f"play together, so num_envs must be a multiple of {per_area}")
                num_areas = num_envs // per_area
            else:
                num_areas, agents_per_area = 1, num_envs
        self.scene = Scene(task, num_areas=num_areas or 1, agents_per_area=agents_per_area, seed=seed,
                           decision_period=decision_period, env_params=env_params)
        self.num_envs = self.scene.num_agents
        self.single_observation_space = spaces.observation_space(self.scene.observation_specs)
        self.single_action_space = spaces.action_space(self.scene.action_spec)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        if render_mode is not None and (render_mode not in self.metadata["render_modes"]
                                        or not can_render(self.scene.task)):
            raise ValueError(f"render_mode {render_mode!r} is not available for task {task!r}")
        self.render_mode = render_mode
        self._frames = SceneFrames(self.scene, render_mode)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:  # the rebuilt task has a new MjModel
            self._frames.drop()
        observations = self.scene.reset(seed)
        return spaces.observations(self.scene.observation_specs, observations), {}

    def step(self, actions):
        scene = self.scene
        continuous, discrete = spaces.task_actions(scene.action_spec, actions, self.num_envs)
        result = scene.step(continuous, discrete)
        infos: dict[str, Any] = {}
        ended = result.ended
        if ended.any():
            final = np.empty(self.num_envs, dtype=object)
            for i in np.flatnonzero(ended):  # only the agents that ended this step
                final[i] = spaces.observations(scene.observation_specs, result.final_observations, i)
            infos = {"final_obs": final, "_final_obs": ended.copy(),
                     "final_info": np.array([{} for _ in range(self.num_envs)]), "_final_info": ended.copy()}
        obs = spaces.observations(scene.observation_specs, result.observations)
        return obs, result.rewards, result.terminated, result.truncated, infos

    def render(self):
        return self._frames.frame()

    def close_extras(self, **kwargs) -> None:
        self._frames.drop()
