"""distributions.py in numpy, name for name, with the gradients the numpy updates take of them.

Every numpy path computes the action distributions here: acting (common/policy.py and
sac/policy.py), PPO's minibatch step (ppo/numpy_update.py) and SAC's gradient step
(sac/numpy_step.py). The expressions are those of the torch functions in the same order, so a
value here equals the torch one computed in float32 (a sum over options may round once
differently: numpy adds in another order); tests/unit/test_numpy_distributions.py checks every
value against distributions.py and every gradient against autograd.

One deliberate difference, ``float64_constant``: acting and SAC's step have subtracted the
Gaussian's log sqrt(2 pi) in float64 since they were written, PPO's update (like torch) in
float32. Each path keeps its own so that the same seed still gives the same numbers.

Shapes: n = batch, c = continuous dimensions, k = options of one discrete branch.
"""
from __future__ import annotations

import math

import numpy as np


# the constants of both modules, here so that acting needs no torch (distributions.py imports them)
EPSILON = 1e-7  # as ML-Agents, so log-probs and entropies agree numerically
MASKED_LOGIT_OFFSET = 1e8
LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))  # a Python float: float32 arithmetic, as torch's
_LOG_SQRT_2PI_FLOAT64 = np.float64(0.5 * np.log(2 * np.pi))
TWO_PI_E = 2 * math.pi * math.e
_MAX, _SUM = np.maximum.reduce, np.add.reduce  # ndarray.max/sum without their Python wrappers

__all__ = ["EPSILON", "MASKED_LOGIT_OFFSET", "gaussian_log_prob", "gaussian_log_prob_grads", "gaussian_entropy",
           "gaussian_entropy_grad", "mask_logits", "softmax", "categorical_log_prob", "categorical_log_prob_grad",
           "categorical_entropy", "categorical_entropy_grad"]


# ---------------------------------------------------------------------------------- Gaussian
def gaussian_log_prob(actions: np.ndarray, mu: np.ndarray, log_sigma: np.ndarray,
                      float64_constant: bool = False) -> np.ndarray:
    """Per-dimension log N(a; mu, sigma). actions, mu [n, c]; log_sigma [1, c] or [n, c] -> [n, c]
    (float64 with ``float64_constant``)."""
    sigma = np.exp(log_sigma)
    constant = _LOG_SQRT_2PI_FLOAT64 if float64_constant else LOG_SQRT_2PI
    return -((actions - mu) ** 2) / (2 * sigma**2 + EPSILON) - np.log(sigma + EPSILON) - constant


def gaussian_log_prob_grads(actions: np.ndarray, mu: np.ndarray, log_sigma: np.ndarray, grad: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """``grad`` [n, c] (d loss / d log-prob) taken back through ``gaussian_log_prob``: (d loss / d mu
    [n, c], d loss / d log_sigma per element [n, c]; sum it over rows for a shared log_sigma)."""
    sigma = np.exp(log_sigma)
    diff = actions - mu
    denom = 2 * sigma ** 2 + EPSILON
    grad_mu = grad * 2.0 * diff / denom
    grad_log_sigma = grad * (diff ** 2 * 4.0 * sigma ** 2 / denom ** 2 - sigma / (sigma + EPSILON))
    return grad_mu, grad_log_sigma


def gaussian_entropy(log_sigma: np.ndarray) -> np.ndarray:
    """Per-dimension entropy 0.5*log(2*pi*e*sigma^2). log_sigma [.., c] -> [.., c]."""
    return 0.5 * np.log(TWO_PI_E * np.exp(log_sigma) ** 2 + EPSILON)


def gaussian_entropy_grad(log_sigma: np.ndarray) -> np.ndarray:
    """d gaussian_entropy / d log_sigma, per element. [.., c] -> [.., c]."""
    sigma = np.exp(log_sigma)
    return TWO_PI_E * sigma ** 2 / (TWO_PI_E * sigma ** 2 + EPSILON)


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


def categorical_entropy(probs: np.ndarray) -> np.ndarray:
    """-sum_k p log(p + EPSILON). probs [n, k] -> [n]."""
    return -np.sum(probs * np.log(probs + EPSILON), axis=1)


def categorical_entropy_grad(probs: np.ndarray) -> np.ndarray:
    """d categorical_entropy(softmax(logits)) / d logits. probs [n, k] -> [n, k]."""
    # d/dp_j of -sum p log(p + eps) = -log(p_j + eps) - p_j / (p_j + eps), then through the softmax
    d_entropy = -np.log(probs + EPSILON) - probs / (probs + EPSILON)
    return probs * (d_entropy - np.sum(probs * d_entropy, axis=1, keepdims=True))
