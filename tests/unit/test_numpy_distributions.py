"""trainer/common/numpy_distributions.py against trainer/common/distributions.py: every value
equal to the torch function's in float32 (sums within their rounding), every gradient equal to
autograd's, on random inputs with masked options, and the entropies by hand."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from trainer.common import distributions as td
from trainer.common import numpy_distributions as nd

RNG = np.random.default_rng(7)
N, C, K = 9, 3, 4


def arrays():
    actions = RNG.standard_normal((N, C)).astype(np.float32)
    mu = RNG.standard_normal((N, C)).astype(np.float32)
    log_sigma = (RNG.standard_normal((1, C)) * 0.5).astype(np.float32)
    logits = RNG.standard_normal((N, K)).astype(np.float32)
    allowed = (RNG.random((N, K)) > 0.3).astype(np.float32)
    allowed[:, 0] = 1.0  # at least one option allowed per row
    choice = np.array([RNG.choice(np.flatnonzero(row)) for row in allowed])
    return actions, mu, log_sigma, logits, allowed, choice


def t(a):
    return torch.tensor(a)


def test_the_names_mirror_distributions_py():
    torch_names = {name for name in dir(td) if not name.startswith("_") and callable(getattr(td, name))
                   and getattr(td, name).__module__ == td.__name__}
    assert torch_names <= set(nd.__all__)
    assert nd.EPSILON == td.EPSILON and nd.MASKED_LOGIT_OFFSET == td.MASKED_LOGIT_OFFSET


def test_values_equal_the_torch_functions():
    actions, mu, log_sigma, logits, allowed, choice = arrays()
    np.testing.assert_array_equal(nd.gaussian_log_prob(actions, mu, log_sigma),
                                  td.gaussian_log_prob(t(actions), t(mu), t(log_sigma)).numpy())
    np.testing.assert_allclose(nd.gaussian_log_prob(actions, mu, log_sigma, float64_constant=True),
                               nd.gaussian_log_prob(actions, mu, log_sigma), rtol=1e-6)
    np.testing.assert_array_equal(nd.gaussian_entropy(log_sigma), td.gaussian_entropy(t(log_sigma)).numpy())
    masked = nd.mask_logits(logits, allowed)
    np.testing.assert_array_equal(masked, td.mask_logits(t(logits), t(allowed)).numpy())
    probs = nd.softmax(masked)
    np.testing.assert_allclose(probs, torch.softmax(t(masked), dim=1).numpy(), rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(nd.categorical_log_prob(probs, choice),
                                  td.categorical_log_prob(t(probs), t(choice)).numpy())
    # numpy's and torch's log may round apart by one float32 unit on some of the K values
    np.testing.assert_allclose(nd.categorical_option_log_probs(probs),
                               td.categorical_option_log_probs(t(probs)).numpy(), rtol=3e-7, atol=1e-7)
    # a sum over the options: numpy and torch add in another order (one float32 rounding apart)
    np.testing.assert_allclose(nd.categorical_entropy(probs), td.categorical_entropy(t(probs)).numpy(), rtol=3e-7)


def test_the_squashed_gaussian_equals_the_torch_functions():
    _, mu, _, _, _, _ = arrays()
    log_sigma = (RNG.standard_normal((N, C)) * 0.5).astype(np.float32)  # SAC's sigma is a head: per row
    noise = RNG.standard_normal((N, C)).astype(np.float32)
    raw, action = nd.squashed_sample(mu, log_sigma, noise)
    raw_t, action_t = td.squashed_sample(t(mu), t(log_sigma), t(noise))
    # numpy's and torch's exp and tanh may round apart by one float32 unit
    np.testing.assert_allclose(raw, raw_t.numpy(), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(action, action_t.numpy(), rtol=1e-6, atol=1e-6)
    # float64 constant (SAC's numpy paths), and softplus vs logaddexp: a float32 rounding apart
    np.testing.assert_allclose(nd.squashed_log_prob(raw, mu, log_sigma),
                               td.squashed_log_prob(raw_t, t(mu), t(log_sigma)).numpy(), rtol=1e-5, atol=1e-5)
    big = np.array([[30.0, -30.0]], np.float32)  # log |tanh'(x)| ~ log 4 - 2|x|, no overflow
    np.testing.assert_allclose(nd.tanh_log_abs_det_jacobian(big), [[math.log(4) - 60] * 2], rtol=1e-6)


def test_combined_entropy_equals_the_torch_function():
    _, _, log_sigma, logits, _, _ = arrays()
    probs = nd.softmax(logits)
    branches = [nd.categorical_entropy(probs[:, :2]), nd.categorical_entropy(probs[:, 2:])]
    shared = nd.combined_entropy(nd.gaussian_entropy(log_sigma), branches, N)  # sigma [1, C], as PPO's
    expected = td.combined_entropy(td.gaussian_entropy(t(log_sigma)).expand(N, C), [t(b) for b in branches])
    assert shared.dtype == np.float32 and shared.shape == (N,)
    np.testing.assert_allclose(shared, expected.numpy(), rtol=1e-6)
    np.testing.assert_array_equal(nd.combined_entropy(None, branches[:1], N), branches[0])


def test_entropies_by_hand():
    # sigma = 1: 0.5 log(2 pi e); uniform over 4 options: log 4 (both up to the 1e-7 inside the log)
    assert nd.gaussian_entropy(np.zeros((1, 1), np.float32))[0, 0] == pytest.approx(
        0.5 * math.log(2 * math.pi * math.e), abs=1e-6)
    assert nd.categorical_entropy(np.full((1, 4), 0.25, np.float32))[0] == pytest.approx(math.log(4), abs=1e-6)


def test_gradients_equal_autograd():
    actions, mu, log_sigma, logits, allowed, choice = arrays()
    grad_out = RNG.standard_normal((N, C)).astype(np.float32)
    mu_t, ls_t = t(mu).requires_grad_(), t(log_sigma).requires_grad_()
    (td.gaussian_log_prob(t(actions), mu_t, ls_t) * t(grad_out)).sum().backward()
    grad_mu, grad_ls = nd.gaussian_log_prob_grads(actions, mu, log_sigma, grad_out)
    np.testing.assert_allclose(grad_mu, mu_t.grad.numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(grad_ls.sum(axis=0, keepdims=True), ls_t.grad.numpy(), rtol=1e-5, atol=1e-6)

    ls_t = t(log_sigma).requires_grad_()
    td.gaussian_entropy(ls_t).sum().backward()
    np.testing.assert_allclose(nd.gaussian_entropy_grad(log_sigma), ls_t.grad.numpy(), rtol=1e-6)

    grad_lp = RNG.standard_normal(N).astype(np.float32)
    logits_t = t(logits).requires_grad_()
    probs_t = torch.softmax(td.mask_logits(logits_t, t(allowed)), dim=1)
    (td.categorical_log_prob(probs_t, t(choice)) * t(grad_lp)).sum().backward()
    probs = nd.softmax(nd.mask_logits(logits, allowed))
    np.testing.assert_allclose(nd.categorical_log_prob_grad(probs, choice, grad_lp) * allowed,
                               logits_t.grad.numpy(), rtol=1e-5, atol=1e-6)

    logits_t = t(logits).requires_grad_()
    td.categorical_entropy(torch.softmax(td.mask_logits(logits_t, t(allowed)), dim=1)).sum().backward()
    np.testing.assert_allclose(nd.categorical_entropy_grad(probs) * allowed, logits_t.grad.numpy(),
                               rtol=1e-4, atol=1e-6)


def test_squashed_sample_gradients_equal_autograd():
    """Back through the reparameterised sample and its log-prob (SAC's policy loss reaches mu and
    log sigma both ways), for a loss sum(g_a * a) + k * sum(log pi)."""
    _, mu, _, _, _, _ = arrays()
    log_sigma = (RNG.standard_normal((N, C)) * 0.5).astype(np.float32)
    noise = RNG.standard_normal((N, C)).astype(np.float32)
    grad_action = RNG.standard_normal((N, C)).astype(np.float32)
    k = np.float32(0.37)
    mu_t, ls_t = t(mu).requires_grad_(), t(log_sigma).requires_grad_()
    raw_t, action_t = td.squashed_sample(mu_t, ls_t, t(noise))
    ((action_t * t(grad_action)).sum() + float(k) * td.squashed_log_prob(raw_t, mu_t, ls_t).sum()).backward()
    raw, action = nd.squashed_sample(mu, log_sigma, noise)
    grad_mu, grad_ls = nd.squashed_sample_grads(raw, action, mu, log_sigma, noise, grad_action, k)
    np.testing.assert_allclose(grad_mu, mu_t.grad.numpy(), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(grad_ls, ls_t.grad.numpy(), rtol=1e-4, atol=1e-5)


def test_terms_computed_once_give_the_same_bits():
    """``terms=`` and ``option_log_probs=`` (what acting caches and PPO's step shares) change no bit."""
    actions, mu, log_sigma, logits, _, choice = arrays()
    terms = nd.gaussian_terms(log_sigma)
    grad = RNG.standard_normal((N, C)).astype(np.float32)
    for constant in (False, True):
        assert np.array_equal(nd.gaussian_log_prob(actions, mu, log_sigma, constant, terms=terms),
                              nd.gaussian_log_prob(actions, mu, log_sigma, constant))
    for shared, alone in zip(nd.gaussian_log_prob_grads(actions, mu, log_sigma, grad, terms),
                             nd.gaussian_log_prob_grads(actions, mu, log_sigma, grad)):
        assert np.array_equal(shared, alone)
    assert np.array_equal(nd.gaussian_entropy_grad(log_sigma, terms), nd.gaussian_entropy_grad(log_sigma))
    probs = nd.softmax(logits)
    option_log_probs = nd.categorical_option_log_probs(probs)
    assert np.array_equal(nd.categorical_entropy(probs, option_log_probs), nd.categorical_entropy(probs))
    assert np.array_equal(nd.categorical_entropy_grad(probs, option_log_probs), nd.categorical_entropy_grad(probs))
