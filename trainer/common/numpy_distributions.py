"""distributions.py in numpy, name for name, with the gradients the numpy updates take of them.

Every numpy path computes the action distributions here: acting (common/policy.py and
sac/policy.py), PPO's minibatch step (ppo/numpy_update.py) and SAC's gradient step
(sac/numpy_step.py), whose reparameterised squashed sample takes its gradient from
``squashed_sample_grads``. The expressions are those of the torch functions in the same order, so a
value here equals the torch one computed in float32 (a sum over options may round once
differently: numpy adds in another order); tests/unit/test_numpy_distributions.py checks every
value against distributions.py and every gradient against autograd.

One deliberate difference, ``float64_constant``: acting and SAC's step have subtracted the
Gaussian's log sqrt(2 pi) in float64 since they were written, PPO's update (like torch) in
float32. Each path keeps its own so that the same seed still gives the same numbers (the squashed
Gaussian's log-prob is SAC's only, so float64 there).

Shapes: n = batch, c = continuous dimensions, k = options of one discrete branch.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


# the constants of both modules, here so that acting needs no torch (distributions.py imports them)
EPSILON = 1e-7  # as ML-Agents, so log-probs and entropies agree numerically
MASKED_LOGIT_OFFSET = 1e8
LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))  # a Python float: float32 arithmetic, as torch's
_LOG_SQRT_2PI_FLOAT64 = np.float64(0.5 * np.log(2 * np.pi))
_LOG_2 = np.log(2.0)
TWO_PI_E = 2 * math.pi * math.e
_MAX, _SUM = np.maximum.reduce, np.add.reduce  # ndarray.max/sum without their Python wrappers

__all__ = ["EPSILON", "MASKED_LOGIT_OFFSET", "GaussianTerms", "gaussian_terms", "gaussian_log_prob", "gaussian_log_prob_grads", "gaussian_entropy",
           "gaussian_entropy_grad", "tanh_log_abs_det_jacobian", "squashed_sample", "squashed_log_prob",
           "squashed_sample_grads", "mask_logits", "softmax", "categorical_log_prob", "categorical_log_prob_grad",
           "categorical_option_log_probs", "categorical_entropy", "categorical_entropy_grad", "combined_entropy"]


# ---------------------------------------------------------------------------------- Gaussian
class GaussianTerms(NamedTuple):
    """What the Gaussian's log-prob and its gradients need of log_sigma alone, computed once by
    ``gaussian_terms`` and passed as ``terms=`` where log_sigma is shared: acting caches them
    while the parameters do not change (numpy_net.NumpyActor.gaussian), PPO's minibatch step
    computes them once for its log-probs, their gradients and the entropy's gradient. The same
    expressions as computed inline, so the numbers are the same with or without."""

    sigma: np.ndarray  # exp(log_sigma)
    denom: np.ndarray  # 2 sigma^2 + EPSILON
    log_term: np.ndarray  # log(sigma + EPSILON)


def gaussian_terms(log_sigma: np.ndarray) -> GaussianTerms:
    """``GaussianTerms`` of log_sigma ([1, c] or [n, c], each term the same shape)."""
    sigma = np.exp(log_sigma)
    return GaussianTerms(sigma, 2 * sigma**2 + EPSILON, np.log(sigma + EPSILON))


def gaussian_log_prob(actions: np.ndarray, mu: np.ndarray, log_sigma: np.ndarray,
                      float64_constant: bool = False, terms: GaussianTerms | None = None) -> np.ndarray:
    """Per-dimension log N(a; mu, sigma). actions, mu [n, c]; log_sigma [1, c] or [n, c] -> [n, c]
    (float64 with ``float64_constant``); ``terms``: ``gaussian_terms(log_sigma)`` if at hand."""
    if terms is None:
        terms = gaussian_terms(log_sigma)
    constant = _LOG_SQRT_2PI_FLOAT64 if float64_constant else LOG_SQRT_2PI
    return -((actions - mu) ** 2) / terms.denom - terms.log_term - constant


def gaussian_log_prob_grads(actions: np.ndarray, mu: np.ndarray, log_sigma: np.ndarray, grad: np.ndarray,
                            terms: GaussianTerms | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``grad`` [n, c] (d loss / d log-prob) taken back through ``gaussian_log_prob``: (d loss / d mu
    [n, c], d loss / d log_sigma per element [n, c]; sum it over rows for a shared log_sigma)."""
    if terms is None:
        terms = gaussian_terms(log_sigma)
    sigma, denom = terms.sigma, terms.denom
    diff = actions - mu
    grad_mu = grad * 2.0 * diff / denom
    grad_log_sigma = grad * (diff ** 2 * 4.0 * sigma ** 2 / denom ** 2 - sigma / (sigma + EPSILON))
    return grad_mu, grad_log_sigma


def gaussian_entropy(log_sigma: np.ndarray) -> np.ndarray:
    """Per-dimension entropy 0.5*log(2*pi*e*sigma^2). log_sigma [.., c] -> [.., c]."""
    return 0.5 * np.log(TWO_PI_E * np.exp(log_sigma) ** 2 + EPSILON)


def gaussian_entropy_grad(log_sigma: np.ndarray, terms: GaussianTerms | None = None) -> np.ndarray:
    """d gaussian_entropy / d log_sigma, per element. [.., c] -> [.., c]."""
    sigma = np.exp(log_sigma) if terms is None else terms.sigma
    return TWO_PI_E * sigma ** 2 / (TWO_PI_E * sigma ** 2 + EPSILON)


# ---------------------------------------------------------------------------------- squashed (SAC)
def tanh_log_abs_det_jacobian(raw: np.ndarray) -> np.ndarray:
    """log |d tanh(x) / dx| = 2 (log 2 - x - softplus(-2x)), stable for large |x|. [n, c] -> [n, c]."""
    return 2.0 * (_LOG_2 - raw - np.logaddexp(0.0, -2.0 * raw))


def squashed_sample(mu: np.ndarray, log_sigma: np.ndarray, noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reparameterised sample of a tanh-squashed Gaussian: (raw = mu + noise sigma, tanh(raw)). [n, c] each."""
    raw = mu + noise * np.exp(log_sigma)
    return raw, np.tanh(raw)


def squashed_log_prob(raw: np.ndarray, mu: np.ndarray, log_sigma: np.ndarray) -> np.ndarray:
    """Per-dimension log-density of tanh(raw) with raw ~ N(mu, sigma), float64. [n, c] -> [n, c]."""
    return gaussian_log_prob(raw, mu, log_sigma, float64_constant=True) - tanh_log_abs_det_jacobian(raw)


def squashed_sample_grads(raw: np.ndarray, action: np.ndarray, mu: np.ndarray, log_sigma: np.ndarray,
                          noise: np.ndarray, grad_action: np.ndarray, grad_log_prob: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Back through ``squashed_sample`` and the ``squashed_log_prob`` of its sample, with the noise
    held: ``grad_action`` (d loss / d tanh(raw), [n, c]) and ``grad_log_prob`` (d loss / d log-prob,
    broadcast to [n, c]) -> (d loss / d mu [n, c], d loss / d log_sigma [n, c])."""
    # d log-prob / d raw = 2 tanh(raw) - d log N / d mu; raw moves with mu (1) and log_sigma (noise sigma)
    sigma = np.exp(log_sigma)
    diff = raw - mu
    denom = 2.0 * sigma ** 2 + EPSILON
    gauss = 2.0 * diff / denom  # d log N / d mu = -d log N / d raw
    grad_raw = grad_action * (1.0 - action ** 2) + grad_log_prob * (2.0 * action - gauss)
    grad_mu = grad_raw + grad_log_prob * gauss
    grad_sigma = noise * grad_raw + grad_log_prob * (diff ** 2 * 4.0 * sigma / denom ** 2 - 1.0 / (sigma + EPSILON))
    return grad_mu, sigma * grad_sigma


# ---------------------------------------------------------------------------------- categorical
def mask_logits(logits: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """logits * allowed - 1e8 * (1 - allowed). logits, allowed (float, 1 = allowed) [n, k] -> [n, k]."""
    return logits * allowed - MASKED_LOGIT_OFFSET * (1.0 - allowed)


def softmax(logits: np.ndarray) -> np.ndarray:
    """torch.softmax(logits, dim=1): exp(x - max) / sum. [n, k] -> [n, k]."""
    z = np.exp(logits - _MAX(logits, axis=1, keepdims=True))
    return z / _SUM(z, axis=1, keepdims=True)


def categorical_log_prob(probs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """log(p[action] + EPSILON). probs [n, k]; actions int [n] -> [n]."""
    return np.log(probs[np.arange(len(probs)), actions] + EPSILON)


def categorical_log_prob_grad(probs: np.ndarray, actions: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """``grad`` [n] (d loss / d log-prob) taken back through ``categorical_log_prob`` of
    ``softmax(logits)`` to the logits: [n, k]."""
    n = len(probs)
    chosen = probs[np.arange(n), actions]
    onehot = np.zeros_like(probs)
    onehot[np.arange(n), actions] = 1.0
    return (grad * chosen / (chosen + EPSILON))[:, None] * (onehot - probs)


def categorical_option_log_probs(probs: np.ndarray) -> np.ndarray:
    """log(p + EPSILON) of every option (SAC's losses weigh each option). probs [n, k] -> [n, k]."""
    return np.log(probs + EPSILON)


def categorical_entropy(probs: np.ndarray, option_log_probs: np.ndarray | None = None) -> np.ndarray:
    """-sum_k p log(p + EPSILON). probs [n, k] -> [n]; ``option_log_probs``:
    ``categorical_option_log_probs(probs)`` if at hand (PPO's step shares it with the gradient)."""
    if option_log_probs is None:
        option_log_probs = categorical_option_log_probs(probs)
    return -np.sum(probs * option_log_probs, axis=1)


def categorical_entropy_grad(probs: np.ndarray, option_log_probs: np.ndarray | None = None) -> np.ndarray:
    """d categorical_entropy(softmax(logits)) / d logits. probs [n, k] -> [n, k]."""
    if option_log_probs is None:
        option_log_probs = categorical_option_log_probs(probs)
    # d/dp_j of -sum p log(p + eps) = -log(p_j + eps) - p_j / (p_j + eps), then through the softmax
    d_entropy = -option_log_probs - probs / (probs + EPSILON)
    return probs * (d_entropy - np.sum(probs * d_entropy, axis=1, keepdims=True))


def combined_entropy(continuous_entropy: np.ndarray | None, discrete_entropies: list[np.ndarray], rows: int
                     ) -> np.ndarray:
    """Policy entropy per agent, float32 [rows]: mean over the Gaussian's dimensions ([rows, c], or
    [1, c] for a state-independent sigma) plus the sum of the branch entropies ([rows] each)."""
    total = np.zeros(rows, dtype=np.float32)
    if continuous_entropy is not None:
        total = total + np.mean(continuous_entropy, axis=1)
    for branch_entropy in discrete_entropies:
        total = total + branch_entropy
    return total.astype(np.float32)
