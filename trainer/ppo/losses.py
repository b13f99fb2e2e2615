"""PPO loss terms as pure torch functions (clipped surrogate, clipped value loss)."""
from __future__ import annotations

import torch


def policy_loss(advantages: torch.Tensor, log_probs: torch.Tensor, old_log_probs: torch.Tensor,
                epsilon: float) -> torch.Tensor:
    """-mean(min(r*A, clip(r, 1-eps, 1+eps)*A)), with one ratio per action dimension / branch.

    advantages [n]; log_probs, old_log_probs [n, c + b]. The mean runs over all n*(c+b) elements.
    """
    advantage = advantages.unsqueeze(-1)
    ratio = torch.exp(log_probs - old_log_probs)
    unclipped = ratio * advantage
    clipped = torch.clamp(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantage
    return -torch.mean(torch.min(unclipped, clipped))


def value_loss(values: dict[str, torch.Tensor], old_values: dict[str, torch.Tensor],
               returns: dict[str, torch.Tensor], epsilon: float) -> torch.Tensor:
    """Mean over heads of mean(max((R - V)^2, (R - (V_old + clip(V - V_old, -eps, eps)))^2)). Each [n]."""
    losses = []
    for name, value in values.items():
        old = old_values[name]
        clipped_value = old + torch.clamp(value - old, -epsilon, epsilon)
        unclipped_error = (returns[name] - value) ** 2
        clipped_error = (returns[name] - clipped_value) ** 2
        losses.append(torch.mean(torch.max(unclipped_error, clipped_error)))
    return torch.mean(torch.stack(losses))


def ppo_loss(policy_term: torch.Tensor, value_term: torch.Tensor, entropy: torch.Tensor, beta: float
             ) -> torch.Tensor:
    """policy_loss + 0.5 * value_loss - beta * mean(entropy); entropy [n]."""
    return policy_term + 0.5 * value_term - beta * torch.mean(entropy)


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
