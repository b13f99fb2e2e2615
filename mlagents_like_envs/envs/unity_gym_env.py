"""``UnityToGymWrapper``: a single-agent ``BaseEnv`` (a Unity build, the Editor or the stub) as a
Gymnasium 1.x ``Env``, in the role of mlagents_envs' wrapper of the same name.

mlagents_envs 1.1.0 wrapped the old ``gym`` API; this one speaks Gymnasium 1.x: ``reset(seed=,
options=)`` returns ``(obs, info)`` and ``step`` returns ``(obs, reward, terminated, truncated,
info)`` with ``truncated`` = the agent was interrupted (max step reached). The constructor keeps
mlagents_envs' arguments and checks (one behavior, one agent, no hybrid actions); the spaces are
the same: ``Discrete`` / ``MultiDiscrete`` (or one flattened ``Discrete``) / ``Box(-1, 1)`` actions;
the first visual observation, else the vector observations concatenated, or with
``allow_multiple_obs`` a ``Tuple`` of the visual ones then the vector one.

``gymnasium.make("mlagents_like_envs/Unity-v0", file_name=BUILD, ...)`` launches a build and wraps
it (``make_unity_gym``): the form SB3's ``make_vec_env`` and Gymnasium's checker use. A build
takes its seed once, at launch (``UnityEnvironment(seed=...)``): ``reset(seed=...)`` seeds the
wrapper's random generator and action space, not the build, so the same seed does not replay the
same episode; the registration says so (``nondeterministic=True``), and Gymnasium's checker then
does not expect it.
"""
from __future__ import annotations

import itertools
import logging
import socket
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import error, spaces

from mlagents_like_envs.base_env import ActionTuple, BaseEnv, DecisionSteps, TerminalSteps

logger = logging.getLogger(__name__)


class UnityGymException(error.Error):
    """Any error related to the Gymnasium wrapper."""


class UnityToGymWrapper(gym.Env):
    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, unity_env: BaseEnv, uint8_visual: bool = False, flatten_branched: bool = False,
                 allow_multiple_obs: bool = False, action_space_seed: int | None = None) -> None:
        """Wrap ``unity_env`` (closed when the wrapper closes). ``uint8_visual``: visual
        observations as uint8 0-255 instead of float 0-1; ``flatten_branched``: several discrete
        branches as one ``Discrete``; ``allow_multiple_obs``: every observation, as a tuple;
        ``action_space_seed``: seed of the action space's sampler."""
        self._env = unity_env
        if not self._env.behavior_specs:  # the specs come with the first message
            self._env.step()
        if len(self._env.behavior_specs) != 1:
            raise UnityGymException("There can only be one behavior in a UnityEnvironment if it is wrapped in a "
                                    f"gym; this one has {sorted(self._env.behavior_specs)}.")
        self.name = next(iter(self._env.behavior_specs))
        self.group_spec = self._env.behavior_specs[self.name]
        self._allow_multiple_obs = allow_multiple_obs
        self._visual = [i for i, o in enumerate(self.group_spec.observation_specs) if len(o.shape) == 3]
        self._vector = [i for i, o in enumerate(self.group_spec.observation_specs) if len(o.shape) == 1]
        vector_size = sum(self.group_spec.observation_specs[i].shape[0] for i in self._vector)
        if not self._visual and vector_size == 0:
            raise UnityGymException("There are no observations provided by the environment.")
        if uint8_visual and not self._visual:
            logger.warning("uint8_visual was set to true, but visual observations are not in use. "
                           "This setting will not have any effect.")
        self.uint8_visual = uint8_visual and bool(self._visual)
        if len(self._visual) + bool(self._vector) >= 2 and not allow_multiple_obs:
            logger.warning("The environment contains multiple observations. You must define "
                           "allow_multiple_obs=True to receive them all. Otherwise, only the first visual "
                           "observation (or the vector observations if there are no visual ones) will be provided.")
        self._flattener: ActionFlattener | None = None
        self.action_space = self._make_action_space(flatten_branched)
        if action_space_seed is not None:
            self.action_space.seed(action_space_seed)
        visual_spaces = [spaces.Box(0, 255, self.group_spec.observation_specs[i].shape, np.uint8) if self.uint8_visual
                         else spaces.Box(0.0, 1.0, self.group_spec.observation_specs[i].shape, np.float32)
                         for i in self._visual]
        vector_space = [spaces.Box(-np.inf, np.inf, (vector_size,), np.float32)] if vector_size else []
        all_spaces = visual_spaces + vector_space
        self.observation_space = spaces.Tuple(all_spaces) if allow_multiple_obs else all_spaces[0]
        self.render_mode = "rgb_array" if self._visual else None
        self.metadata = {"render_modes": ["rgb_array"] if self._visual else []}
        self.visual_obs: np.ndarray | None = None
        self.game_over = False
        self._env.reset()
        decision_steps, _ = self._env.get_steps(self.name)
        self._check_agents(len(decision_steps))

    def _make_action_space(self, flatten_branched: bool) -> spaces.Space:
        action_spec = self.group_spec.action_spec
        if action_spec.is_discrete():
            self.action_size = action_spec.discrete_size
            branches = tuple(int(b) for b in action_spec.discrete_branches)
            if len(branches) == 1:
                return spaces.Discrete(branches[0])
            if flatten_branched:
                self._flattener = ActionFlattener(branches)
                return self._flattener.action_space
            return spaces.MultiDiscrete(branches)
        if action_spec.is_continuous():
            if flatten_branched:
                logger.warning("The environment has a non-discrete action space. It will not be flattened.")
            self.action_size = action_spec.continuous_size
            return spaces.Box(-1.0, 1.0, (action_spec.continuous_size,), np.float32)
        raise UnityGymException("The gym wrapper does not provide explicit support for both discrete and "
                                "continuous actions.")

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the environment; returns (observation, {"step": DecisionSteps})."""
        super().reset(seed=seed)
        if seed is not None:
            self.action_space.seed(seed)
        self._env.reset()
        decision_steps, _ = self._env.get_steps(self.name)
        self._check_agents(len(decision_steps))
        self.game_over = False
        return self._observation(decision_steps), {"step": decision_steps}

    def step(self, action):
        """Act, run until the agent decides again or its episode ends; after an end call ``reset``."""
        if self.game_over:
            raise UnityGymException("You are calling 'step()' even though this environment has already returned "
                                    "terminated or truncated. You must always call 'reset()' once an episode ends.")
        if self._flattener is not None:
            action = self._flattener.lookup_action(int(action))
        action = np.asarray(action).reshape((1, self.action_size))
        action_tuple = ActionTuple()
        if self.group_spec.action_spec.is_continuous():
            action_tuple.add_continuous(action.astype(np.float32))
        else:
            action_tuple.add_discrete(action.astype(np.int32))
        self._env.set_actions(self.name, action_tuple)
        self._env.step()
        decision_steps, terminal_steps = self._env.get_steps(self.name)
        self._check_agents(max(len(decision_steps), len(terminal_steps)))
        if len(terminal_steps):
            self.game_over = True
            interrupted = bool(terminal_steps.interrupted[0])
            return (self._observation(terminal_steps), float(terminal_steps.reward[0]), not interrupted,
                    interrupted, {"step": terminal_steps})
        return self._observation(decision_steps), float(decision_steps.reward[0]), False, False, {"step": decision_steps}

    def _observation(self, steps: DecisionSteps | TerminalSteps):
        visual = [self._preprocess(steps.obs[i][0]) for i in self._visual]
        vector = [np.concatenate([steps.obs[i][0] for i in self._vector]).astype(np.float32)] if self._vector else []
        if visual:
            self.visual_obs = visual[0]
        if self._allow_multiple_obs:
            return tuple(visual + vector)
        return visual[0] if visual else vector[0]

    def _preprocess(self, visual: np.ndarray) -> np.ndarray:
        return (255.0 * visual).astype(np.uint8) if self.uint8_visual else visual

    def render(self):
        """The latest visual observation (no new frame is rendered), or None without cameras."""
        return self.visual_obs

    def close(self) -> None:
        self._env.close()

    @staticmethod
    def _check_agents(n_agents: int) -> None:
        if n_agents > 1:
            raise UnityGymException(f"There can only be one Agent in the environment but {n_agents} were detected. "
                                    "Use the PettingZoo wrappers (UnityParallelEnv, UnityAECEnv) for several.")


def make_unity_gym(file_name: str, worker_id: int | None = None, base_port: int | None = None,
                   uint8_visual: bool = False, flatten_branched: bool = False, allow_multiple_obs: bool = False,
                   action_space_seed: int | None = None, render_mode: str | None = None,
                   **unity_environment_args) -> UnityToGymWrapper:
    """Launch the build ``file_name`` (``UnityEnvironment``'s arguments: seed, no_graphics,
    timeout_wait, additional_args, side_channels, log_folder, num_areas ...) and wrap it.
    ``worker_id=None`` (the default here): a port no one listens on, so several envs (SB3's
    ``make_vec_env``) need no numbering. ``render_mode`` is accepted for Gymnasium's ``make``; frames
    are the build's first camera observation, as ``UnityToGymWrapper.render`` says."""
    from mlagents_like_envs.environment import UnityEnvironment

    if worker_id is None:
        if base_port is None:
            with socket.socket() as probe:
                probe.bind(("127.0.0.1", 0))
                base_port = probe.getsockname()[1]
        worker_id = 0
    env = UnityEnvironment(file_name, worker_id=worker_id, base_port=base_port, **unity_environment_args)
    try:
        return UnityToGymWrapper(env, uint8_visual=uint8_visual, flatten_branched=flatten_branched,
                                 allow_multiple_obs=allow_multiple_obs, action_space_seed=action_space_seed)
    except BaseException:
        env.close()
        raise


ENV_ID = "mlagents_like_envs/Unity-v0"
if ENV_ID not in gym.registry:
    gym.register(ENV_ID, entry_point=make_unity_gym, nondeterministic=True, disable_env_checker=True)


class ActionFlattener:
    """Several discrete branches as one ``Discrete``: each index one combination of branch values."""

    def __init__(self, branched_action_space: tuple[int, ...]) -> None:
        self._action_shape = tuple(branched_action_space)
        self.action_lookup = dict(enumerate(list(a) for a in itertools.product(*(range(n) for n in self._action_shape))))
        self.action_space = spaces.Discrete(len(self.action_lookup))

    def lookup_action(self, action: int) -> list[int]:
        """The branch values of the flattened ``action``."""
        return self.action_lookup[action]
