"""``UnityParallelEnv``: a ``BaseEnv`` (a Unity build, the Editor or the stub) as a PettingZoo
``ParallelEnv``, in the role of mlagents_envs' wrapper of the same name, on the current PettingZoo
API (``reset(seed=, options=)`` -> ``(observations, infos)``; ``step`` -> observations, rewards,
terminations, truncations, infos).

As in mlagents_envs:

* an agent is named ``<behavior name>?agent_id=<id>``, the id Unity gives the agent for one
  episode, so an agent whose episode ends leaves ``agents`` for good and its next episode joins
  as a new name; ``possible_agents`` holds every name seen since the last ``reset``;
* each behavior's observation space is a ``Box`` per sensor (a ``Tuple`` of them for several),
  its action space ``Box(-1, 1)`` / ``Discrete`` / ``MultiDiscrete``, or a ``Tuple`` of the
  continuous and discrete parts;
* rewards are the agent's own; ``infos`` carry ``behavior_name``, ``group_id``, ``group_reward``
  (add it for group tasks), ``interrupted`` for an ended agent and, for discrete actions,
  ``action_mask`` in PettingZoo's form (int8, 1 = allowed: one array for ``Discrete``, a tuple of
  one per branch for ``MultiDiscrete``; Unity's masks say True = not allowed);
* ``terminated`` is an end by the environment's rule, ``truncated`` an interrupted episode.

An agent with no decision due this step (a longer decision period than its neighbours') stays in
``agents`` and its action is not used. ``reset(seed=...)`` seeds the action spaces, not the build.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import error, spaces
from pettingzoo import ParallelEnv

from mlagents_like_envs.base_env import ActionTuple, BaseEnv, BehaviorSpec, DecisionSteps, TerminalSteps

AGENT_ID = "?agent_id="


def agent_name(behavior_name: str, agent_id: int) -> str:
    return f"{behavior_name}{AGENT_ID}{agent_id}"


def behavior_of(agent: str) -> str:
    return agent.split(AGENT_ID)[0]


def observation_space(spec: BehaviorSpec) -> spaces.Space:
    boxes = tuple(spaces.Box(-np.float32(np.inf), np.float32(np.inf), tuple(o.shape), np.float32)
                  for o in spec.observation_specs)
    return boxes[0] if len(boxes) == 1 else spaces.Tuple(boxes)


def action_space(spec: BehaviorSpec) -> spaces.Space:
    action = spec.action_spec
    branches = tuple(int(b) for b in action.discrete_branches)
    if not action.continuous_size and not branches:
        raise error.Error("No actions found")
    discrete = (spaces.Discrete(branches[0]) if len(branches) == 1 else spaces.MultiDiscrete(branches)) \
        if branches else None
    continuous = spaces.Box(-1.0, 1.0, (action.continuous_size,), np.float32) if action.continuous_size else None
    if continuous is not None and discrete is not None:
        return spaces.Tuple((continuous, discrete))
    return continuous if continuous is not None else discrete


class UnityParallelEnv(ParallelEnv):
    metadata = {"render_modes": [], "name": "unity_parallel_env", "is_parallelizable": True}

    def __init__(self, env: BaseEnv, seed: int | None = None) -> None:
        """Wrap ``env`` (closed when this closes); ``seed``: the action spaces' sampler seed."""
        self._env = env
        self._seed = seed
        self.render_mode = None
        if not self._env.behavior_specs:  # the specs come with the first message
            self._env.step()
        self._observation_spaces: dict[str, spaces.Space] = {}
        self._action_spaces: dict[str, spaces.Space] = {}
        self._update_spaces()
        self.agents: list[str] = []
        self.possible_agents: list[str] = []
        self._rows: dict[str, tuple[str, int]] = {}  # agent -> (behavior, row in its DecisionSteps)
        self._deciding: dict[str, int] = {}  # behavior -> agents in its last DecisionSteps

    # ------------------------------------------------------------------ spaces
    def _update_spaces(self) -> None:
        for behavior, spec in self._env.behavior_specs.items():
            if behavior not in self._action_spaces:
                self._observation_spaces[behavior] = observation_space(spec)
                self._action_spaces[behavior] = action_space(spec)
                if self._seed is not None:
                    self._action_spaces[behavior].seed(self._seed)

    def observation_space(self, agent: str) -> spaces.Space:
        return self._observation_spaces[behavior_of(agent)]

    def action_space(self, agent: str) -> spaces.Space:
        return self._action_spaces[behavior_of(agent)]

    @property
    def observation_spaces(self) -> dict[str, spaces.Space]:
        return {agent: self.observation_space(agent) for agent in self.possible_agents}

    @property
    def action_spaces(self) -> dict[str, spaces.Space]:
        return {agent: self.action_space(agent) for agent in self.possible_agents}

    # ------------------------------------------------------------------ the cycle
    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the environment; every agent of the first decisions is live."""
        if seed is not None:
            self._seed = seed
            for space in self._action_spaces.values():
                space.seed(seed)
        self._env.reset()
        self.agents, self.possible_agents = [], []
        observations, _, _, _, infos = self._collect()
        return observations, infos

    def step(self, actions: dict[str, Any]):
        """The actions of live agents (missing ones act with zeros), then one environment step."""
        if not self.agents and actions:
            raise error.Error("You must reset the environment before you can perform a step.")
        batches = {behavior: self._env.behavior_specs[behavior].action_spec.empty_action(count)
                   for behavior, count in self._deciding.items()}
        for agent, action in actions.items():
            if agent not in self._rows:
                if agent in self.agents:
                    continue  # live, but no decision of it is due this step
                raise error.Error(f"Agent {agent!r} is not live (live agents: {self.agents}).")
            behavior, row = self._rows[agent]
            space = self._action_spaces[behavior]
            self._write_action(batches[behavior], row, space, action, agent)
        for behavior, batch in batches.items():
            self._env.set_actions(behavior, batch)
        self._env.step()
        return self._collect()

    @staticmethod
    def _write_action(batch: ActionTuple, row: int, space: spaces.Space, action, agent: str) -> None:
        parts = action if isinstance(space, spaces.Tuple) else (action,)
        kinds = ("continuous", "discrete") if isinstance(space, spaces.Tuple) else \
            (("continuous",) if isinstance(space, spaces.Box) else ("discrete",))
        for kind, part in zip(kinds, parts):
            target = batch.continuous if kind == "continuous" else batch.discrete
            value = np.asarray(part).reshape(-1)
            if value.shape[0] != target.shape[1]:
                raise error.Error(f"Invalid action for {agent!r}: {action!r}, expected one from {space}")
            target[row] = value

    def _collect(self):
        """Read every behavior's steps: the dicts ``step`` returns, and the new live agents."""
        self._update_spaces()
        observations, rewards, terminations, truncations, infos = {}, {}, {}, {}, {}
        ended, deciding = set(), []
        self._rows, self._deciding = {}, {}
        for behavior in self._env.behavior_specs:
            decision_steps, terminal_steps = self._env.get_steps(behavior)
            self._deciding[behavior] = len(decision_steps)
            for row, agent_id in enumerate(terminal_steps.agent_id.tolist()):
                agent = agent_name(behavior, agent_id)
                interrupted = bool(terminal_steps.interrupted[row])
                self._record(agent, behavior, terminal_steps, row, observations, rewards, infos)
                terminations[agent], truncations[agent] = not interrupted, interrupted
                infos[agent]["interrupted"] = interrupted
                ended.add(agent)
            for row, agent_id in enumerate(decision_steps.agent_id.tolist()):
                agent = agent_name(behavior, agent_id)
                self._record(agent, behavior, decision_steps, row, observations, rewards, infos)
                terminations[agent] = truncations[agent] = False
                if decision_steps.action_mask is not None:
                    allowed = tuple((~mask[row]).astype(np.int8) for mask in decision_steps.action_mask)
                    infos[agent]["action_mask"] = allowed[0] if len(allowed) == 1 else allowed
                self._rows[agent] = (behavior, row)
                deciding.append(agent)
        waiting = [agent for agent in self.agents if agent not in ended and agent not in self._rows]
        self.agents = waiting + [agent for agent in deciding if agent not in ended]
        known = set(self.possible_agents)
        self.possible_agents += [agent for agent in list(observations) if agent not in known]
        return observations, rewards, terminations, truncations, infos

    @staticmethod
    def _record(agent, behavior, steps: DecisionSteps | TerminalSteps, row, observations, rewards, infos):
        obs = [o[row] for o in steps.obs]
        observations[agent] = obs[0] if len(obs) == 1 else tuple(obs)
        rewards[agent] = float(steps.reward[row])
        infos[agent] = {"behavior_name": behavior, "group_id": int(steps.group_id[row]),
                        "group_reward": float(steps.group_reward[row])}

    def render(self):
        """Not supported, as in mlagents_envs: a build's frames are its camera observations."""
        return None

    def close(self) -> None:
        if self._env is not None:
            self._env.close()
            self._env = None

    def state(self):
        raise NotImplementedError("A Unity environment has no global state observation")
