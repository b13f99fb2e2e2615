"""Means over the rows a mask keeps: recurrent minibatches pad each sequence with rows marked 0."""
from __future__ import annotations

import torch


def masked_mean(values: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of ``values`` [n, ...] over the rows where mask [n] is nonzero (all rows if None);
    recurrent minibatches mark the padding that completes each sequence with 0."""
    if mask is None:
        return torch.mean(values)
    weights = mask.reshape(-1, *([1] * (values.ndim - 1))).to(values.dtype).expand_as(values)
    return (values * weights).sum() / torch.clamp(weights.sum(), min=1.0)
