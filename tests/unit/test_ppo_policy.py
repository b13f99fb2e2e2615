"""Policy.act: one batched pass, shapes/dtypes, clamped env actions, log-probs, masks and seeding."""
from __future__ import annotations

import math

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
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.policy import Policy

HYPER = PPOHyperparams(hidden_units=16, num_layers=2)


def make_spec(continuous: int, branches: tuple[int, ...], obs_size: int = 4) -> BehaviorSpec:
    obs = ObservationSpec((obs_size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector")
    return BehaviorSpec((obs,), ActionSpec(continuous, branches))


@pytest.mark.parametrize("n", [0, 1, 256])
def test_hybrid_shapes_and_dtypes(n):
    policy = Policy(make_spec(2, (3, 2)), HYPER, seed=1)
    out = policy.act([np.random.randn(n, 4).astype(np.float32)], np.zeros((n, 5), dtype=bool))
    assert out.env_actions.continuous.shape == (n, 2) and out.env_actions.continuous.dtype == np.float32
    assert out.env_actions.discrete.shape == (n, 2) and out.env_actions.discrete.dtype == np.int32
    assert out.continuous_raw.shape == (n, 2) and out.continuous_raw.dtype == np.float32
    assert out.discrete.shape == (n, 2) and out.discrete.dtype == np.int32
    assert out.log_probs.shape == (n, 4) and out.log_probs.dtype == np.float32
    assert out.entropy.shape == (n,)
    np.testing.assert_array_equal(out.env_actions.discrete, out.discrete)


def test_env_actions_are_clamped_raw_over_three():
    policy = Policy(make_spec(3, ()), HYPER, seed=2)
    with torch.no_grad():
        policy.actor.log_sigma.fill_(math.log(4.0))  # wide enough that many samples exceed +-3
    out = policy.act([np.zeros((200, 4), np.float32)])
    assert np.abs(out.continuous_raw).max() > 3.0
    np.testing.assert_allclose(out.env_actions.continuous, np.clip(out.continuous_raw, -3, 3) / 3, rtol=1e-6)
    assert out.env_actions.discrete.shape == (200, 0)


def test_log_probs_and_entropy_follow_the_distributions():
    policy = Policy(make_spec(2, (3,)), HYPER, seed=3)
    with torch.no_grad():
        policy.actor.log_sigma.copy_(torch.tensor([[0.0, math.log(0.5)]]))
    obs = np.random.default_rng(0).normal(size=(6, 4)).astype(np.float32)
    out = policy.act([obs])
    with torch.no_grad():
        mu, logits = policy.actor.heads([torch.from_numpy(obs)], None)
    mu, logits = mu.numpy(), logits[0].numpy()
    sigma = np.array([1.0, 0.5])
    expected_cont = -((out.continuous_raw - mu) ** 2) / (2 * sigma**2) - np.log(sigma) - 0.5 * np.log(2 * np.pi)
    np.testing.assert_allclose(out.log_probs[:, :2], expected_cont, rtol=1e-4, atol=1e-5)
    log_softmax = logits - np.log(np.exp(logits).sum(1, keepdims=True))
    expected_disc = log_softmax[np.arange(6), out.discrete[:, 0]]
    np.testing.assert_allclose(out.log_probs[:, 2], expected_disc, rtol=1e-4, atol=1e-5)
    probs = np.exp(log_softmax)
    gaussian = np.mean(0.5 * np.log(2 * np.pi * np.e * sigma**2))
    np.testing.assert_allclose(out.entropy, gaussian - (probs * np.log(probs)).sum(1), rtol=1e-4)


def test_masked_options_are_never_chosen():
    policy = Policy(make_spec(0, (3, 2)), HYPER, seed=4)
    n = 256
    mask = np.zeros((n, 5), dtype=bool)
    mask[:, 1] = True  # branch 0 option 1 masked for everyone
    mask[: n // 2, 3] = True  # branch 1 option 0 masked for the first half
    for _ in range(4):
        out = policy.act([np.random.randn(n, 4).astype(np.float32)], mask)
        assert not np.any(out.discrete[:, 0] == 1)
        assert np.all(out.discrete[: n // 2, 1] == 1)
    assert set(np.unique(out.discrete[:, 0])) == {0, 2}


def test_deterministic_uses_mean_and_argmax():
    policy = Policy(make_spec(2, (4,)), HYPER, seed=5)
    obs = np.random.randn(8, 4).astype(np.float32)
    out = policy.act([obs], deterministic=True)
    with torch.no_grad():
        mu, logits = policy.actor.heads([torch.from_numpy(obs)], None)
    np.testing.assert_allclose(out.continuous_raw, mu.numpy(), rtol=1e-5, atol=1e-7)  # numpy vs torch float32 rounding
    np.testing.assert_array_equal(out.discrete[:, 0], logits[0].argmax(1).numpy())


def test_same_seed_same_actions_other_seed_differs():
    obs = [np.random.randn(32, 4).astype(np.float32)]
    first = Policy(make_spec(2, (3,)), HYPER, seed=7).act(obs)
    again = Policy(make_spec(2, (3,)), HYPER, seed=7).act(obs)
    other = Policy(make_spec(2, (3,)), HYPER, seed=8).act(obs)
    np.testing.assert_array_equal(first.continuous_raw, again.continuous_raw)
    np.testing.assert_array_equal(first.discrete, again.discrete)
    assert not np.allclose(first.continuous_raw, other.continuous_raw)


def test_construction_does_not_touch_global_rng():
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    Policy(make_spec(2, (3,)), HYPER, seed=9).act([np.zeros((4, 4), np.float32)])
    torch.testing.assert_close(torch.rand(3), expected)
