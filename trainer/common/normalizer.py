"""Running observation normaliser (ML-Agents ``normalize: true``), part of the exported graph."""
from __future__ import annotations

import torch
from torch import nn


class Normalizer(nn.Module):
    """Running mean / variance-sum of vector observations, updated with a batched Welford step.

    Buffers (all saved in the state dict): ``normalization_steps`` (starts at 1), ``running_mean``
    (starts at 0) and ``running_variance`` (the variance *sum*, starts at 1).
    """

    def __init__(self, size: int):
        super().__init__()
        self.register_buffer("normalization_steps", torch.tensor(1, dtype=torch.int64))
        self.register_buffer("running_mean", torch.zeros(size))
        self.register_buffer("running_variance", torch.ones(size))
        # data-parallel ranks (trainer/distributed.py): updates wait here as float64 sums
        # (count, sum(x - mean), sum((x - mean)^2)) until every rank's are merged by ``apply``
        self.pending: list | None = None

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """inputs [n, size] -> clip((x - mean) / sqrt(var_sum / steps), -5, 5), [n, size]."""
        std = torch.sqrt(self.running_variance / self.normalization_steps)
        return torch.clamp((inputs - self.running_mean) / std, -5.0, 5.0)

    @torch.no_grad()
    def update(self, batch: torch.Tensor) -> None:
        """Fold a batch [n, size] into the statistics (one call per trajectory).

        new_mean = mean + sum(x - mean) / (steps + n);  var_sum += sum((x - new_mean)(x - mean)).
        """
        if self.pending is not None:
            centered = batch.double() - self.running_mean.double()
            self.pending[0] += batch.shape[0]
            self.pending[1] += centered.sum(0)
            self.pending[2] += (centered * centered).sum(0)
            return
        batch = batch.to(self.running_mean.dtype)
        total_steps = self.normalization_steps + batch.shape[0]
        to_old_mean = batch - self.running_mean
        new_mean = self.running_mean + (to_old_mean / total_steps).sum(0)
        to_new_mean = batch - new_mean
        self.running_variance.add_((to_new_mean * to_old_mean).sum(0))
        self.running_mean.copy_(new_mean)
        self.normalization_steps.copy_(total_steps)

    def defer(self) -> None:
        """From now on ``update`` only accumulates; ``apply`` folds the accumulated sums in."""
        size = self.running_mean.shape[0]
        self.pending = [0, torch.zeros(size, dtype=torch.float64), torch.zeros(size, dtype=torch.float64)]

    def take_pending(self) -> torch.Tensor:
        """The accumulated [count, sum(x - mean)..., sum((x - mean)^2)...] (float64), reset to zero."""
        count, s1, s2 = self.pending
        out = torch.cat([torch.tensor([float(count)], dtype=torch.float64), s1, s2])
        self.defer()
        return out

    @torch.no_grad()
    def apply(self, count: int, s1: torch.Tensor, s2: torch.Tensor) -> None:
        """Fold ``count`` observations in, given their sums relative to the current mean (float64):
        the batched Welford step of ``update`` for all of them at once,
        new_mean = mean + s1 / (steps + count); var_sum += s2 - (new_mean - mean) * s1."""
        if count == 0:
            return
        total_steps = int(self.normalization_steps) + count
        shift = s1 / total_steps
        mean = self.running_mean.double()
        self.running_variance.copy_(self.running_variance.double() + s2 - shift * s1)
        self.running_mean.copy_(mean + shift)
        self.normalization_steps.fill_(total_steps)
