"""``mirror``: replay the behaviors of a ``behaviors.json`` (protos/spec_file.py, docs/mirror.md)
with learnable synthetic dynamics, so a game's own trainer YAML trains in CI without the game.

One ``MirrorTask`` per behavior of the file (each team of a behavior is its own task), with the
file's names, observation shapes, types and compressions (PNG cameras included), action spec,
agents per area and groups. Behind each one is a small hidden linear system, the same for every
run of the same file (its matrices are seeded by the behavior's name), its noise seeded by the
run's seed:

  hidden state  s in R^4, reset to N(0, 0.5^2) per agent
  observations  vectors: W_i s + N(0, 0.05^2); cameras C x H x W: 4 vertical stripes, stripe k
                showing sigmoid(2 s_k) (scaled per channel), so a CNN can read s
  target        continuous: t = tanh(3 K s) (mostly near +-1); discrete branch b of n options: argmax(K_b s)
  score         mean over action components of 1 - |clip(a) - t| (continuous, in [-1, 1]) and
                1 if the branch's choice is the target else 0 (discrete); random play scores
                ~0.3 per continuous component and 1/n per branch, the target policy 1
  reward        0.1 * score per control step; -1 and the episode ends (terminal, not
                interrupted) when the state leaves the box |s_k| < 4
  dynamics      s <- 0.8 R s + 0.3 B e + N(0, 0.1^2), R a rotation, e the action error
                (a - t for continuous components, 1 - correct for branches)

Episodes are interrupted at the file's ``max_step`` (``DEFAULT_MAX_STEP`` control steps when it
is not known); decisions come every ``decision_period`` (1 when not known). A policy that learns
the map from observations to the target raises its return from about ``10 * random score`` to
``10`` per 100 steps within a few thousand steps (tests/integration/test_mirror.py).
"""
from __future__ import annotations

import zlib

import numpy as np

from protos.spec_file import BehaviorRecord, SpecFile
from protos.types import StatsAggregationMethod
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep

HIDDEN = 4
DEFAULT_MAX_STEP = 100
STEP_REWARD_SCALE = 0.1
FAIL_REWARD = -1.0
BOUND = 4.0
TARGET_GAIN = 3.0  # mostly saturated targets: the sign of the mean action is most of the score


class MirrorTask(Task):
    name = "mirror"
    description = "replays a behaviors.json (--spec FILE) with learnable synthetic dynamics."

    def __init__(self, record: BehaviorRecord, num_areas: int, seed: int,
                 env_params: EnvironmentParameters | None = None, stats: tuple[str, ...] = (),
                 captured_areas: int = 1):
        self.behavior_name = record.brain_name
        self.team_id = record.team_id
        self.observation_specs = record.spec.observation_specs
        self.observation_compressions = record.compressions if "png" in record.compressions else None
        self.action_spec = record.spec.action_spec
        self.agents_per_area = record.agents_per_area or max(1, -(-record.agents // max(captured_areas, 1)))
        self.decision_period = record.decision_period or 1
        self.max_step = DEFAULT_MAX_STEP if record.max_step is None else record.max_step
        super().__init__(num_areas, seed, env_params)
        self.record = record
        self.stats_keys = stats
        system = np.random.default_rng(zlib.crc32(record.name.encode()))  # the same system for a file
        self.noise = np.random.default_rng([seed, zlib.crc32(record.name.encode())])
        self.projections = [system.normal(0.0, 1.0 / np.sqrt(HIDDEN), (int(np.prod(o.shape)), HIDDEN))
                            for o in self.observation_specs]
        self.channel_gain = [system.uniform(0.5, 1.0, o.shape[0]) for o in self.observation_specs]
        continuous = self.action_spec.continuous_size
        self.target_continuous = system.normal(0.0, 1.0, (continuous, HIDDEN))
        self.target_branches = [system.normal(0.0, 1.0, (n, HIDDEN)) for n in self.action_spec.discrete_branches]
        components = continuous + len(self.target_branches)
        rotation, _ = np.linalg.qr(system.normal(size=(HIDDEN, HIDDEN)))
        self.transition = 0.8 * rotation
        self.error_gain = 0.3 * system.normal(0.0, 1.0 / np.sqrt(components), (HIDDEN, components))
        self.state = np.zeros((self.num_agents, HIDDEN))
        self.episode_step = np.zeros(self.num_agents, dtype=np.int64)
        self.episode_score = np.zeros(self.num_agents)
        groups = record.groups_per_area
        self._groups = None if not groups else (
            np.arange(self.num_agents) // self.agents_per_area * groups
            + np.arange(self.num_agents) % self.agents_per_area % groups + 1).astype(np.int64)
        self._mask = (np.zeros((self.num_agents, sum(self.action_spec.discrete_branches)), dtype=bool)
                      if record.action_mask and self.action_spec.discrete_branches else None)
        self.reset()

    # ------------------------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        agents = self.all_agents(mask)
        self.state[agents] = self.noise.normal(0.0, 0.5, (int(agents.sum()), HIDDEN))
        self.episode_step[agents] = 0
        self.episode_score[agents] = 0.0

    def observe(self) -> list[np.ndarray]:
        n = self.num_agents
        out = []
        for spec, projection, gain in zip(self.observation_specs, self.projections, self.channel_gain):
            if len(spec.shape) == 3:  # a camera: stripe k across the width shows hidden component k
                channels, height, width = spec.shape
                stripe = np.minimum(np.arange(width) * HIDDEN // width, HIDDEN - 1)
                level = 1.0 / (1.0 + np.exp(-2.0 * self.state))  # [n, HIDDEN]
                image = gain[None, :, None, None] * level[:, stripe][:, None, None, :]
                out.append(np.broadcast_to(image, (n, channels, height, width)).astype(np.float32))
            else:
                values = self.state @ projection.T + self.noise.normal(0.0, 0.05, (n, projection.shape[0]))
                out.append(values.reshape(n, *spec.shape).astype(np.float32))
        return out

    def action_mask(self) -> np.ndarray | None:
        return self._mask

    def group_ids(self) -> np.ndarray | None:
        return self._groups

    def targets(self) -> tuple[np.ndarray, list[np.ndarray]]:
        """The best actions now: (continuous float [n, c], per branch int [n])."""
        continuous = np.tanh(TARGET_GAIN * self.state @ self.target_continuous.T)
        return continuous, [np.argmax(self.state @ k.T, axis=1) for k in self.target_branches]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        n = self.num_agents
        target_c, target_d = self.targets()
        errors = [np.clip(np.asarray(continuous, dtype=np.float64).reshape(n, -1), -1, 1) - target_c]
        scores = [1.0 - np.abs(errors[0])]
        chosen = np.asarray(discrete).reshape(n, -1)
        for b, best in enumerate(target_d):
            correct = (chosen[:, b] == best).astype(np.float64)
            scores.append(correct[:, None])
            errors.append(1.0 - correct[:, None])
        score = np.concatenate(scores, axis=1).mean(axis=1)
        error = np.concatenate(errors, axis=1)
        self.state = (self.state @ self.transition.T + error @ self.error_gain.T
                      + self.noise.normal(0.0, 0.1, (n, HIDDEN)))
        self.episode_step += 1
        self.episode_score += score
        failed = np.abs(self.state).max(axis=1) >= BOUND
        rewards = np.where(failed, FAIL_REWARD, STEP_REWARD_SCALE * score).astype(np.float32)
        interrupted = (self.episode_step >= self.max_step) & ~failed if self.max_step > 0 else np.zeros(n, bool)
        done = failed | interrupted
        stats = []
        if done.any() and self.stats_keys:
            mean_score = float(np.mean(self.episode_score[done] / self.episode_step[done]))
            stats = [(key, mean_score, StatsAggregationMethod.AVERAGE) for key in self.stats_keys]
        return TaskStep(rewards, done, interrupted, stats)


def mirror_tasks(spec: SpecFile, num_areas: int, seed: int,
                 env_params: EnvironmentParameters | None = None) -> list[MirrorTask]:
    """One task per behavior of ``spec``; the first one also sends the file's stats keys."""
    return [MirrorTask(record, num_areas, seed + index, env_params, spec.stats if index == 0 else (),
                       spec.num_areas)
            for index, record in enumerate(spec.behaviors)]
