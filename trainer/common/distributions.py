"""Log-probabilities and entropies of the action distributions, as pure torch functions.

The Gaussian (PPO's actions, clipped for the environment), SAC's tanh-squashed Gaussian and the
categorical of each discrete branch; numpy_distributions.py is the same, name for name, in numpy.

The small constant EPSILON (numpy_distributions.py, imported here) matches ML-Agents so log-probs
and entropies agree numerically.
Shapes: n = batch, c = continuous dimensions, k = options of one discrete branch.
"""
from __future__ import annotations

import math

import torch

from trainer.common.numpy_distributions import EPSILON, MASKED_LOGIT_OFFSET

_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))


def gaussian_log_prob(actions: torch.Tensor, mu: torch.Tensor, log_sigma: torch.Tensor) -> torch.Tensor:
    """Per-dimension log N(a; mu, sigma). actions, mu [n, c]; log_sigma [1, c] or [n, c] -> [n, c]."""
    sigma = torch.exp(log_sigma)
    return (
        -((actions - mu) ** 2) / (2 * sigma**2 + EPSILON)
        - torch.log(sigma + EPSILON)
        - _LOG_SQRT_2PI
    )


def gaussian_entropy(log_sigma: torch.Tensor) -> torch.Tensor:
    """Per-dimension entropy 0.5*log(2*pi*e*sigma^2). log_sigma [.., c] -> [.., c]."""
    return 0.5 * torch.log(2 * math.pi * math.e * torch.exp(log_sigma) ** 2 + EPSILON)


def tanh_log_abs_det_jacobian(raw: torch.Tensor) -> torch.Tensor:
    """log |d tanh(x) / dx| = 2 (log 2 - x - softplus(-2x)), stable for large |x|. [n, c] -> [n, c]."""
    return 2.0 * (math.log(2.0) - raw - torch.nn.functional.softplus(-2.0 * raw))


def squashed_sample(mu: torch.Tensor, log_sigma: torch.Tensor, noise: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """The reparameterised sample of a tanh-squashed Gaussian: (raw = mu + noise sigma, tanh(raw)). [n, c] each."""
    raw = mu + noise * torch.exp(log_sigma)
    return raw, torch.tanh(raw)


def squashed_log_prob(raw: torch.Tensor, mu: torch.Tensor, log_sigma: torch.Tensor) -> torch.Tensor:
    """Per-dimension log-density of tanh(raw) with raw ~ N(mu, sigma). [n, c] -> [n, c]."""
    return gaussian_log_prob(raw, mu, log_sigma) - tanh_log_abs_det_jacobian(raw)


def mask_logits(logits: torch.Tensor, allowed: torch.Tensor) -> torch.Tensor:
    """logits * allowed - 1e8 * (1 - allowed). logits, allowed (float, 1 = allowed) [n, k] -> [n, k]."""
    return logits * allowed - MASKED_LOGIT_OFFSET * (-1.0 * allowed + 1.0)


def categorical_log_prob(probs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """log(p[action] + EPSILON). probs [n, k]; actions int [n] -> [n]."""
    chosen = torch.gather(probs, 1, actions.long().unsqueeze(1)).squeeze(1)
    return torch.log(chosen + EPSILON)


def categorical_option_log_probs(probs: torch.Tensor) -> torch.Tensor:
    """log(p + EPSILON) of every option (SAC's losses weigh each option). probs [n, k] -> [n, k]."""
    return torch.log(probs + EPSILON)


def categorical_entropy(probs: torch.Tensor) -> torch.Tensor:
    """-sum_k p log(p + EPSILON). probs [n, k] -> [n]."""
    return -torch.sum(probs * torch.log(probs + EPSILON), dim=1)


def combined_entropy(continuous_entropy: torch.Tensor | None, discrete_entropies: list[torch.Tensor]
                     ) -> torch.Tensor:
    """Policy entropy per agent: mean over Gaussian dims [n, c] plus the sum of branch entropies ([n] each)."""
    total: torch.Tensor | None = None
    if continuous_entropy is not None:
        total = continuous_entropy.mean(dim=1)
    for branch_entropy in discrete_entropies:
        total = branch_entropy if total is None else total + branch_entropy
    if total is None:
        raise ValueError("a policy needs at least one continuous dimension or discrete branch")
    return total
