"""``StubParallelEnv``: a stub scene's agents as a PettingZoo ``ParallelEnv``
(``unity_stub_env.gym.parallel_env("pushblock")``), for the multi-agent tasks above all
(pushblock, dungeon, soccer, soccer_twos) and usable with any task.

Agents are named ``<behavior>?team=<t>?agent_id=<row>`` (the behavior key Unity sends, then the
agent's row in the scene), so the name says which policy an agent belongs to (soccer: one
behavior per team). Rewards and infos follow ML-Agents' PettingZoo wrappers (and ours,
``mlagents_like_envs.envs``): the reward is the agent's own, ``infos[agent]`` holds
``behavior_name``, ``group_id`` and ``group_reward`` (Unity's ``AddGroupReward``: add it for
pushblock and dungeon, whose rewards are all group rewards). An agent whose episode ended leaves
``agents`` until the next ``reset``; the scene keeps it acting with zero actions meanwhile.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from pettingzoo import ParallelEnv

from unity_stub_env.gym import spaces
from unity_stub_env.gym.render import SceneFrames, can_render
from unity_stub_env.gym.scene import Scene


class StubParallelEnv(ParallelEnv):
    metadata = {"render_modes": ["rgb_array"], "name": "unity_stub_env", "is_parallelizable": True}

    def __init__(self, task: str, num_areas: int = 1, render_mode: str | None = None,
                 decision_period: int | None = None, seed: int = 0, **env_params: float) -> None:
        self.scene = Scene(task, num_areas=num_areas, seed=seed, decision_period=decision_period,
                           env_params=env_params)
        self.metadata = {**self.metadata, "name": f"unity_stub_env_{task}"}
        names = np.empty(self.scene.num_agents, dtype=object)
        self._behavior: dict[str, str] = {}
        for key, rows in self.scene.task.behaviors():
            indices = np.arange(self.scene.num_agents)[rows]
            names[indices] = [f"{key}?agent_id={row}" for row in indices]
            self._behavior.update({f"{key}?agent_id={row}": key for row in indices})
        self.possible_agents: list[str] = names.tolist()
        self._row = {name: row for row, name in enumerate(self.possible_agents)}
        obs_space = spaces.observation_space(self.scene.observation_specs)
        act_space = spaces.action_space(self.scene.action_spec)
        self.observation_spaces = {name: obs_space for name in self.possible_agents}
        self.action_spaces = {name: act_space for name in self.possible_agents}
        if render_mode is not None and (render_mode not in self.metadata["render_modes"]
                                        or not can_render(self.scene.task)):
            raise ValueError(f"render_mode {render_mode!r} is not available for task {task!r}")
        self.render_mode = render_mode
        self._frames = SceneFrames(self.scene, render_mode)
        self.agents: list[str] = []
        self._live = np.zeros(self.scene.num_agents, dtype=bool)

    def observation_space(self, agent: str):
        return self.observation_spaces[agent]

    def action_space(self, agent: str):
        return self.action_spaces[agent]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None:  # the rebuilt task has a new MjModel
            self._frames.drop()
        observations = self.scene.reset(seed)
        for name in self.possible_agents:  # agents' spaces sample reproducibly after a seeded reset
            if seed is not None:
                self.action_spaces[name].seed(seed + self._row[name])
        self.agents = list(self.possible_agents)
        self._live[:] = True
        return self._per_agent(observations, self.agents), self._infos(self.agents, None)

    def _infos(self, names: list[str], group_rewards: np.ndarray | None) -> dict[str, dict]:
        groups = self.scene.task.group_ids()
        return {name: {"behavior_name": self._behavior[name],
                       "group_id": 0 if groups is None else int(groups[self._row[name]]),
                       "group_reward": 0.0 if group_rewards is None else float(group_rewards[self._row[name]])}
                for name in names}

    def step(self, actions: dict[str, Any]):
        scene = self.scene
        unknown = set(actions) - set(self.agents)
        if unknown:
            raise KeyError(f"Actions for agents that are not live: {sorted(unknown)}; live agents: {self.agents}")
        act_space = spaces.action_space(scene.action_spec)
        full = np.zeros((scene.num_agents, *act_space.shape), dtype=act_space.dtype)
        if actions:
            rows = [self._row[name] for name in actions]
            full[rows] = np.asarray(list(actions.values())).reshape(len(rows), *act_space.shape)
        continuous, discrete = spaces.task_actions(scene.action_spec, full, scene.num_agents)
        result = scene.step(continuous, discrete)
        live = self.agents
        ended = result.ended
        observations = result.observations
        if ended.any():  # agents that ended report their episode's last observation
            observations = [np.where(ended.reshape(-1, *[1] * (o.ndim - 1)), f, o)
                            for o, f in zip(result.observations, result.final_observations)]
        obs = self._per_agent(observations, live)
        rewards = {name: float(result.rewards[self._row[name]]) for name in live}
        terminations = {name: bool(result.terminated[self._row[name]]) for name in live}
        truncations = {name: bool(result.truncated[self._row[name]]) for name in live}
        infos = self._infos(live, result.group_rewards)
        self._live &= ~ended
        self.agents = [name for name in live if self._live[self._row[name]]]
        return obs, rewards, terminations, truncations, infos

    def _per_agent(self, observations: list[np.ndarray], names: list[str]) -> dict[str, Any]:
        specs = self.scene.observation_specs
        return {name: spaces.observations(specs, observations, self._row[name]) for name in names}

    def render(self):
        return self._frames.frame()

    def close(self) -> None:
        self._frames.drop()
