"""The numpy minibatch steps (hand-written gradients + Adam) against the torch path
(autograd + trainer.ppo.adam), from identical trainers fed identical trajectories."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from trainer.ppo import numpy_update
from trainer.ppo.buffer import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer
from trainer.protocol.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType


def vec(n: int, name: str = "v") -> ObservationSpec:
    return ObservationSpec((n,), (DimensionProperty.NONE,), ObservationType.DEFAULT, name)


def trained_pair(spec: BehaviorSpec, num_epoch: int, masked: bool):
    hp = PPOHyperparams(batch_size=32, buffer_size=200, num_epoch=num_epoch, normalize=True,
                        hidden_units=24, num_layers=2, beta=5e-3, learning_rate=3e-3,
                        reward_signals={"extrinsic": (0.99, 0.5)})
    trainers = [PPOTrainer("B", spec, hp, seed=5), PPOTrainer("B", spec, hp, seed=5)]
    trainers[0].numpy_update, trainers[1].numpy_update = True, False
    rng = np.random.default_rng(11)
    branches = spec.action_spec.discrete_branches
    for length in (70, 90, 60):  # 220 experiences > buffer_size
        obs = [(rng.standard_normal((length, o.shape[0])) * 2 + 1).astype(np.float32) for o in spec.observation_specs]
        mask = None
        if branches:
            mask = np.zeros((length, sum(branches)), dtype=bool)
            if masked:
                mask[::2, 1] = True  # option 1 of branch 0 forbidden on every other step
        out = trainers[0].policy.act(obs, mask)
        rewards = rng.standard_normal(length).astype(np.float32)
        for trainer in trainers:
            trainer.process_trajectory(Trajectory(obs, [o[-1] + 0.5 for o in obs], rewards, out.continuous_raw,
                                                  out.discrete, out.log_probs, mask, length == 90, False))
    assert numpy_update.supports(trainers[0])
    stats = [trainer.update() for trainer in trainers]
    return trainers, stats


@pytest.mark.parametrize("action_spec,masked", [
    (ActionSpec(2, ()), False),
    (ActionSpec(0, (3, 2)), True),
    (ActionSpec(2, (4,)), True),
])
def test_numpy_steps_match_autograd_and_adam(action_spec, masked):
    spec = BehaviorSpec((vec(5), vec(3, "w")), action_spec)
    (fast, slow), (fast_stats, slow_stats) = trained_pair(spec, num_epoch=3, masked=masked)
    assert fast.optimizer.step_count == slow.optimizer.step_count == 3 * (220 // 32)
    for name in ("Losses/Policy Loss", "Losses/Value Loss", "Policy/Entropy"):
        assert fast_stats[name] == pytest.approx(slow_stats[name], rel=1e-4, abs=1e-6), name
    for module in ("actor", "critic"):
        a = getattr(fast.policy, "actor") if module == "actor" else fast.critic
        b = getattr(slow.policy, "actor") if module == "actor" else slow.critic
        for (key, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items()):
            np.testing.assert_allclose(x.numpy(), y.numpy(), rtol=1e-4, atol=2e-5, err_msg=f"{module}.{key}")
    for x, y in zip(fast.optimizer.exp_avg_sq, slow.optimizer.exp_avg_sq):
        np.testing.assert_allclose(x.numpy(), y.numpy(), rtol=1e-3, atol=1e-9)
    # the weights moved, and the numpy actor used for deciding sees the new ones
    obs = [np.ones((4, 5), np.float32), np.zeros((4, 3), np.float32)]
    with torch.no_grad():
        mu, logits = fast.policy.actor.heads([torch.from_numpy(o) for o in obs], None)
    fast_mu, fast_logits, _ = fast.policy._numpy_actor.heads(obs, None)
    if mu is not None:
        np.testing.assert_allclose(fast_mu, mu.numpy(), rtol=1e-5, atol=1e-6)
    for x, y in zip(fast_logits, logits):
        np.testing.assert_allclose(x, y.numpy(), rtol=1e-5, atol=1e-5)


def test_visual_observations_keep_the_autograd_path():
    visual = ObservationSpec((3, 36, 36), (DimensionProperty.NONE, DimensionProperty.TRANSLATIONAL_EQUIVARIANCE,
                                           DimensionProperty.TRANSLATIONAL_EQUIVARIANCE), ObservationType.DEFAULT, "cam")
    trainer = PPOTrainer("V", BehaviorSpec((visual,), ActionSpec(1, ())), PPOHyperparams(hidden_units=8), seed=0)
    assert not numpy_update.supports(trainer)
