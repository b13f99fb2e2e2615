"""PPO loss terms as pure torch functions (clipped surrogate, clipped value loss)."""
from __future__ import annotations

import torch


def masked_mean(values: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of ``values`` [n, ...] over the rows where mask [n] is nonzero (all rows if None);
    recurrent minibatches mark the padding that completes each sequence with 0."""
    if mask is None:
        return torch.mean(values)
    weights = mask.reshape(-1, *([1] * (values.ndim - 1))).to(values.dtype).expand_as(values)
    return (values * weights).sum() / torch.clamp(weights.sum(), min=1.0)


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
