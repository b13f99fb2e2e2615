"""SAC's pure pieces: entropy targets, the soft target update and the four losses (ML-Agents'
discrete/continuous SAC; docs/sac.md). The squashed Gaussian itself: trainer/common/distributions.py.

Shapes: n = batch, c = continuous dimensions, b = discrete branches, K = sum of branch sizes.
Per reward signal, Q networks give [n] (continuous only) or [n, K] (one value per discrete option).
"""
from __future__ import annotations

import math
from typing import Sequence

import torch
from torch import nn

CONTINUOUS_TARGET_ENTROPY_SCALE = 1.0  # target entropy -1 nat per continuous dimension
DISCRETE_TARGET_ENTROPY_SCALE = 0.2  # 0.2 * log(k) per branch: about epsilon-greedy 0.05


def target_entropies(continuous_size: int, discrete_branches: Sequence[int]) -> tuple[float, list[float]]:
    """(-scale * c for the continuous block, [0.2 * log(k_b) per discrete branch])."""
    return (-CONTINUOUS_TARGET_ENTROPY_SCALE * float(continuous_size),
            [DISCRETE_TARGET_ENTROPY_SCALE * math.log(k) for k in discrete_branches])


@torch.no_grad()
def soft_update(source: nn.Module | Sequence[torch.Tensor], target: nn.Module | Sequence[torch.Tensor],
                tau: float) -> None:
    """target = tau * source + (1 - tau) * target, parameter by parameter (tau 1 copies).
    Modules, or their parameter lists (the trainer keeps them: no module walk per step)."""
    sources = source.parameters() if isinstance(source, nn.Module) else source
    targets = target.parameters() if isinstance(target, nn.Module) else target
    for src, dst in zip(sources, targets):
        dst.lerp_(src, tau)


def q_backup(rewards: torch.Tensor, dones: torch.Tensor, next_values: torch.Tensor, gamma: float,
             use_dones: bool = True) -> torch.Tensor:
    """r + gamma * (1 - done) * V_target(s'). All [n]; ``use_dones`` False bootstraps through
    episode ends (reward signals that ignore them)."""
    alive = 1.0 - dones if use_dones else torch.ones_like(dones)
    return rewards + gamma * alive * next_values


def branch_sums(values: torch.Tensor, branches: Sequence[int]) -> torch.Tensor:
    """Sum of each branch's columns: [n, K] -> [n, b]."""
    return torch.stack([part.sum(dim=1) for part in torch.split(values, list(branches), dim=1)], dim=1)


def chosen_q(q: torch.Tensor, discrete_actions: torch.Tensor, branches: Sequence[int]) -> torch.Tensor:
    """The mean over branches of each branch's Q of the option taken. q [n, K]; actions int [n, b] -> [n]."""
    parts = torch.split(q, list(branches), dim=1)
    taken = [part.gather(1, discrete_actions[:, i:i + 1].long()) for i, part in enumerate(parts)]
    return torch.cat(taken, dim=1).mean(dim=1)


def q_loss(q: torch.Tensor, backup: torch.Tensor) -> torch.Tensor:
    """0.5 * mean((backup - Q)^2). [n], [n] -> scalar."""
    return 0.5 * torch.mean((backup.detach() - q) ** 2)


def value_target(q1_policy: torch.Tensor, q2_policy: torch.Tensor, continuous_log_probs: torch.Tensor | None,
                 continuous_alpha: torch.Tensor, discrete_probs: torch.Tensor | None,
                 discrete_log_probs: torch.Tensor | None, discrete_alpha: torch.Tensor | None,
                 branches: Sequence[int]) -> torch.Tensor:
    """V target: min of the twin Qs under the current policy minus alpha * log pi. [n].

    Continuous only: min(Q1, Q2)(s, a~pi) - alpha_c * sum_c log pi(a_c). With discrete branches the
    Qs [n, K] are averaged under pi per branch (mean over branches of sum_k pi_k Q_k), and the
    entropy term is the mean over branches of alpha_b * sum_k pi_k log pi_k (the continuous term
    is subtracted as above)."""
    with torch.no_grad():
        if discrete_probs is None:
            target = torch.min(q1_policy, q2_policy)
        else:
            expected_q1 = branch_sums(q1_policy * discrete_probs, branches).mean(dim=1)
            expected_q2 = branch_sums(q2_policy * discrete_probs, branches).mean(dim=1)
            target = torch.min(expected_q1, expected_q2)
            neg_entropy = branch_sums(discrete_probs * discrete_log_probs, branches)  # [n, b]
            target = target - (discrete_alpha * neg_entropy).mean(dim=1)
        if continuous_log_probs is not None:
            target = target - continuous_alpha * continuous_log_probs.sum(dim=1)
    return target


def policy_loss(q1_policy: torch.Tensor, continuous_log_probs: torch.Tensor | None, continuous_alpha: torch.Tensor,
                discrete_probs: torch.Tensor | None, discrete_log_probs: torch.Tensor | None,
                discrete_alpha: torch.Tensor | None, branches: Sequence[int]) -> torch.Tensor:
    """mean_n [ alpha_c * sum_c log pi(a_c) - Q1(s, a~pi) ] for continuous actions; with discrete
    branches, + sum_b sum_k (alpha_b * pi_k log pi_k - pi_k Q1_k), and the continuous term's Q is
    sum_k pi_k Q1_k. The alphas are constants here; gradients reach the policy only."""
    loss = torch.zeros(q1_policy.shape[0], device=q1_policy.device)
    if discrete_probs is not None:
        per_option = discrete_probs * discrete_log_probs
        alpha_per_option = torch.repeat_interleave(discrete_alpha.detach(),
                                                   torch.tensor(list(branches), device=q1_policy.device))
        loss = loss + (alpha_per_option * per_option - discrete_probs * q1_policy).sum(dim=1)
        expected_q = (discrete_probs * q1_policy).sum(dim=1)
    else:
        expected_q = q1_policy
    if continuous_log_probs is not None:
        loss = loss + continuous_alpha.detach() * continuous_log_probs.sum(dim=1) - expected_q
    return loss.mean()


def entropy_loss(log_alpha_continuous: torch.Tensor | None, continuous_log_probs: torch.Tensor | None,
                 continuous_target: float, log_alpha_discrete: torch.Tensor | None,
                 discrete_probs: torch.Tensor | None, discrete_log_probs: torch.Tensor | None,
                 discrete_targets: Sequence[float], branches: Sequence[int]) -> torch.Tensor:
    """-log alpha * (log pi + target entropy), averaged: alpha grows while the policy's entropy is
    below its target and shrinks above it. Only the log alphas get gradients."""
    loss = torch.zeros((), device=(log_alpha_continuous if log_alpha_continuous is not None
                                   else log_alpha_discrete).device)
    if discrete_probs is not None:
        with torch.no_grad():
            neg_entropy = branch_sums(discrete_probs * discrete_log_probs, branches)  # [n, b]
            gap = neg_entropy + torch.tensor(list(discrete_targets), device=neg_entropy.device)
        loss = loss - (log_alpha_discrete * gap).mean(dim=1).mean()
    if continuous_log_probs is not None:
        with torch.no_grad():
            gap = continuous_log_probs.sum(dim=1) + continuous_target
        loss = loss - (log_alpha_continuous * gap).mean()
    return loss
