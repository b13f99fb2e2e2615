"""Small building blocks with ML-Agents' weight initialisation.

ML-Agents initialises a Linear layer's kernel with a named scheme (Kaiming-He normal computed with
``nonlinearity="linear"``, i.e. std = 1/sqrt(fan_in), or Xavier-Glorot uniform) and then multiplies the
whole kernel by a ``gain``; biases start at zero.

The kernel W [out, in] is stored input-major: W^T is the contiguous array. numpy_net.py reads the
layers through numpy views of their storage, and OpenBLAS multiplies a small batch by a
contiguous W^T up to 3x faster than by a transposed view (docs/performance.md, "One network, run
in numpy on views of the torch parameters"); torch's Linear and its checkpoints do not care about
the layout.
"""
from __future__ import annotations

import torch
from torch import nn

KAIMING_NORMAL = "kaiming_normal"
XAVIER_UNIFORM = "xavier_uniform"


def linear_layer(
    input_size: int, output_size: int, kernel_init: str = XAVIER_UNIFORM, gain: float = 1.0
) -> nn.Linear:
    """Linear(input_size, output_size) with ``kernel_init`` scaled by ``gain`` and a zero bias."""
    layer = nn.Linear(input_size, output_size)
    with torch.no_grad():
        if kernel_init == KAIMING_NORMAL:
            nn.init.kaiming_normal_(layer.weight, nonlinearity="linear")
        elif kernel_init == XAVIER_UNIFORM:
            nn.init.xavier_uniform_(layer.weight)
        else:
            raise ValueError(f"unknown kernel_init {kernel_init!r}")
        layer.weight.mul_(gain)
        layer.bias.zero_()
    layer.weight = nn.Parameter(layer.weight.detach().t().contiguous().t())  # the same values, W^T contiguous
    return layer


class Swish(nn.Module):
    """x * sigmoid(x); exported to ONNX as Sigmoid + Mul."""

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return inputs * torch.sigmoid(inputs)


def hidden_layers(input_size: int, hidden_units: int, num_layers: int) -> nn.Sequential:
    """num_layers x (Linear -> Swish), Kaiming-normal kernels with gain 1. [n, input] -> [n, hidden]."""
    layers: list[nn.Module] = []
    size = input_size
    for _ in range(num_layers):
        layers += [linear_layer(size, hidden_units, KAIMING_NORMAL, 1.0), Swish()]
        size = hidden_units
    return nn.Sequential(*layers)
