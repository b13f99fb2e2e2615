"""PPO learns one-step contextual bandits, driven through Policy.act -> Trajectory -> PPOTrainer."""
from __future__ import annotations

import numpy as np

from protos.types import (
    ActionSpec,
    BehaviorSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
)
from trainer.common.trajectory import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer

OBS = ObservationSpec((1,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "sign")
HYPER = PPOHyperparams(batch_size=64, buffer_size=256, learning_rate=3e-3, beta=1e-3, num_epoch=3,
                       learning_rate_schedule="constant", beta_schedule="constant", epsilon_schedule="constant",
                       hidden_units=32, num_layers=1, max_steps=100_000)
AGENTS = 64


def play(trainer: PPOTrainer, rng: np.random.Generator, reward_of) -> None:
    """One decision for every agent; each agent's episode ends right after it (T = 1)."""
    obs = rng.choice([-1.0, 1.0], size=(AGENTS, 1)).astype(np.float32)
    out = trainer.policy.act([obs])
    rewards = reward_of(obs[:, 0], out).astype(np.float32)
    for i in range(AGENTS):
        trainer.process_trajectory(Trajectory(
            obs=[obs[i:i + 1]], next_obs=[obs[i]], rewards=rewards[i:i + 1],
            continuous_actions=out.continuous_raw[i:i + 1], discrete_actions=out.discrete[i:i + 1],
            log_probs=out.log_probs[i:i + 1], action_masks=None, done=True, interrupted=False,
        ))


def train(trainer: PPOTrainer, reward_of, success, max_updates: int) -> int:
    rng = np.random.default_rng(0)
    for update in range(max_updates):
        while not trainer.ready_to_update():
            play(trainer, rng, reward_of)
        trainer.update()
        if success(trainer):
            return update + 1
    raise AssertionError(f"not learned within {max_updates} updates")


def test_discrete_bandit_reaches_90_percent():
    spec = BehaviorSpec((OBS,), ActionSpec(0, (2,)))
    trainer = PPOTrainer("Bandit", spec, HYPER, seed=0)
    probe = np.array([[-1.0]] * 200 + [[1.0]] * 200, dtype=np.float32)
    correct = (probe[:, 0] > 0).astype(np.int32)

    def reward_of(sign, out):
        return (out.discrete[:, 0] == (sign > 0)).astype(np.float32)

    def success(t: PPOTrainer) -> bool:  # sampled (not argmax) actions, so the policy itself is sharp
        return float(np.mean(t.policy.act([probe]).discrete[:, 0] == correct)) > 0.9

    assert train(trainer, reward_of, success, max_updates=15) <= 15


def test_continuous_bandit_moves_mean_to_target():
    spec = BehaviorSpec((OBS,), ActionSpec(1, ()))
    trainer = PPOTrainer("Bandit", spec, HYPER, seed=0)
    probe = np.array([[-1.0], [1.0]], dtype=np.float32)
    target = 0.5 * probe  # env action (in [-1, 1]) that maximises reward

    def reward_of(sign, out):
        return -((out.env_actions.continuous[:, 0] - 0.5 * sign) ** 2)

    def success(t: PPOTrainer) -> bool:
        mean_action = t.policy.act([probe], deterministic=True).env_actions.continuous
        return float(np.max(np.abs(mean_action - target))) < 0.1

    assert train(trainer, reward_of, success, max_updates=15) <= 15
