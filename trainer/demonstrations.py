"""Demonstrations as experiences: a ``.demo`` file (or folder) read into numpy columns for
behavioral cloning (trainer/behavioral_cloning.py) and GAIL (trainer/common/reward_providers.py).

The file format is ``protos.demo_file``'s; the agent infos go through the trainer's one codec
(``codec.agent_fields``), exactly as they would arrive on the wire. Pairing, as the reference
loader does (docs/demonstrations.md): experience t holds the observations and the action of record
t and the reward and done flag of record t+1; the last record only gives those "next" values.

Actions are kept as the environment received them (continuous in [-1, 1]); a record without
actions (Unity's terminal records) counts as zeros; files written before communication API 1.3
carry only ``vector_actions_deprecated``, which is read as the continuous actions of a
continuous behavior and as the branch choices otherwise.

Every problem is a ConfigError naming the YAML key (exit code 2): the path at start
(trainer/config/support.py's ``check_demo_paths``, before a results folder or a simulator
exists), the spec when the behavior connects (``load_demonstrations``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from protos.demo_file import DemoFileError, read_demo
from protos.errors import ProtocolError
from protos.types import BehaviorSpec
from trainer.errors import ConfigError


@dataclass(frozen=True)
class DemoExperiences:
    obs: list[np.ndarray]  # float32 [N, *shape] per observation
    continuous: np.ndarray  # float32 [N, c], as the environment received them
    discrete: np.ndarray  # int64 [N, b]
    rewards: np.ndarray  # float32 [N]: the reward that followed the action
    done: np.ndarray  # bool [N]: the action ended the episode

    def __len__(self) -> int:
        return len(self.rewards)


def _describe(spec: BehaviorSpec) -> str:
    a = spec.action_spec
    shapes = [tuple(o.shape) for o in spec.observation_specs]
    return f"observations {shapes}, {a.continuous_size} continuous actions, discrete branches {list(a.discrete_branches)}"


def load_demonstrations(path: str, spec: BehaviorSpec, where: str) -> DemoExperiences:
    """The experiences of ``path`` for a behavior of ``spec``; ConfigError (naming ``where``, the
    YAML key) if the file cannot be read or was recorded for other observations or actions."""
    from trainer.protocol import codec  # numpy and protobuf: not needed to check a path at start

    try:
        demo = read_demo(path)
        demo_spec = codec.behavior_spec_from_proto(demo.brain_parameters, demo.pairs[0].agent_info)
    except (DemoFileError, ProtocolError) as error:
        raise ConfigError(f"{where}: {error}") from None
    same_obs = [tuple(o.shape) for o in demo_spec.observation_specs] == [tuple(o.shape) for o in spec.observation_specs]
    if demo_spec.action_spec != spec.action_spec or not same_obs:
        raise ConfigError(f"{where}: the demonstration {path!r} was recorded with {_describe(demo_spec)}, but "
                          f"the behavior has {_describe(spec)}; record a demonstration of this behavior")
    try:
        fields = codec.agent_fields(demo.brain_parameters.brain_name, [p.agent_info for p in demo.pairs], spec)
    except ProtocolError as error:
        raise ConfigError(f"{where}: {path!r}: {error}") from None
    values = [fields.reward, *fields.obs]
    if not all(np.isfinite(v).all() for v in values):
        raise ConfigError(f"{where}: the demonstration {path!r} holds NaN or infinite observations or "
                          "rewards; record it again")
    continuous, discrete = _actions(demo.pairs, spec)
    return DemoExperiences(
        obs=[o[:-1] for o in fields.obs], continuous=continuous[:-1], discrete=discrete[:-1],
        rewards=fields.reward[1:].astype(np.float32), done=fields.done[1:].copy())


def _actions(pairs, spec: BehaviorSpec) -> tuple[np.ndarray, np.ndarray]:
    c, b = spec.action_spec.continuous_size, len(spec.action_spec.discrete_branches)
    continuous = np.zeros((len(pairs), c), np.float32)
    discrete = np.zeros((len(pairs), b), np.int64)
    for index, pair in enumerate(pairs):
        action = pair.action_info
        cont, disc = action.continuous_actions, action.discrete_actions
        if not cont and not disc and action.vector_actions_deprecated:
            if c:
                cont = action.vector_actions_deprecated
            else:
                disc = [int(v) for v in action.vector_actions_deprecated]
        if len(cont) == c:
            continuous[index] = cont
        if len(disc) == b:
            discrete[index] = disc
    return continuous, discrete
