"""A numpy copy of the actor for deciding actions when every observation is a vector.

Why: inside the trainer process every small torch op releases the GIL, and gRPC's threads take
it each time; measured under load, ``Policy.act`` for one agent took 3 ms of ~40 tiny ops, most of
it waiting to get the GIL back. The same forward pass in numpy (a few small matmuls, which keep
the GIL) takes tens of microseconds. This copy refreshes its weights whenever a parameter
changed (torch bumps ``Tensor._version`` on every in-place update: optimizer steps,
load_state_dict, the numpy update's ``finish``) and, separately and far more cheaply, its
normaliser mean/std whenever a normaliser changed (every trajectory), so it never acts with
stale values.

Math (same as Actor.heads): x_i -> clip((x_i - mean_i)/sqrt(var_sum_i/steps_i), -5, 5) if
normalised; h = concat(x_i); h = swish(h W_l^T + b_l) per hidden layer; mu = h W_mu^T + b_mu;
branch logits = (h W_b^T + b_b) * allowed - 1e8 * (1 - allowed).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from trainer.ppo.distributions import EPSILON
from trainer.ppo.encoders import VectorInput
from trainer.ppo.networks import Actor, Critic


def supports(module: Actor | Critic) -> bool:
    """Vector observations only, no LSTM, not a critic on the actor's body (those act and learn
    in torch: the numpy update's gradients assume separate bodies)."""
    body = module.network_body
    return not getattr(module, "shared", False) and body.lstm is None and all(isinstance(e, VectorInput) for e in body.observation_encoder.encoders)


class _Tracked:
    """Knows when any of ``tensors`` changed since the last look: torch bumps
    ``Tensor._version`` on every in-place torch update (optimizer steps, normaliser updates,
    load_state_dict, the numpy update's ``finish``)."""

    def __init__(self, tensors) -> None:
        self._tensors = list(tensors)
        self._key: tuple | None = None

    def stale(self) -> bool:
        key = tuple(t._version for t in self._tensors)
        if key != self._key:
            self._key = key
            return True
        return False


def body_normalizers(network_body) -> list:
    """(mean, std) float32 per input, or None for an input without normaliser."""
    normalizers = []
    with torch.no_grad():
        for norm in (encoder.normalizer for encoder in network_body.observation_encoder.encoders):
            if norm is None:
                normalizers.append(None)
            else:
                std = torch.sqrt(norm.running_variance / norm.normalization_steps)
                normalizers.append((norm.running_mean.numpy().astype(np.float32).copy(),
                                    std.numpy().astype(np.float32).copy()))
    return normalizers


def _linear(module: nn.Linear) -> tuple[np.ndarray, np.ndarray]:
    """(W^T, b) of a Linear layer as numpy copies."""
    with torch.no_grad():
        return module.weight.detach().numpy().T.copy(), module.bias.detach().numpy().copy()


def body_layers(network_body) -> list:
    """(W^T, b) per hidden Linear, as numpy copies."""
    return [_linear(m) for m in network_body.hidden if isinstance(m, nn.Linear)]


def body_input(obs: list[np.ndarray], normalizers: list) -> np.ndarray:
    """The hidden layers' input: each observation normalised and clipped, then concatenated."""
    parts = []
    for x, norm in zip(obs, normalizers):
        x = np.asarray(x, dtype=np.float32)
        if norm is not None:
            x = (x - norm[0]) / norm[1]
            np.maximum(x, -5.0, out=x)  # np.clip's values without its Python-level wrapper
            np.minimum(x, 5.0, out=x)
            x = x.astype(np.float32, copy=False)
        parts.append(x)
    return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)


def body_forward(obs: list[np.ndarray], normalizers: list, layers: list) -> np.ndarray:
    h = body_input(obs, normalizers)
    for weight, bias in layers:
        h = h @ weight  # a new array: the in-place steps below never touch the inputs
        h += bias
        t = np.negative(h)
        np.exp(t, out=t)
        t += 1.0
        h /= t  # swish: x * sigmoid(x) = x / (1 + exp(-x)), the same float32 steps in place
    return h


class _NumpyCopy:
    """A torch module's hidden layers and normalisers as numpy copies, kept in step with it:
    weights re-copied when a parameter changed, normaliser mean/std when a buffer changed."""

    def __init__(self, module: Actor | Critic) -> None:
        if not supports(module):
            raise ValueError(f"{type(self).__name__} handles vector observations only")
        self.module = module
        self._weights = _Tracked(module.parameters())
        self._normalizers = _Tracked(module.buffers())

    def _copy_heads(self) -> None:
        """Copy the output layers (subclasses); called with every weight re-copy."""

    def _hidden(self, obs: list[np.ndarray]) -> np.ndarray:
        """Refresh what changed, then the last hidden layer's output [n, hidden]."""
        if self._weights.stale():
            self.layers = body_layers(self.module.network_body)
            self._copy_heads()
        if self._normalizers.stale():
            self.normalizers = body_normalizers(self.module.network_body)
        return body_forward(obs, self.normalizers, self.layers)


class NumpyCritic(_NumpyCopy):
    """The critic's forward pass in numpy (value estimates while processing trajectories)."""

    def _copy_heads(self) -> None:
        self.heads = {name: _linear(head) for name, head in self.module.value_heads.items()}

    def __call__(self, obs: list[np.ndarray]) -> dict[str, np.ndarray]:
        """Value estimates per reward signal, float32 [n] each."""
        h = self._hidden(obs)
        return {name: (h @ weight + bias)[:, 0] for name, (weight, bias) in self.heads.items()}


class NumpyActor(_NumpyCopy):
    def _copy_heads(self) -> None:
        actor = self.module
        self.mu = None
        if actor.mu is not None:
            self.mu = _linear(actor.mu)
            # what the Gaussian's log-prob and entropy need of log_sigma, once per weight change:
            # sigma [1, c], 2 sigma^2 + eps, log(sigma + eps), the mean entropy
            sigma = np.exp(actor.log_sigma.detach().numpy().astype(np.float32))
            self.gaussian = (sigma, 2 * sigma**2 + EPSILON, np.log(sigma + EPSILON),
                             np.mean(0.5 * np.log(2 * np.pi * np.e * sigma**2 + EPSILON)))
        self.branches = [_linear(b) for b in actor.discrete_branches]
        self.offsets = list(actor._mask_offsets)

    def heads(self, obs: list[np.ndarray], allowed: np.ndarray | None
              ) -> tuple[np.ndarray | None, list[np.ndarray]]:
        """mu [n, c] or None, and masked logits [n, k_b] per branch (allowed: float [n, sum], 1 = allowed)."""
        h = self._hidden(obs)
        mu = h @ self.mu[0] + self.mu[1] if self.mu is not None else None
        logits = []
        for index, (weight, bias) in enumerate(self.branches):
            branch = h @ weight + bias
            if allowed is not None:
                a = allowed[:, self.offsets[index]:self.offsets[index + 1]]
                branch = branch * a - 1e8 * (1.0 - a)
            logits.append(branch)
        return mu, logits
