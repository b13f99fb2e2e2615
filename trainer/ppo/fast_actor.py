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
branch logits = (h W_b^T + b_b) * allowed - 1e8 * (1 - allowed), i.e. -1e8 where masked.
"""
from __future__ import annotations

import operator

import numpy as np
import torch
from torch import nn

from trainer.ppo.distributions import EPSILON
from trainer.ppo.encoders import VectorInput
from trainer.ppo.networks import Actor, Critic


_VERSION = operator.attrgetter("_version")


def supports(module: Actor | Critic, recurrent: bool = False) -> bool:
    """Vector observations only, not a critic on the actor's body (the numpy update's gradients
    assume separate bodies), and no LSTM unless ``recurrent`` (forward passes step the LSTM in
    numpy; the numpy update does not train one)."""
    body = module.network_body
    return (not getattr(module, "shared", False) and (recurrent or body.lstm is None)
            and all(isinstance(e, VectorInput) for e in body.observation_encoder.encoders))


class _Tracked:
    """Knows when any of ``tensors`` changed since the last look: torch bumps
    ``Tensor._version`` on every in-place torch update (optimizer steps, normaliser updates,
    load_state_dict, the numpy update's ``finish``)."""

    def __init__(self, tensors) -> None:
        self._tensors = list(tensors)
        self._key: tuple | None = None

    def stale(self) -> bool:
        key = tuple(map(_VERSION, self._tensors))
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
        if not supports(module, recurrent=True):
            raise ValueError(f"{type(self).__name__} handles vector observations only")
        self.module = module
        self.recurrent = module.network_body.lstm is not None  # (nn.Module attribute reads are slow)
        self._weights = _Tracked(module.parameters())
        self._normalizers = _Tracked(module.buffers())

    def _copy_heads(self) -> None:
        """Copy the output layers (subclasses); called with every weight re-copy."""

    def _hidden(self, obs: list[np.ndarray]) -> np.ndarray:
        """Refresh what changed, then the last hidden layer's output [n, hidden]."""
        if self._weights.stale():
            self.layers = body_layers(self.module.network_body)
            self.lstm = lstm_weights(self.module.network_body)
            self._copy_heads()
        if self._normalizers.stale():
            self.normalizers = body_normalizers(self.module.network_body)
        return body_forward(obs, self.normalizers, self.layers)

    def _hidden_memory(self, obs: list[np.ndarray], memories: np.ndarray, sequence_length: int = 1
                       ) -> tuple[np.ndarray, np.ndarray]:
        """A recurrent body: rows are sequences of ``sequence_length`` steps starting from
        memories [n_seq, m] -> (LSTM outputs [rows, m/2], memories after each sequence [n_seq, m])."""
        h = self._hidden(obs)
        w_in, w_hidden, bias = self.lstm
        size = w_hidden.shape[0]
        inputs = (h @ w_in + bias).reshape(-1, sequence_length, 4 * size)  # the input part of every gate
        state, cell = memories[:, :size].astype(np.float32), memories[:, size:].astype(np.float32)
        outputs = np.empty((inputs.shape[0], sequence_length, size), dtype=np.float32)
        for t in range(sequence_length):
            gates = inputs[:, t] + state @ w_hidden
            i, f, g, o = (gates[:, k * size:(k + 1) * size] for k in range(4))  # torch's gate order
            cell = _sigmoid(f) * cell + _sigmoid(i) * np.tanh(g)
            state = _sigmoid(o) * np.tanh(cell)
            outputs[:, t] = state
        return outputs.reshape(-1, size), np.concatenate([state, cell], axis=1)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


def lstm_weights(network_body) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(W_ih^T [in, 4h], W_hh^T [h, 4h], b_ih + b_hh [4h]) of the body's LSTM, or None."""
    if network_body.lstm is None:
        return None
    lstm = network_body.lstm.lstm
    with torch.no_grad():
        return (lstm.weight_ih_l0.numpy().T.copy(), lstm.weight_hh_l0.numpy().T.copy(),
                (lstm.bias_ih_l0 + lstm.bias_hh_l0).numpy().copy())


class NumpyCritic(_NumpyCopy):
    """The critic's forward pass in numpy (value estimates while processing trajectories)."""

    def _copy_heads(self) -> None:
        self.heads = {name: _linear(head) for name, head in self.module.value_heads.items()}

    def __call__(self, obs: list[np.ndarray]) -> dict[str, np.ndarray]:
        """Value estimates per reward signal, float32 [n] each."""
        return self._values(self._hidden(obs))

    def with_memory(self, obs: list[np.ndarray], memories: np.ndarray, sequence_length: int
                    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """A recurrent critic: (values per signal [rows], memories after each sequence [n_seq, m])."""
        h, memories = self._hidden_memory(obs, memories, sequence_length)
        return self._values(h), memories

    def _values(self, h: np.ndarray) -> dict[str, np.ndarray]:
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

    def heads(self, obs: list[np.ndarray], action_mask: np.ndarray | None, memories: np.ndarray | None = None
              ) -> tuple[np.ndarray | None, list[np.ndarray], np.ndarray | None]:
        """mu [n, c] or None, masked logits [n, k_b] per branch (action_mask: bool [n, sum],
        True = masked, or None), and for a recurrent actor the next memories [n, m] (from
        ``memories``, zero if None)."""
        memories_out = None
        if self.recurrent:
            if memories is None:
                memories = np.zeros((len(obs[0]), self.module.network_body.memory_size), dtype=np.float32)
            h, memories_out = self._hidden_memory(obs, memories, 1)
        else:
            h = self._hidden(obs)
        mu = h @ self.mu[0] + self.mu[1] if self.mu is not None else None
        logits = []
        for index, (weight, bias) in enumerate(self.branches):
            branch = h @ weight + bias
            if action_mask is not None:  # logit * 1 - 0 where allowed, logit * 0 - 1e8 where masked
                branch = np.where(action_mask[:, self.offsets[index]:self.offsets[index + 1]], -1e8, branch)
            logits.append(branch)
        return mu, logits, memories_out
