"""PPO loss terms as pure torch functions (clipped surrogate, clipped value loss)."""
from __future__ import annotations

import torch

from trainer.common.masked import masked_mean


def policy_loss(advantages: torch.Tensor, log_probs: torch.Tensor, old_log_probs: torch.Tensor,
                epsilon: float, mask: torch.Tensor | None = None) -> torch.Tensor:
    """-mean(min(r*A, clip(r, 1-eps, 1+eps)*A)), with one ratio per action dimension / branch.

    advantages [n]; log_probs, old_log_probs [n, c + b]. The mean runs over all n*(c+b) elements
    (of the rows where ``mask`` [n] is set).
    """
    advantage = advantages.unsqueeze(-1)
    ratio = torch.exp(log_probs - old_log_probs)
    unclipped = ratio * advantage
    clipped = torch.clamp(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantage
    return -masked_mean(torch.min(unclipped, clipped), mask)


def value_loss(values: dict[str, torch.Tensor], old_values: dict[str, torch.Tensor],
               returns: dict[str, torch.Tensor], epsilon: float, mask: torch.Tensor | None = None
               ) -> torch.Tensor:
    """Mean over heads of mean(max((R - V)^2, (R - (V_old + clip(V - V_old, -eps, eps)))^2)). Each [n]."""
    losses = []
    for name, value in values.items():
        old = old_values[name]
        clipped_value = old + torch.clamp(value - old, -epsilon, epsilon)
        unclipped_error = (returns[name] - value) ** 2
        clipped_error = (returns[name] - clipped_value) ** 2
        losses.append(masked_mean(torch.max(unclipped_error, clipped_error), mask))
    return torch.mean(torch.stack(losses))


def ppo_loss(policy_term: torch.Tensor, value_term: torch.Tensor, entropy: torch.Tensor, beta: float,
             mask: torch.Tensor | None = None) -> torch.Tensor:
    """policy_loss + 0.5 * value_loss - beta * mean(entropy); entropy [n]."""
    return policy_term + 0.5 * value_term - beta * masked_mean(entropy, mask)
