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

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """inputs [n, size] -> clip((x - mean) / sqrt(var_sum / steps), -5, 5), [n, size]."""
        std = torch.sqrt(self.running_variance / self.normalization_steps)
        return torch.clamp((inputs - self.running_mean) / std, -5.0, 5.0)

    @torch.no_grad()
    def update(self, batch: torch.Tensor) -> None:
        """Fold a batch [n, size] into the statistics (one call per trajectory).

        new_mean = mean + sum(x - mean) / (steps + n);  var_sum += sum((x - new_mean)(x - mean)).
        """
        batch = batch.to(self.running_mean.dtype)
        total_steps = self.normalization_steps + batch.shape[0]
        to_old_mean = batch - self.running_mean
        new_mean = self.running_mean + (to_old_mean / total_steps).sum(0)
        to_new_mean = batch - new_mean
        self.running_variance.add_((to_new_mean * to_old_mean).sum(0))
        self.running_mean.copy_(new_mean)
        self.normalization_steps.copy_(total_steps)
