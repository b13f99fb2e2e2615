"""The networks' initial weights, drawn in numpy: the one initialisation, with or without torch.

ML-Agents' schemes (layers.py says which layer takes which): a Linear kernel W [out, in] is
Kaiming-He normal with ``nonlinearity="linear"`` (std = 1/sqrt(fan_in)) or Xavier-Glorot uniform
(bound sqrt(6/(fan_in + fan_out))), times a gain; biases start at zero; an LSTM's kernels are
Xavier uniform per gate with zero biases and the forget gate's biases at 1.

Why numpy: the first actions of a run are decided before torch has finished importing
(docs/performance.md, "Start-up and exit"). ``actor_parameters`` gives a vector-observation
actor's whole state dict, under networks.Actor's names, from the run's seed; numpy_net.NumpyActor
acts with it, and the torch Actor loads exactly these arrays (``load_state_dict`` is strict, so a
name or shape that drifted from networks.py fails at once). The torch layers built without a
state dict from here (critics, visual encoders' dense layers, the reward providers' networks)
draw their kernels through ``kernel`` too, from a generator seeded off torch's (layers.py).

Kernels are returned input-major (W^T is the contiguous array), as layers.py stores them.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

KAIMING_NORMAL = "kaiming_normal"
XAVIER_UNIFORM = "xavier_uniform"
MODEL_EXPORT_VERSION = 3
LSTM_FORGET_BIAS = 1.0
# networks.Actor's head gains (ML-Agents'): Gaussian mean and a squashed actor's log sigma, discrete branches
MU_GAIN, BRANCH_GAIN = 0.2, 0.1


def kernel(rng: np.random.Generator, output_size: int, input_size: int, scheme: str, gain: float = 1.0
           ) -> np.ndarray:
    """A float32 kernel W [output_size, input_size] (stored input-major) drawn by ``scheme`` x ``gain``."""
    if scheme == KAIMING_NORMAL:
        values = rng.standard_normal((input_size, output_size)) / np.sqrt(input_size)
    elif scheme == XAVIER_UNIFORM:
        bound = np.sqrt(6.0 / (input_size + output_size))
        values = rng.uniform(-bound, bound, (input_size, output_size))
    else:
        raise ValueError(f"unknown kernel_init {scheme!r}")
    return (values * gain).astype(np.float32).T


def lstm_parameters(rng: np.random.Generator, input_size: int, hidden_size: int) -> dict[str, np.ndarray]:
    """nn.LSTM's one layer (gates i, f, g, o stacked on rows): Xavier-uniform kernels per gate,
    both biases zero but the forget gate's at LSTM_FORGET_BIAS (so their sum starts at 2, as in
    ML-Agents)."""
    out = {}
    for name, size in (("weight_ih_l0", input_size), ("weight_hh_l0", hidden_size)):
        blocks = [kernel(rng, hidden_size, size, XAVIER_UNIFORM) for _ in range(4)]
        out[name] = np.ascontiguousarray(np.concatenate(blocks, axis=0).T).T  # [4h, size], input-major
    for name in ("bias_ih_l0", "bias_hh_l0"):
        bias = np.zeros(4 * hidden_size, dtype=np.float32)
        bias[hidden_size:2 * hidden_size] = LSTM_FORGET_BIAS
        out[name] = bias
    return out


def _linear(out: dict, rng: np.random.Generator, name: str, input_size: int, output_size: int,
            scheme: str, gain: float) -> None:
    out[f"{name}.weight"] = kernel(rng, output_size, input_size, scheme, gain)
    out[f"{name}.bias"] = np.zeros(output_size, dtype=np.float32)


def actor_parameters(observation_shapes: Sequence[tuple[int, ...]], continuous_size: int,
                     discrete_branches: Sequence[int], hyperparams, squashed: bool, seed: int
                     ) -> dict[str, np.ndarray] | None:
    """networks.Actor's state dict at initialisation (every parameter, buffer and ONNX constant,
    under its name), drawn from ``seed``; None when an observation is not a vector (visual
    encoders are built and initialised in torch)."""
    if any(len(shape) != 1 for shape in observation_shapes):
        return None
    rng = np.random.default_rng(seed)
    out: dict[str, np.ndarray] = {
        "version_number": np.array([MODEL_EXPORT_VERSION], np.float32),
        "memory_size_vector": np.array([hyperparams.memory_size], np.float32),
        "continuous_act_size_vector": np.array([continuous_size], np.float32),
        "discrete_act_size_vector": np.array([list(discrete_branches)], np.float32),
    }
    for index, (size,) in enumerate(observation_shapes):
        if hyperparams.normalize:
            prefix = f"network_body.observation_encoder.encoders.{index}.normalizer."
            out[prefix + "normalization_steps"] = np.array(1, dtype=np.int64)
            out[prefix + "running_mean"] = np.zeros(size, np.float32)
            out[prefix + "running_variance"] = np.ones(size, np.float32)
    size = sum(shape[0] for shape in observation_shapes)
    for layer in range(hyperparams.num_layers):  # nn.Sequential(Linear, Swish, ...): Linear at even indices
        _linear(out, rng, f"network_body.hidden.{2 * layer}", size, hyperparams.hidden_units, KAIMING_NORMAL, 1.0)
        size = hyperparams.hidden_units
    if hyperparams.memory_size:
        lstm = lstm_parameters(rng, size, hyperparams.memory_size // 2)
        out.update({f"network_body.lstm.lstm.{name}": value for name, value in lstm.items()})
        size = hyperparams.memory_size // 2
    if continuous_size:
        _linear(out, rng, "mu", size, continuous_size, KAIMING_NORMAL, MU_GAIN)
        if squashed:
            _linear(out, rng, "log_sigma_head", size, continuous_size, KAIMING_NORMAL, MU_GAIN)
        else:
            out["log_sigma"] = np.zeros((1, continuous_size), np.float32)
    for branch, options in enumerate(discrete_branches):
        _linear(out, rng, f"discrete_branches.{branch}", size, options, KAIMING_NORMAL, BRANCH_GAIN)
    return out
