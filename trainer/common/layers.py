"""Small building blocks with ML-Agents' weight initialisation.

ML-Agents initialises a Linear layer's kernel with a named scheme (Kaiming-He normal computed with
``nonlinearity="linear"``, i.e. std = 1/sqrt(fan_in), or Xavier-Glorot uniform) and then multiplies the
whole kernel by a ``gain``; biases start at zero. The draws are initial_parameters.py's, in numpy
(one initialisation, with or without torch).

The kernel W [out, in] is stored input-major: W^T is the contiguous array. numpy_net.py reads the
layers through numpy views of their storage, and OpenBLAS multiplies a small batch by a
contiguous W^T up to 3x faster than by a transposed view (docs/performance.md, "One network, run
in numpy on views of the torch parameters"); torch's Linear and its checkpoints do not care about
the layout.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from trainer.common.initial_parameters import KAIMING_NORMAL, XAVIER_UNIFORM, kernel


def torch_seeded_rng() -> np.random.Generator:
    """A numpy generator seeded from torch's global one: layers built in torch draw their initial
    weights with initial_parameters' functions, reproducibly under ``torch.manual_seed``."""
    return np.random.default_rng(int(torch.randint(0, 2**62, ())))


def linear_layer(
    input_size: int, output_size: int, kernel_init: str = XAVIER_UNIFORM, gain: float = 1.0
) -> nn.Linear:
    """Linear(input_size, output_size) with ``kernel_init`` scaled by ``gain`` and a zero bias
    (initial_parameters.kernel, W^T contiguous)."""
    layer = nn.Linear(input_size, output_size)
    weight = kernel(torch_seeded_rng(), output_size, input_size, kernel_init, gain)
    layer.weight = nn.Parameter(torch.from_numpy(np.ascontiguousarray(weight.T)).t())
    with torch.no_grad():
        layer.bias.zero_()
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
