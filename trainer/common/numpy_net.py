"""The vector-observation actor and critic of networks.py, run in numpy on the same parameters.

networks.py is the one definition of the networks: layers, initialisation, parameters, and the
torch forward pass used for ONNX export, recurrent and visual training, and as the reference in
the tests. This module reads those modules (never a second description of them) and runs their
forward pass, and the hidden layers' backward pass, in numpy:

* acting and value estimates: inside the trainer process every small torch op releases the GIL
  and gRPC's threads take it each time; measured under load, ``Policy.act`` for one agent took
  3 ms of ~40 tiny ops, the same forward pass in numpy (a few small matmuls that keep the GIL)
  tens of microseconds;
* the PPO update (numpy_update.py): per-op dispatch and autograd dominate a minibatch of these
  small networks; the numpy update is ~3x faster (tests check it against autograd).
* SAC's gradient step (trainer/sac/numpy_step.py), likewise: ~5x faster than autograd there.

Parameters are never copied: every weight and bias here is a numpy view of the torch tensor
(shared memory), so an optimiser step, a load_state_dict or the numpy update (which writes
through these views, with Adam from adam.py) is seen at once by both sides, with nothing to sync.
Linear kernels are stored input-major (layers.py), so the views of W^T are contiguous, which
OpenBLAS multiplies fastest. What is *derived* from parameters (the normalisers' std, the
Gaussian's sigma terms, the LSTM's summed biases) is cached and recomputed whenever the bytes it
comes from differ (a ~0.2 us comparison per call; see ``_Derived``).

Math (same as Actor.heads / Critic.forward): x_i -> clip((x_i - mean_i)/sqrt(var_sum_i/steps_i),
-5, 5) if normalised; h = concat(x_i); h = swish(h W_l^T + b_l) per hidden layer; optional LSTM
(torch's gate order i, f, g, o); mu = h W_mu^T + b_mu; branch logits = (h W_b^T + b_b) masked to
-1e8; value_k = h W_k^T + b_k.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from trainer.common import numpy_distributions

if TYPE_CHECKING:  # this module imports no torch: the first actions are decided before it is loaded
    import torch

    from trainer.common.networks import Actor, Critic

# networks.Actor.log_sigma_of's clamp of a squashed (SAC) actor's log sigma (networks.py imports it)
LOG_SIGMA_MIN, LOG_SIGMA_MAX = -20.0, 2.0
BODY = "network_body."


def supports(module: Actor | Critic, recurrent: bool = False) -> bool:
    """Vector observations only, not a critic on the actor's body (the numpy update's gradients
    assume separate bodies), and no LSTM unless ``recurrent`` (forward passes step the LSTM in
    numpy; the numpy update does not train one)."""
    from trainer.common.encoders import VectorInput

    body = module.network_body
    return (not getattr(module, "shared", False) and (recurrent or body.lstm is None)
            and all(isinstance(e, VectorInput) for e in body.observation_encoder.encoders))


def view(tensor: torch.Tensor) -> np.ndarray:
    """A numpy view of a CPU tensor's storage (writes reach torch and back)."""
    return tensor.detach().numpy()


def views(module: torch.nn.Module) -> dict[str, np.ndarray]:
    """A module's state dict (parameters and buffers, by name) as numpy views of its tensors."""
    return {name: view(tensor) for name, tensor in module.state_dict(keep_vars=True).items()}


def _linear(params: Mapping[str, np.ndarray], name: str) -> tuple[np.ndarray, np.ndarray]:
    """(W^T [in, out], b [out]) of the Linear layer ``name`` (W^T contiguous: see layers.py)."""
    return params[f"{name}.weight"].T, params[f"{name}.bias"]


class _Derived:
    """``compute(*arrays)``, recomputed only when the bytes of ``arrays`` (views of small torch
    tensors: normaliser buffers, log_sigma, LSTM biases) changed since the last call. Comparing
    bytes needs no knowledge of who changed them, or how (no torch version counters)."""

    def __init__(self, compute, *arrays: np.ndarray) -> None:
        self.compute, self.arrays = compute, arrays
        self._key: bytes | None = None
        self._value = None

    def __call__(self):
        key = b"".join([a.tobytes() for a in self.arrays])
        if key != self._key:
            self._value = self.compute(*self.arrays)
            self._key = key
        return self._value


def _mean_std(mean: np.ndarray, variance: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A Normalizer's (mean, std) in float32, std as torch's float32 / int64 division computes it."""
    std = np.sqrt(variance / variance.dtype.type(steps))
    return mean.astype(np.float32), std.astype(np.float32, copy=False)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(np.minimum(-x, 80.0)))  # no float32 overflow warning (see forward)


class NumpyBody:
    """A NetworkBody's normalisers, hidden Linear layers and LSTM, read by name from its state
    dict ``params`` (networks.NetworkBody's names; numpy views of the torch tensors, or
    initial_parameters' arrays before torch is loaded).

    ``kernels``: (W^T, b) per hidden layer; ``linears``: the torch layers when built from a
    module (the update's gradients are keyed by their parameters)."""

    def __init__(self, params: Mapping[str, np.ndarray], observations: int, linears: list | None = None) -> None:
        self.linears = linears
        self.kernels = []
        while f"{BODY}hidden.{2 * len(self.kernels)}.weight" in params:  # Linear, Swish, Linear, ...
            self.kernels.append(_linear(params, f"{BODY}hidden.{2 * len(self.kernels)}"))
        self.normalizers = []
        for index in range(observations):
            prefix = f"{BODY}observation_encoder.encoders.{index}.normalizer."
            self.normalizers.append(_Derived(_mean_std, *(params[prefix + name] for name in (
                "running_mean", "running_variance", "normalization_steps"))) if prefix + "running_mean" in params
                else None)
        self.lstm = None  # (W_ih^T [in, 4h], W_hh^T [h, 4h], b_ih + b_hh [4h]) of the LSTM, if any
        self.memory_size = 0
        lstm = f"{BODY}lstm.lstm."
        if lstm + "weight_hh_l0" in params:
            self.lstm = (params[lstm + "weight_ih_l0"].T, params[lstm + "weight_hh_l0"].T,
                         _Derived(np.add, params[lstm + "bias_ih_l0"], params[lstm + "bias_hh_l0"]))
            self.memory_size = 2 * params[lstm + "weight_hh_l0"].shape[1]

    @classmethod
    def of(cls, module: Actor | Critic) -> "NumpyBody":
        """The body of a torch Actor or Critic, as views of its tensors."""
        from torch import nn

        body = module.network_body
        return cls({BODY + name: value for name, value in views(body).items()},
                   len(body.observation_encoder.encoders), [m for m in body.hidden if isinstance(m, nn.Linear)])

    def input(self, obs: list[np.ndarray]) -> np.ndarray:
        """The hidden layers' input: each observation normalised and clipped, then concatenated."""
        parts = []
        for x, norm in zip(obs, self.normalizers):
            x = np.asarray(x, dtype=np.float32)
            if norm is not None:
                mean, std = norm()
                x = (x - mean) / std
                np.maximum(x, -5.0, out=x)  # np.clip's values without its Python-level wrapper
                np.minimum(x, 5.0, out=x)
            parts.append(x)
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)

    def forward(self, h: np.ndarray, cache: list | None = None) -> np.ndarray:
        """swish(h W^T + b) per hidden layer: [n, in] -> [n, hidden]. With ``cache`` (the update),
        each layer's (input, pre-activation a, sigmoid(a)) is appended for ``backward``. The
        elementwise steps run in place on fresh arrays (the inputs are never touched)."""
        for kernel, bias in self.kernels:
            a = h @ kernel
            a += bias
            s = np.negative(a)
            np.minimum(s, 80.0, out=s)  # exp(88.7) overflows float32; a/(1+e^80) is -1e-33, not -0
            np.exp(s, out=s)
            s += 1.0
            if cache is None:  # swish(a) = a / (1 + exp(-a))
                a /= s
                h = a
            else:
                np.reciprocal(s, out=s)  # s = sigmoid(a)
                cache.append((h, a, s))
                h = a * s
        return h

    def backward(self, grad_h: np.ndarray, cache: list, grads: dict[int, np.ndarray],
                 param_rows: int | None = None, input_grad: bool = False) -> np.ndarray | None:
        """Gradients of the hidden layers' weights and biases into ``grads`` (keyed by id of the
        torch parameter), from grad_h = d loss / d (last layer's output) and ``forward``'s cache.

        For SAC's Q networks (trainer/sac/numpy_step.py): ``grad_h`` may cover only the first
        rows of the cached forward pass; ``param_rows``: only the first rows reach the weights
        (the others are rows whose loss holds this network constant); ``input_grad``: return
        d loss / d input (its continuous-action columns lead to the policy)."""
        rows = len(grad_h)
        last = len(cache) - 1
        for index, ((kernel, _), linear, (h_in, a, s)) in enumerate(
                zip(reversed(self.kernels), reversed(self.linears), reversed(cache))):
            if len(a) != rows:
                h_in, a, s = h_in[:rows], a[:rows], s[:rows]
            grad_a = a * s  # grad_h * swish'(a) = grad_h * (s + a * s * (1 - s))
            grad_a *= 1.0 - s
            grad_a += s
            grad_a *= grad_h
            if param_rows is None:
                grads[id(linear.weight)] = (h_in.T @ grad_a).T  # laid out as the parameter (W^T contiguous)
                grads[id(linear.bias)] = np.add.reduce(grad_a, axis=0)
            else:
                grads[id(linear.weight)] = (h_in[:param_rows].T @ grad_a[:param_rows]).T
                grads[id(linear.bias)] = np.add.reduce(grad_a[:param_rows], axis=0)
            if index < last or input_grad:  # the observations themselves need no gradient
                grad_h = grad_a @ kernel.T
        return grad_h if input_grad else None

    def hidden(self, obs: list[np.ndarray]) -> np.ndarray:
        """The last hidden layer's output [n, hidden]."""
        return self.forward(self.input(obs))

    def hidden_memory(self, obs: list[np.ndarray], memories: np.ndarray, sequence_length: int = 1
                      ) -> tuple[np.ndarray, np.ndarray]:
        """A recurrent body: rows are sequences of ``sequence_length`` steps starting from
        memories [n_seq, m] -> (LSTM outputs [rows, m/2], memories after each sequence [n_seq, m])."""
        h = self.hidden(obs)
        w_in, w_hidden, bias = self.lstm
        bias = bias()
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


class _NumpyModule:
    """What NumpyActor and NumpyCritic share: the torch module (None before torch is loaded) and its body."""

    def __init__(self, module: Actor | Critic | None, body: NumpyBody) -> None:
        if module is not None and not supports(module, recurrent=True):
            raise ValueError(f"{type(self).__name__} handles vector observations only")
        self.module = module
        self.body = body
        self.recurrent = body.lstm is not None  # (nn.Module attribute reads are slow)


class NumpyCritic(_NumpyModule):
    """The critic's forward pass in numpy (value estimates, and the numpy update)."""

    def __init__(self, critic: Critic) -> None:
        super().__init__(critic, NumpyBody.of(critic))
        params = views(critic)
        self.heads = {name: _linear(params, f"value_heads.{name}") for name in critic.value_heads}  # (W^T, b)

    def __call__(self, obs: list[np.ndarray]) -> dict[str, np.ndarray]:
        """Value estimates per reward signal, float32 [n] each."""
        return self._values(self.body.hidden(obs))

    def with_memory(self, obs: list[np.ndarray], memories: np.ndarray, sequence_length: int
                    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """A recurrent critic: (values per signal [rows], memories after each sequence [n_seq, m])."""
        h, memories = self.body.hidden_memory(obs, memories, sequence_length)
        return self._values(h), memories

    def _values(self, h: np.ndarray) -> dict[str, np.ndarray]:
        return {name: (h @ weight + bias)[:, 0] for name, (weight, bias) in self.heads.items()}


def _gaussian_terms(log_sigma: np.ndarray) -> tuple:
    """What acting needs of log_sigma [1, c]: sigma (to scale the noise), the entropy per dimension
    [1, c], and the log-prob's numpy_distributions.GaussianTerms (sigma among them)."""
    terms = numpy_distributions.gaussian_terms(log_sigma)
    return terms.sigma, numpy_distributions.gaussian_entropy(log_sigma), terms


class NumpyActor(_NumpyModule):
    """The actor's heads in numpy (deciding actions, and the numpy update).

    Built from a torch Actor (``NumpyActor(actor)``: views of its tensors) or, before torch is
    loaded, from initial_parameters.actor_parameters' state dict (``from_parameters``)."""

    def __init__(self, actor: Actor) -> None:
        if not supports(actor, recurrent=True):
            raise ValueError("NumpyActor handles vector observations only")
        self._read(views(actor), actor.action_spec.discrete_branches, NumpyBody.of(actor))
        self.module = actor

    @classmethod
    def from_parameters(cls, params: Mapping[str, np.ndarray], observations: int,
                        discrete_branches: Sequence[int]) -> "NumpyActor":
        """An actor without torch: ``params`` is networks.Actor's state dict as numpy arrays."""
        actor = cls.__new__(cls)
        actor._read(params, discrete_branches, NumpyBody(params, observations))
        return actor

    def _read(self, params: Mapping[str, np.ndarray], discrete_branches: Sequence[int], body: NumpyBody) -> None:
        super().__init__(None, body)
        self.params = params  # the state dict, by name
        self.mu = _linear(params, "mu") if "mu.weight" in params else None  # (W^T, b)
        fixed_sigma = "log_sigma" in params
        self.log_sigma = params["log_sigma"] if fixed_sigma else None  # [1, c]
        self.gaussian = _Derived(_gaussian_terms, self.log_sigma) if fixed_sigma else None
        # a squashed (SAC) actor's log sigma is a head of its own: (W^T, b)
        self.log_sigma_head = _linear(params, "log_sigma_head") if "log_sigma_head.weight" in params else None
        self.branches = [_linear(params, f"discrete_branches.{b}") for b in range(len(discrete_branches))]
        offsets = [0]
        for size in discrete_branches:
            offsets.append(offsets[-1] + size)
        self.offsets = offsets  # branch b's columns of the action mask: offsets[b]:offsets[b + 1]

    def heads(self, obs: list[np.ndarray], action_mask: np.ndarray | None, memories: np.ndarray | None = None
              ) -> tuple[np.ndarray | None, list[np.ndarray], np.ndarray | None]:
        """mu [n, c] or None, masked logits [n, k_b] per branch (action_mask: bool [n, sum],
        True = masked, or None), and for a recurrent actor the next memories [n, m] (from
        ``memories``, zero if None)."""
        h, memories_out = self.hidden(obs, memories)
        mu, logits = self.heads_of(h, action_mask)
        return mu, logits, memories_out

    def hidden(self, obs: list[np.ndarray], memories: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """The body's output [n, h] and, for a recurrent actor, the next memories [n, m]."""
        if not self.recurrent:
            return self.body.hidden(obs), None
        if memories is None:
            memories = np.zeros((len(obs[0]), self.body.memory_size), dtype=np.float32)
        return self.body.hidden_memory(obs, memories, 1)

    def log_sigma_of(self, h: np.ndarray) -> np.ndarray:
        """A squashed actor's log sigma [n, c]: clip(h W^T + b, -20, 2) (networks.Actor.log_sigma_of)."""
        log_sigma = h @ self.log_sigma_head[0] + self.log_sigma_head[1]
        return np.minimum(np.maximum(log_sigma, LOG_SIGMA_MIN), LOG_SIGMA_MAX)

    def heads_of(self, h: np.ndarray, action_mask: np.ndarray | None
                 ) -> tuple[np.ndarray | None, list[np.ndarray]]:
        """mu [n, c] or None and the masked logits per branch, from the body's output h."""
        mu = h @ self.mu[0] + self.mu[1] if self.mu is not None else None
        logits = []
        for index, (weight, bias) in enumerate(self.branches):
            branch = h @ weight + bias
            if action_mask is not None:  # logit * 1 - 0 where allowed, logit * 0 - 1e8 where masked
                branch = np.where(action_mask[:, self.offsets[index]:self.offsets[index + 1]], -1e8, branch)
            logits.append(branch)
        return mu, logits
