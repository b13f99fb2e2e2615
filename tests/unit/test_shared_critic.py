"""hyperparameters.shared_critic: value heads on the actor's body (ML-Agents' SharedActorCritic)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from tests.unit.test_ppo_trainer import SPEC, make_trajectory
from trainer.ppo import numpy_update
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer

HYPER = PPOHyperparams(hidden_units=16, num_layers=1, batch_size=4, buffer_size=8, num_epoch=2, max_steps=1000,
                       shared_critic=True, normalize=True, reward_signals={"extrinsic": (0.9, 1.0)})


def test_the_critic_is_heads_on_the_actors_body():
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    assert trainer.critic.network_body is trainer.policy.actor.network_body
    assert sorted(trainer.critic.state_dict()) == ["value_heads.extrinsic.bias", "value_heads.extrinsic.weight"]
    n_actor = len([p for p in trainer.policy.actor.parameters() if p.requires_grad])
    assert len(trainer.optimizer.params) == n_actor + 2  # no second copy of the body
    obs = torch.from_numpy(np.random.default_rng(0).normal(size=(5, 3)).astype(np.float32))
    trainer.critic([obs])["extrinsic"].sum().backward()  # the value loss reaches the actor's body
    first = trainer.policy.actor.network_body.hidden[0].weight
    assert first.grad is not None and first.grad.abs().sum() > 0
    separate = PPOTrainer("Ball", SPEC, replace(HYPER, shared_critic=False), seed=0)
    assert separate.critic.network_body is not separate.policy.actor.network_body


def test_each_trajectory_enters_the_shared_normaliser_twice_as_in_the_reference():
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    trainer.process_trajectory(make_trajectory(trainer, 5, False, False))
    steps = [v for k, v in trainer.policy.actor.state_dict().items() if k.endswith("normalization_steps")]
    assert [int(s) for s in steps] == [1 + 2 * 5]


def test_it_trains_in_torch_and_survives_a_checkpoint():
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    assert trainer._numpy_critic is None and not numpy_update.supports(trainer)
    for seed in range(3):
        trainer.process_trajectory(make_trajectory(trainer, 4, False, False, seed=seed))
    stats = trainer.update()
    assert np.isfinite(stats["Losses/Value Loss"]) and np.isfinite(stats["Losses/Policy Loss"])
    restored = PPOTrainer("Ball", SPEC, HYPER, seed=9)
    restored.load_state_dict(trainer.state_dict())
    obs = torch.from_numpy(np.random.default_rng(1).normal(size=(4, 3)).astype(np.float32))
    with torch.no_grad():
        assert torch.equal(trainer.critic([obs])["extrinsic"], restored.critic([obs])["extrinsic"])
