"""Curiosity and RND reward signals: rewards and losses against the formulas written out in
numpy from the networks' weights, learning, bootstrapping, per-episode statistics, checkpoints."""
from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from tests.unit.test_ppo_trainer import expected_advantages, make_trajectory
from trainer.common.hyperparams import SignalNetwork
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.reward_providers import CuriosityProvider, Experience, RNDProvider
from trainer.ppo.trainer import PPOTrainer

SPEC = BehaviorSpec(
    (ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector"),),
    ActionSpec(2, (3, 2)),  # hybrid: both inverse-model heads and the one-hot flattening
)
NET = SignalNetwork(learning_rate=1e-3, hidden_units=8, num_layers=2)


def experience(n=6, seed=0):
    rng = np.random.default_rng(seed)
    return Experience([rng.normal(size=(n, 3)).astype(np.float32)], [rng.normal(size=(n, 3)).astype(np.float32)],
                      rng.normal(size=(n, 2)).astype(np.float32),
                      np.stack([rng.integers(0, 3, n), rng.integers(0, 2, n)], axis=1))


def weights(module) -> dict[str, np.ndarray]:
    return {k: v.detach().numpy().astype(np.float64) for k, v in module.state_dict().items()}


def swish(x):
    return x / (1.0 + np.exp(-x))


def body(w, prefix, x):
    """NetworkBody with num_layers 2, no normaliser: swish(W2 swish(W1 x + b1) + b2)."""
    h = swish(x @ w[f"{prefix}hidden.0.weight"].T + w[f"{prefix}hidden.0.bias"])
    return swish(h @ w[f"{prefix}hidden.2.weight"].T + w[f"{prefix}hidden.2.bias"])


def one_hot(discrete):
    return np.concatenate([np.eye(3)[discrete[:, 0]], np.eye(2)[discrete[:, 1]]], axis=1)


def curiosity_by_hand(provider, exp):
    """(forward error per sample [n], inverse loss) from the weights."""
    w = weights(provider.network)
    x, nx = exp.obs[0].numpy().astype(np.float64), exp.next_obs[0].numpy().astype(np.float64)
    cont, disc = exp.continuous.numpy().astype(np.float64), exp.discrete.numpy()
    phi, phi_next = body(w, "state_encoder.", x), body(w, "state_encoder.", nx)
    hidden = swish(np.concatenate([phi, cont, one_hot(disc)], 1) @ w["forward_model.0.weight"].T
                   + w["forward_model.0.bias"])
    predicted = hidden @ w["forward_model.2.weight"].T + w["forward_model.2.bias"]
    forward_error = (0.5 * (phi_next - predicted) ** 2).sum(1)
    inv = swish(np.concatenate([phi, phi_next], 1) @ w["inverse_encoder.0.weight"].T + w["inverse_encoder.0.bias"])
    cont_pred = inv @ w["continuous_prediction.weight"].T + w["continuous_prediction.bias"]
    logits = inv @ w["discrete_prediction.weight"].T + w["discrete_prediction.bias"]
    probs = np.concatenate([np.exp(b) / np.exp(b).sum(1, keepdims=True) for b in (logits[:, :3], logits[:, 3:])], 1)
    inverse = ((cont - cont_pred) ** 2).sum(1).mean() + (-np.log(probs + 1e-10) * one_hot(disc)).sum(1).mean()
    return forward_error, inverse


def test_curiosity_reward_is_zero_until_the_first_update_then_the_capped_forward_error():
    torch.manual_seed(0)
    provider = CuriosityProvider(SPEC, strength=0.5, network=NET)
    exp = experience()
    assert provider.evaluate(exp).tolist() == [0.0] * 6  # no update yet: no curiosity
    forward_error, inverse = curiosity_by_hand(provider, exp)
    stats = provider.update(exp)
    assert stats["Losses/Curiosity Forward Loss"] == pytest.approx(forward_error.mean(), rel=1e-5)
    assert stats["Losses/Curiosity Inverse Loss"] == pytest.approx(inverse, rel=1e-5)
    forward_error, _ = curiosity_by_hand(provider, exp)  # weights moved: evaluate with the new ones
    np.testing.assert_allclose(provider.evaluate(exp), np.minimum(forward_error, 1 / 0.5), rtol=1e-5)
    low = CuriosityProvider(SPEC, strength=50.0, network=NET)  # cap 1/strength = 0.02
    low.update(exp)
    capped = low.evaluate(exp)
    assert capped.max() <= 0.02 + 1e-9 and np.isclose(capped, 0.02).any()


def test_curiosity_learns_its_transitions():
    torch.manual_seed(1)
    provider = CuriosityProvider(SPEC, strength=1.0, network=NET)
    exp = experience(32, seed=3)
    first = [provider.update(exp) for _ in range(200)]
    assert first[-1]["Losses/Curiosity Forward Loss"] < 0.5 * first[0]["Losses/Curiosity Forward Loss"]
    assert first[-1]["Losses/Curiosity Inverse Loss"] < 0.8 * first[0]["Losses/Curiosity Inverse Loss"]


def test_rnd_reward_is_the_prediction_error_and_training_lowers_it():
    torch.manual_seed(2)
    provider = RNDProvider(SPEC, strength=1.0, network=NET)
    exp = experience(16, seed=4)
    target_before = weights(provider.target)
    w_t, w_p = weights(provider.target), weights(provider.predictor)
    x = exp.obs[0].numpy().astype(np.float64)
    by_hand = ((body(w_p, "", x) - body(w_t, "", x)) ** 2).sum(1)
    np.testing.assert_allclose(provider.evaluate(exp), by_hand, rtol=1e-5)
    losses = [provider.update(exp)["Losses/RND Loss"] for _ in range(300)]
    assert losses[0] == pytest.approx(by_hand.mean(), rel=1e-5)
    assert losses[-1] < 0.2 * losses[0]
    assert all(np.array_equal(target_before[k], v) for k, v in weights(provider.target).items())  # frozen


def test_rnd_normalisers_follow_every_pass_when_asked():
    torch.manual_seed(3)
    provider = RNDProvider(SPEC, strength=1.0, network=replace(NET, normalize=True))
    exp = experience(10, seed=5)
    provider.evaluate(exp)
    provider.update(exp)
    for net in (provider.target, provider.predictor):
        steps = [v for k, v in net.state_dict().items() if k.endswith("normalization_steps")]
        assert [int(s) for s in steps] == [1 + 2 * 10]  # starts at 1, +10 per pass


HYPER = PPOHyperparams(hidden_units=16, num_layers=1, batch_size=4, buffer_size=8, num_epoch=2, max_steps=1000,
                       lambd=0.8, reward_signals={"extrinsic": (0.9, 1.0), "curiosity": (0.95, 0.1),
                                                  "rnd": (0.99, 0.01)},
                       reward_signal_networks={"curiosity": NET, "rnd": replace(NET, hidden_units=4)})


def test_intrinsic_returns_bootstrap_through_done_and_sum_per_episode():
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    trainer.providers["curiosity"].has_updated = True  # so its rewards are not all zero
    first = replace(make_trajectory(trainer, 4, False, False, seed=1), episode="a")
    last = replace(make_trajectory(trainer, 3, True, False, seed=2), episode="a")
    stats_first = trainer.process_trajectory(first)
    assert "Policy/Curiosity Reward" not in stats_first  # reported once the episode ends
    expected = {}
    for traj in (first, last):
        obs, nxt = traj.obs[0], np.concatenate([traj.obs[0][1:], traj.next_obs[0][None]])
        exp = Experience([obs], [nxt], traj.continuous_actions, traj.discrete_actions)
        expected[id(traj)] = {"curiosity": trainer.providers["curiosity"].evaluate(exp) * np.float32(0.1)}
    stats = trainer.process_trajectory(last)
    data = trainer.buffer.concatenated()
    np.testing.assert_array_equal(data["next_obs_0"][4:6], last.obs[0][1:])  # step t+1's obs ...
    np.testing.assert_array_equal(data["next_obs_0"][6], last.next_obs[0])   # ... then the terminal obs
    with torch.no_grad():
        values = trainer.critic([torch.from_numpy(last.obs[0])])
        next_values = trainer.critic([torch.from_numpy(last.next_obs[0][None])])
    cur_rewards = expected[id(last)]["curiosity"]
    adv = expected_advantages(cur_rewards, values["curiosity"].numpy(), next_values["curiosity"].item(), 0.95, 0.8)
    np.testing.assert_allclose(data["returns:curiosity"][4:], adv + values["curiosity"].numpy(), rtol=1e-4, atol=1e-6)
    ext = expected_advantages(last.rewards, values["extrinsic"].numpy(), 0.0, 0.9, 0.8)  # done: no bootstrap
    np.testing.assert_allclose(data["returns:extrinsic"][4:], ext + values["extrinsic"].numpy(), rtol=1e-4, atol=1e-6)
    assert stats["Policy/Curiosity Reward"] == pytest.approx(
        float(expected[id(first)]["curiosity"].sum() + cur_rewards.sum()), rel=1e-5)
    assert "Policy/Rnd Reward" in stats and "Policy/Rnd Value Estimate" in stats
    assert trainer._episode_intrinsic == {}  # nothing kept for ended episodes


@pytest.mark.parametrize("numpy_path", [True, False])
def test_update_steps_the_providers_on_every_minibatch(numpy_path):
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    trainer.numpy_update = numpy_path
    for seed in range(3):
        trainer.process_trajectory(make_trajectory(trainer, 4, False, False, seed=seed))
    before = weights(trainer.providers["rnd"].predictor)
    stats = trainer.update()
    assert trainer.providers["curiosity"].optimizer.step_count == 2 * (12 // 4)  # num_epoch x minibatches
    assert trainer.providers["rnd"].optimizer.step_count == 6
    assert trainer.providers["curiosity"].has_updated
    assert any(not np.array_equal(before[k], v) for k, v in weights(trainer.providers["rnd"].predictor).items())
    for key in ("Losses/Curiosity Forward Loss", "Losses/Curiosity Inverse Loss", "Losses/RND Loss",
                "Losses/Policy Loss"):
        assert np.isfinite(stats[key])


def test_providers_survive_a_checkpoint_and_a_missing_one_starts_fresh(tmp_path, caplog):
    from trainer.artifacts.checkpoints import load_checkpoint, save_checkpoint

    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    for seed in range(3):
        trainer.process_trajectory(make_trajectory(trainer, 4, False, False, seed=seed))
    trainer.update()
    save_checkpoint(tmp_path / "c.pt", trainer.state_dict())
    state = load_checkpoint(tmp_path / "c.pt")
    assert {"Module:Curiosity", "Module:RND-pred", "Module:RND-target"} <= set(state)
    restored = PPOTrainer("Ball", SPEC, HYPER, seed=7)
    restored.load_state_dict(state)
    for name in ("curiosity", "rnd"):
        a, b = trainer.providers[name], restored.providers[name]
        assert a.optimizer.step_count == b.optimizer.step_count == 6
        for key, value in a.state_dict().items():
            if key.startswith("Module:"):
                assert all(torch.equal(value[k], b.state_dict()[key][k]) for k in value)
    assert restored.providers["curiosity"].has_updated
    exp = experience()
    np.testing.assert_array_equal(trainer.providers["curiosity"].evaluate(exp),
                                  restored.providers["curiosity"].evaluate(exp))
    for key in ("Module:Curiosity", "Optimizer:Curiosity"):
        del state[key]
    fresh = PPOTrainer("Ball", SPEC, HYPER, seed=7)
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        fresh.load_state_dict(state)
    assert "no curiosity reward signal" in caplog.text
    assert not fresh.providers["curiosity"].has_updated and fresh.providers["rnd"].optimizer.step_count == 6


def test_a_checkpoint_from_before_a_signal_was_added_or_removed_still_loads(caplog):
    plain = PPOTrainer("Ball", SPEC, replace(HYPER, reward_signals={"extrinsic": (0.9, 1.0)},
                                             reward_signal_networks={}), seed=0)
    for seed in range(3):
        plain.process_trajectory(make_trajectory(plain, 4, False, False, seed=seed))
    plain.update()
    grown = PPOTrainer("Ball", SPEC, HYPER, seed=5)
    untrained_head = grown.critic.value_heads["curiosity"].weight.clone()
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        grown.load_state_dict(plain.state_dict())
    assert "reward signals differ from the checkpoint's (curiosity, rnd)" in caplog.text
    assert torch.equal(grown.critic.value_heads["extrinsic"].weight, plain.critic.value_heads["extrinsic"].weight)
    assert torch.equal(grown.critic.value_heads["curiosity"].weight, untrained_head)
    assert grown.step == plain.step and grown.optimizer.step_count == 0  # fresh moments for the new layout
    shrunk = PPOTrainer("Ball", SPEC, replace(HYPER, reward_signals={"extrinsic": (0.9, 1.0)},
                                              reward_signal_networks={}), seed=5)
    shrunk.load_state_dict(grown.state_dict())  # the other way round: extra heads are dropped
    assert torch.equal(shrunk.critic.value_heads["extrinsic"].weight, plain.critic.value_heads["extrinsic"].weight)
    wider = PPOTrainer("Ball", SPEC, replace(HYPER, hidden_units=32), seed=5)
    with pytest.raises(RuntimeError, match="size mismatch"):  # a different network is still refused
        wider.load_state_dict(grown.state_dict())
