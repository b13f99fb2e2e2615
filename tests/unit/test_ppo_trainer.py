"""PPOTrainer wiring: bootstrapping, reward strength, normalisation, update bookkeeping, state dicts."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from protos.types import (
    ActionSpec,
    BehaviorSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
)
from trainer.artifacts.checkpoints import load_checkpoint, save_checkpoint
from trainer.errors import ConfigError
from trainer.common.trajectory import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer, normalize_advantages

SPEC = BehaviorSpec(
    (ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector"),),
    ActionSpec(1, (2,)),
)
HYPER = PPOHyperparams(hidden_units=16, num_layers=1, batch_size=4, buffer_size=8, num_epoch=2,
                       max_steps=1000, reward_signals={"extrinsic": (0.9, 0.5)}, lambd=0.8)


def make_trajectory(trainer: PPOTrainer, length: int, done: bool, interrupted: bool, seed: int = 0
                    ) -> Trajectory:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(length, 3)).astype(np.float32)
    out = trainer.policy.act([obs])
    return Trajectory(obs=[obs], next_obs=[rng.normal(size=3).astype(np.float32)],
                      rewards=rng.normal(size=length).astype(np.float32),
                      continuous_actions=out.continuous_raw, discrete_actions=out.discrete,
                      log_probs=out.log_probs, action_masks=None, done=done, interrupted=interrupted)


def expected_advantages(rewards, values, bootstrap, gamma, lambd):
    """Textbook GAE written out independently: A_t = sum_k (gamma lambda)^k delta_{t+k}."""
    next_values = list(values[1:]) + [bootstrap]
    deltas = [r + gamma * nv - v for r, v, nv in zip(rewards, values, next_values)]
    return np.array([sum((gamma * lambd) ** k * deltas[t + k] for k in range(len(deltas) - t))
                     for t in range(len(deltas))])


@pytest.mark.parametrize("done, interrupted, bootstraps", [
    (True, False, False), (True, True, True), (False, False, True),
])
def test_bootstrap_and_reward_strength(done, interrupted, bootstraps):
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    traj = make_trajectory(trainer, 5, done, interrupted)
    stats = trainer.process_trajectory(traj)
    with torch.no_grad():
        values = trainer.critic([torch.from_numpy(traj.obs[0])])["extrinsic"].numpy()
        next_value = trainer.critic([torch.from_numpy(traj.next_obs[0][None])])["extrinsic"].item()
    bootstrap = next_value if bootstraps else 0.0
    advantages = expected_advantages(0.5 * traj.rewards, values, bootstrap, 0.9, 0.8)
    data = trainer.buffer.concatenated()
    np.testing.assert_allclose(data["advantages"], advantages, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(data["returns:extrinsic"], advantages + values, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(data["values:extrinsic"], values, rtol=1e-5)
    assert stats["Policy/Extrinsic Value Estimate"] == pytest.approx(values.mean(), rel=1e-5)
    assert trainer.step == 5


def test_normalisers_update_once_per_trajectory_only_when_enabled():
    trainer = PPOTrainer("Ball", SPEC, replace(HYPER, normalize=True), seed=0)
    traj = make_trajectory(trainer, 6, True, False)
    trainer.process_trajectory(traj)
    for network in (trainer.policy.actor, trainer.critic):
        normalizer = network.network_body.observation_encoder.encoders[0].normalizer
        assert int(normalizer.normalization_steps) == 7
        # mean = (0 + sum x) / 7 starting from mean 0
        np.testing.assert_allclose(normalizer.running_mean.numpy(), traj.obs[0].sum(0) / 7, rtol=1e-5)
    plain = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    plain.process_trajectory(make_trajectory(plain, 6, True, False))
    assert plain.policy.actor.network_body.observation_encoder.encoders[0].normalizer is None


def test_normalize_advantages_by_hand():
    # mean 2, population std sqrt(2/3)
    np.testing.assert_allclose(normalize_advantages(np.array([1.0, 2.0, 3.0])),
                               [-math.sqrt(1.5), 0.0, math.sqrt(1.5)], rtol=1e-6)


def test_update_runs_when_buffer_holds_more_than_buffer_size():
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    trainer.process_trajectory(make_trajectory(trainer, 8, False, False, seed=1))
    assert not trainer.ready_to_update()  # exactly buffer_size is not enough
    trainer.process_trajectory(make_trajectory(trainer, 3, True, False, seed=2))
    assert trainer.ready_to_update()
    before = [p.detach().clone() for p in trainer.policy.actor.parameters()]
    stats = trainer.update()
    assert len(trainer.buffer) == 0 and not trainer.ready_to_update()
    # 11 experiences, batch 4 -> 2 minibatches per epoch, 2 epochs -> 4 Adam steps
    adam_steps = {int(s["step"]) for s in trainer.optimizer.state_dict()["state"].values()}
    assert adam_steps == {4}
    assert any(not torch.equal(b, a) for b, a in zip(before, trainer.policy.actor.parameters()))
    assert trainer.policy.actor.version_number.tolist() == [3.0]  # constants are not trained
    # step 11 of 1000: linear decay to the floors
    assert stats["Policy/Learning Rate"] == pytest.approx((3e-4 - 1e-10) * (1 - 11 / 1000) + 1e-10)
    assert stats["Policy/Beta"] == pytest.approx((5e-3 - 1e-5) * (1 - 11 / 1000) + 1e-5)
    assert stats["Policy/Epsilon"] == pytest.approx((0.2 - 0.1) * (1 - 11 / 1000) + 0.1)
    assert trainer.optimizer.param_groups[0]["lr"] == stats["Policy/Learning Rate"]
    assert stats["Losses/Policy Loss"] > 0.0 and stats["Losses/Value Loss"] > 0.0
    assert stats["Policy/Entropy"] > 0.0


def train_twice(trainer: PPOTrainer) -> dict[str, float]:
    stats = {}
    for seed in range(2):
        trainer.process_trajectory(make_trajectory(trainer, 9, True, False, seed=seed))
        stats = trainer.update()
    return stats


@pytest.mark.parametrize("normalize", [False, True])
def test_runs_are_repeatable_and_resumable_through_a_checkpoint(tmp_path, normalize):
    hyper = replace(HYPER, normalize=normalize)
    first, second = PPOTrainer("Ball", SPEC, hyper, seed=3), PPOTrainer("Ball", SPEC, hyper, seed=3)
    assert train_twice(first) == train_twice(second)
    path = tmp_path / "checkpoint.pt"
    save_checkpoint(path, first.state_dict())
    state = load_checkpoint(path)
    assert {"Policy", "global_step", "Optimizer:value_optimizer", "Optimizer:critic"} <= set(state)
    resumed = PPOTrainer("Ball", SPEC, hyper, seed=99)
    resumed.load_state_dict(state)
    assert resumed.step == first.step == 18
    if normalize:  # the running statistics came back too (18 observations seen, not a fresh normaliser)
        saved = {k: v for k, v in state["Policy"].items() if "normalization_steps" in k or "running_" in k}
        assert saved and all(int(v) == 1 + 18 for k, v in saved.items() if k.endswith("normalization_steps"))
        restored = resumed.state_dict()["Policy"]
        for key, value in saved.items():
            assert torch.equal(restored[key], value), key
    obs = [np.ones((4, 3), np.float32)]
    np.testing.assert_array_equal(resumed.policy.act(obs).continuous_raw, first.policy.act(obs).continuous_raw)
    assert train_twice(resumed) == train_twice(first)


def test_unsupported_reward_signal_is_a_config_error():
    with pytest.raises(ConfigError, match="reward_signals.magic is not supported"):
        PPOTrainer("Ball", SPEC, replace(HYPER, reward_signals={"magic": (0.99, 0.02)}), seed=0)
