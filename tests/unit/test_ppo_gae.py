"""GAE, discounted returns and decay schedules against numbers worked out by hand."""
from __future__ import annotations

import numpy as np
import pytest

from trainer.common.gae import discounted_returns, gae
from trainer.common.schedules import decay


def test_discounted_returns_by_hand():
    # G2 = 2 + 0.5*4 = 4, G1 = 0 + 0.5*4 = 2, G0 = 1 + 0.5*2 = 2
    result = discounted_returns(np.array([1.0, 0.0, 2.0]), gamma=0.5, bootstrap_value=4.0)
    assert result.dtype == np.float32
    np.testing.assert_allclose(result, [2.0, 2.0, 4.0], rtol=1e-6)


def test_gae_by_hand():
    rewards = np.array([1.0, 0.0, 2.0], dtype=np.float32)
    values = np.array([0.5, 1.0, 0.5], dtype=np.float32)
    # deltas: 1 + .9*1 - .5 = 1.4 ; 0 + .9*.5 - 1 = -0.55 ; 2 + .9*2 - .5 = 3.3 ; gamma*lambda = 0.72
    # A2 = 3.3 ; A1 = -0.55 + .72*3.3 = 1.826 ; A0 = 1.4 + .72*1.826 = 2.71472
    advantages, returns = gae(rewards, values, bootstrap_value=2.0, gamma=0.9, lambd=0.8)
    assert advantages.dtype == np.float32 and returns.dtype == np.float32
    np.testing.assert_allclose(advantages, [2.71472, 1.826, 3.3], rtol=1e-5)
    np.testing.assert_allclose(returns, [3.21472, 2.826, 3.8], rtol=1e-5)


def test_gae_lambda_one_is_discounted_return_minus_value():
    rng = np.random.default_rng(0)
    rewards, values = rng.normal(size=7), rng.normal(size=7)
    advantages, returns = gae(rewards, values, bootstrap_value=0.3, gamma=0.95, lambd=1.0)
    expected = [sum(0.95**k * rewards[t + k] for k in range(7 - t)) + 0.95 ** (7 - t) * 0.3 for t in range(7)]
    np.testing.assert_allclose(returns, expected, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(advantages, np.array(expected) - values, rtol=1e-5, atol=1e-5)


def test_gae_lambda_zero_is_one_step_td_error():
    advantages, _ = gae(np.array([1.0, 2.0]), np.array([3.0, 4.0]), bootstrap_value=5.0, gamma=0.5, lambd=0.0)
    np.testing.assert_allclose(advantages, [1 + 0.5 * 4 - 3, 2 + 0.5 * 5 - 4], rtol=1e-6)


def test_linear_decay_by_hand():
    # (3e-4 - 1e-10) * (1 - 250/1000) + 1e-10
    assert decay("linear", 3e-4, 1e-10, 250, 1000) == pytest.approx(2.2500002500e-4, rel=1e-9)
    assert decay("linear", 0.2, 0.1, 500, 1000) == pytest.approx(0.15)
    assert decay("linear", 5e-3, 1e-5, 0, 1000) == pytest.approx(5e-3)
    assert decay("linear", 5e-3, 1e-5, 5000, 1000) == pytest.approx(1e-5)  # capped at the floor


def test_constant_and_unknown_schedule():
    assert decay("constant", 0.2, 0.1, 999, 1000) == 0.2
    with pytest.raises(ValueError, match="schedule"):
        decay("cosine", 0.2, 0.1, 1, 10)
