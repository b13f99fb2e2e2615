"""Actor and critic networks (separate bodies, encoders and normalisers, as ML-Agents' default).

Body: encoders of every observation concatenated -> num_layers x (Linear -> Swish), then, with
network_settings.memory, an LSTM of hidden size memory_size / 2 (Xavier-uniform kernels, zero
biases, forget-gate bias 1). A memory [.., memory_size] is the hidden state h then the cell c.
Actor heads: Gaussian mu (Kaiming normal, gain 0.2) with a state-independent log_sigma (init 0);
one Linear per discrete branch (Kaiming normal, gain 0.1). Critic: one Linear(h, 1) per reward signal.
SAC (``squashed`` actor): log_sigma is a second Linear head (Kaiming normal, gain 0.2) clamped to
[-20, 2], and samples pass through tanh; its Q networks are Critics whose body also takes the
continuous actions (concatenated after the observation encodings) and whose heads give one value
per discrete option (docs/sac.md).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from torch import nn

from trainer.errors import ConfigError
from trainer.common.distributions import mask_logits
from trainer.common.encoders import VectorInput, make_visual_encoder
from trainer.common.hyperparams import NetworkHyperparams
from trainer.common.initial_parameters import (BRANCH_GAIN, KAIMING_NORMAL, MODEL_EXPORT_VERSION, MU_GAIN,
                                               XAVIER_UNIFORM, lstm_parameters)
from trainer.common.layers import hidden_layers, linear_layer, torch_seeded_rng
from trainer.common.numpy_net import LOG_SIGMA_MAX, LOG_SIGMA_MIN  # the clamp of a squashed (SAC) actor's log sigma
from protos.types import ActionSpec, ObservationSpec



def check_network_settings(hyperparams: NetworkHyperparams) -> None:
    if hyperparams.memory_size % 2 or hyperparams.memory_size < 0:
        raise ConfigError(f"network_settings.memory.memory_size must be even, got {hyperparams.memory_size}")


class LSTMMemory(nn.Module):
    """nn.LSTM (batch first) whose state travels as one tensor: memories [1, n_seq, 2 * hidden]."""

    def __init__(self, input_size: int, memory_size: int):
        super().__init__()
        self.hidden_size = memory_size // 2
        self.lstm = nn.LSTM(input_size, self.hidden_size, 1, batch_first=True)
        initial = lstm_parameters(torch_seeded_rng(), input_size, self.hidden_size)
        for name, value in initial.items():  # kernels stored input-major, as Linear kernels (layers.py)
            setattr(self.lstm, name, nn.Parameter(torch.from_numpy(np.ascontiguousarray(value.T)).t()
                                                  if value.ndim == 2 else torch.from_numpy(value)))

    def forward(self, inputs: torch.Tensor, memories: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """inputs [n_seq, L, in], memories [1, n_seq, m] -> (outputs [n_seq, L, m/2], memories [1, n_seq, m])."""
        h0 = memories[:, :, :self.hidden_size].contiguous()
        c0 = memories[:, :, self.hidden_size:].contiguous()
        outputs, (h, c) = self.lstm(inputs, (h0, c0))
        return outputs, torch.cat([h, c], dim=-1)


class ObservationEncoder(nn.Module):
    """Encodes a list of observations [n, *shape_i] into one [n, total] tensor."""

    def __init__(self, observation_specs: Sequence[ObservationSpec], hidden_units: int,
                 vis_encode_type: str, normalize: bool):
        super().__init__()
        encoders: list[nn.Module] = []
        self.output_size = 0
        for index, spec in enumerate(observation_specs):
            shape = tuple(spec.shape)
            if len(shape) == 1:
                encoders.append(VectorInput(shape[0], normalize))
                self.output_size += shape[0]
            elif len(shape) == 3:
                encoders.append(make_visual_encoder(shape, hidden_units, vis_encode_type))
                self.output_size += hidden_units
            else:
                raise ConfigError(
                    f"observation {index} ({spec.name!r}) has shape {shape}; only vector (N,) and "
                    "visual (C, H, W) observations are supported (variable-length observations are not)"
                )
        self.encoders = nn.ModuleList(encoders)

    def forward(self, observations: Sequence[torch.Tensor]) -> torch.Tensor:
        encoded = [encoder(obs) for encoder, obs in zip(self.encoders, observations)]
        return torch.cat(encoded, dim=1) if len(encoded) > 1 else encoded[0]

    def update_normalization(self, observations: Sequence[torch.Tensor]) -> None:
        for encoder, obs in zip(self.encoders, observations):
            if isinstance(encoder, VectorInput):
                encoder.update_normalization(obs)


class NetworkBody(nn.Module):
    """Observation encoders -> hidden layers. [n, *shape_i] ... -> [n, hidden_units]."""

    def __init__(self, observation_specs: Sequence[ObservationSpec], hyperparams: NetworkHyperparams,
                 action_size: int = 0):
        super().__init__()
        check_network_settings(hyperparams)
        self.observation_encoder = ObservationEncoder(
            observation_specs, hyperparams.hidden_units, hyperparams.vis_encode_type, hyperparams.normalize
        )
        self.action_size = action_size  # > 0: continuous actions join the encodings (SAC's Q networks)
        self.hidden = hidden_layers(
            self.observation_encoder.output_size + action_size, hyperparams.hidden_units, hyperparams.num_layers
        )
        self.output_size = hyperparams.hidden_units if hyperparams.num_layers > 0 else (
            self.observation_encoder.output_size
        )
        self.memory_size = hyperparams.memory_size
        self.lstm = LSTMMemory(self.output_size, self.memory_size) if self.memory_size else None
        if self.lstm is not None:
            self.output_size = self.memory_size // 2

    def forward(self, observations: Sequence[torch.Tensor], actions: torch.Tensor | None = None) -> torch.Tensor:
        """[n, *shape_i] ... (and actions [n, action_size]) -> [n, output_size] (networks without memory)."""
        encoded = self.observation_encoder(observations)
        if actions is not None:
            encoded = torch.cat([encoded, actions], dim=1)
        return self.hidden(encoded)

    def forward_memory(self, observations: Sequence[torch.Tensor], memories: torch.Tensor,
                       sequence_length: int = 1, actions: torch.Tensor | None = None
                       ) -> tuple[torch.Tensor, torch.Tensor]:
        """Rows are n_seq sequences of ``sequence_length`` consecutive steps; memories
        [1, n_seq, m] is each sequence's start. -> (encoding [rows, m/2], memories [1, n_seq, m])."""
        encoding = self.forward(observations, actions)
        encoding = encoding.reshape(-1, sequence_length, encoding.shape[-1])
        encoding, memories = self.lstm(encoding, memories)
        return encoding.reshape(-1, self.memory_size // 2), memories

    def update_normalization(self, observations: Sequence[torch.Tensor]) -> None:
        self.observation_encoder.update_normalization(observations)


def _constant(values: list[float]) -> nn.Parameter:
    return nn.Parameter(torch.tensor(values, dtype=torch.float32), requires_grad=False)


class Actor(nn.Module):
    """The policy network. ``heads`` gives the distribution parameters for a batch.

    Besides weights, the state dict carries the ONNX constants ``version_number``, ``memory_size_vector``,
    ``continuous_act_size_vector`` and ``discrete_act_size_vector`` (as in ML-Agents).
    """

    def __init__(self, observation_specs: Sequence[ObservationSpec], action_spec: ActionSpec,
                 hyperparams: NetworkHyperparams, squashed: bool = False):
        super().__init__()
        self.action_spec = action_spec
        self.squashed = squashed  # SAC: state-dependent sigma, tanh-squashed samples
        self.version_number = _constant([float(MODEL_EXPORT_VERSION)])
        self.memory_size_vector = _constant([float(hyperparams.memory_size)])
        self.continuous_act_size_vector = _constant([float(action_spec.continuous_size)])
        self.discrete_act_size_vector = _constant([[float(b) for b in action_spec.discrete_branches]])
        self.network_body = NetworkBody(observation_specs, hyperparams)
        hidden = self.network_body.output_size
        self.mu: nn.Linear | None = None
        if action_spec.continuous_size > 0:
            self.mu = linear_layer(hidden, action_spec.continuous_size, KAIMING_NORMAL, MU_GAIN)
            if squashed:
                self.log_sigma_head = linear_layer(hidden, action_spec.continuous_size, KAIMING_NORMAL, MU_GAIN)
            else:
                self.log_sigma = nn.Parameter(torch.zeros(1, action_spec.continuous_size))
        self.discrete_branches = nn.ModuleList(
            linear_layer(hidden, size, KAIMING_NORMAL, BRANCH_GAIN) for size in action_spec.discrete_branches
        )
        offsets = [0]
        for size in action_spec.discrete_branches:
            offsets.append(offsets[-1] + size)
        self.mask_offsets = offsets  # branch b's columns of the action mask: offsets[b]:offsets[b + 1]

    def heads(self, observations: Sequence[torch.Tensor], allowed: torch.Tensor | None
              ) -> tuple[torch.Tensor | None, list[torch.Tensor]]:
        """Continuous mean mu [n, c] (or None) and masked logits [n, k_b] for every branch b.

        allowed: float [n, sum(branches)], 1 = allowed, 0 = masked (None = all allowed).
        """
        return self.heads_of(self.network_body(observations), allowed)

    def heads_with_memory(self, observations: Sequence[torch.Tensor], allowed: torch.Tensor | None,
                          memories: torch.Tensor, sequence_length: int = 1
                          ) -> tuple[torch.Tensor | None, list[torch.Tensor], torch.Tensor]:
        """``heads`` of a recurrent actor (see NetworkBody.forward_memory), plus the new memories."""
        encoding, memories = self.network_body.forward_memory(observations, memories, sequence_length)
        mu, logits = self.heads_of(encoding, allowed)
        return mu, logits, memories

    def heads_of(self, encoding: torch.Tensor, allowed: torch.Tensor | None
                 ) -> tuple[torch.Tensor | None, list[torch.Tensor]]:
        mu = self.mu(encoding) if self.mu is not None else None
        logits = []
        for index, branch in enumerate(self.discrete_branches):
            branch_logits = branch(encoding)
            if allowed is not None:
                start, end = self.mask_offsets[index], self.mask_offsets[index + 1]
                branch_logits = mask_logits(branch_logits, allowed[:, start:end])
            logits.append(branch_logits)
        return mu, logits

    def log_sigma_of(self, encoding: torch.Tensor, mu: torch.Tensor) -> torch.Tensor:
        """log sigma [n, c]: clamp(Linear(encoding), -20, 2) for a squashed actor, else the
        state-independent parameter broadcast over the batch (``mu * 0 +``, as in the reference's
        export, which has no Expand)."""
        if self.squashed:
            return torch.clamp(self.log_sigma_head(encoding), LOG_SIGMA_MIN, LOG_SIGMA_MAX)
        return mu * 0 + self.log_sigma

    def update_normalization(self, observations: Sequence[torch.Tensor]) -> None:
        self.network_body.update_normalization(observations)


class Critic(nn.Module):
    """Value network: own body and normalisers, one Linear(h, 1) head (Xavier uniform) per reward signal.

    ``shared_body`` (hyperparameters.shared_critic): the heads sit on the actor's body instead. That
    body is not a submodule here (its weights are the actor's: no second copy in parameters() or
    the state dict), but value-loss gradients reach it, and ``update_normalization`` updates it
    too, so with the actor's own update each trajectory enters its normaliser twice, as in the
    reference (its critic *is* the actor there).
    """

    def __init__(self, observation_specs: Sequence[ObservationSpec], reward_signal_names: Sequence[str],
                 hyperparams: NetworkHyperparams, shared_body: NetworkBody | None = None,
                 action_size: int = 0, outputs_per_signal: int = 1):
        super().__init__()
        self.shared = shared_body is not None
        if self.shared:
            object.__setattr__(self, "network_body", shared_body)  # bypasses submodule registration
        else:
            self.network_body = NetworkBody(observation_specs, hyperparams, action_size)
        hidden = self.network_body.output_size
        self.outputs_per_signal = outputs_per_signal  # > 1: SAC's Q of every discrete option
        self.value_heads = nn.ModuleDict(
            {name: linear_layer(hidden, outputs_per_signal, XAVIER_UNIFORM, 1.0) for name in reward_signal_names}
        )

    def forward(self, observations: Sequence[torch.Tensor], actions: torch.Tensor | None = None
                ) -> dict[str, torch.Tensor]:
        """Value estimates per reward signal, each [n] (or [n, outputs_per_signal] when > 1)."""
        return self._values(self.network_body(observations, actions))

    def forward_memory(self, observations: Sequence[torch.Tensor], memories: torch.Tensor,
                       sequence_length: int = 1, actions: torch.Tensor | None = None
                       ) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """``forward`` of a recurrent critic (see NetworkBody.forward_memory), plus the new memories."""
        encoding, memories = self.network_body.forward_memory(observations, memories, sequence_length, actions)
        return self._values(encoding), memories

    def _values(self, encoding: torch.Tensor) -> dict[str, torch.Tensor]:
        if self.outputs_per_signal > 1:
            return {name: head(encoding) for name, head in self.value_heads.items()}
        return {name: head(encoding).squeeze(1) for name, head in self.value_heads.items()}

    def update_normalization(self, observations: Sequence[torch.Tensor]) -> None:
        self.network_body.update_normalization(observations)
