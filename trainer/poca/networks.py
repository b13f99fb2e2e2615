"""POCA's centralised critic: one network, two questions, over a variable number of group members.

* ``value(group obs)``: V of the whole group (the agent and every teammate present), from the
  observations only: the lambda returns are computed with it (docs/poca.md).
* ``baseline(own obs, teammates' obs and actions)``: the agent's counterfactual baseline, its own
  action left out: the advantage is the return minus it.

Both embed every member as one entity (observation encoders -> Linear -> Swish; a teammate's
entity also sees its action: continuous values and one-hot discrete choices), then one residual
self-attention block over the entities (absent members masked out as keys and left out of the
mean), a mean over the present entities, num_layers hidden layers and a Linear head per reward
signal. Nothing depends on the order of the teammates or on how many slots are padding.

With network_settings.memory an LSTM (PPO's ``LSTMMemory``, hidden size memory_size / 2) sits
between the hidden layers and the heads, as in the reference's multi-agent body. value() and
baseline() share its weights but each runs over its own memory stream (``value_memory`` and
``baseline_memory`` take and return it): the critic memory and the baseline memory of an agent.
"""
from __future__ import annotations

from typing import Sequence

import torch
from torch import nn

from protos.types import ActionSpec, ObservationSpec
from trainer.common.hyperparams import NetworkHyperparams
from trainer.common.layers import XAVIER_UNIFORM, hidden_layers, linear_layer
from trainer.common.networks import LSTMMemory, ObservationEncoder, check_network_settings


class EntityAttention(nn.Module):
    """Entities [n, E, h] with present [n, E] (bool) -> [n, h]: residual self-attention, LayerNorm,
    mean over the present entities."""

    def __init__(self, size: int):
        super().__init__()
        heads = 4 if size % 4 == 0 else 1
        self.attention = nn.MultiheadAttention(size, heads, batch_first=True)
        self.norm = nn.LayerNorm(size)

    def forward(self, entities: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
        weight = present.unsqueeze(-1).to(entities.dtype)
        entities = entities * weight  # what sits in an absent slot never reaches the output
        attended, _ = self.attention(entities, entities, entities, key_padding_mask=~present, need_weights=False)
        out = self.norm(entities + attended) * weight
        return out.sum(dim=1) / weight.sum(dim=1).clamp(min=1.0)


class POCACritic(nn.Module):
    """value() and baseline() (module docstring); checkpoint key ``Optimizer:critic``."""

    def __init__(self, observation_specs: Sequence[ObservationSpec], action_spec: ActionSpec,
                 reward_signal_names: Sequence[str], hyperparams: NetworkHyperparams):
        super().__init__()
        check_network_settings(hyperparams)
        h = hyperparams.hidden_units
        self.branches = tuple(action_spec.discrete_branches)
        self.action_width = action_spec.continuous_size + sum(self.branches)
        self.obs_encoder = ObservationEncoder(observation_specs, h, hyperparams.vis_encode_type, hyperparams.normalize)
        size = self.obs_encoder.output_size
        self.obs_embedding = hidden_layers(size, h, 1)
        self.obs_action_embedding = hidden_layers(size + self.action_width, h, 1)
        self.attention = EntityAttention(h)
        self.hidden = hidden_layers(h, h, hyperparams.num_layers)
        self.memory_size = hyperparams.memory_size
        self.lstm = LSTMMemory(h, self.memory_size) if self.memory_size else None
        out = self.memory_size // 2 if self.memory_size else h
        self.value_heads = nn.ModuleDict({name: linear_layer(out, 1, XAVIER_UNIFORM, 1.0) for name in reward_signal_names})

    def _encode(self, observations: Sequence[torch.Tensor]) -> torch.Tensor:
        """[n, E, *shape_i] ... -> [n, E, encoder output]."""
        n, e = observations[0].shape[:2]
        flat = [o.reshape(n * e, *o.shape[2:]) for o in observations]
        return self.obs_encoder(flat).reshape(n, e, -1)

    def _actions(self, continuous: torch.Tensor, discrete: torch.Tensor) -> torch.Tensor:
        """[n, M, c] and [n, M, b] -> [n, M, c + sum(branches)] (one-hot discrete choices)."""
        parts = [continuous]
        for index, size in enumerate(self.branches):
            parts.append(nn.functional.one_hot(discrete[..., index].long().clamp(0, size - 1), size).to(continuous.dtype))
        return torch.cat(parts, dim=-1)

    def _heads(self, entities: torch.Tensor, present: torch.Tensor, memories: torch.Tensor | None = None,
               sequence_length: int = 1) -> tuple[dict[str, torch.Tensor], torch.Tensor | None]:
        """Values per reward signal [n] and, with ``memories`` [1, n_seq, m] (the rows are n_seq
        sequences of ``sequence_length`` steps, as PPO's recurrent critic), the memories after."""
        encoding = self.hidden(self.attention(entities, present))
        if memories is not None:
            encoding = encoding.reshape(-1, sequence_length, encoding.shape[-1])
            encoding, memories = self.lstm(encoding, memories)
            encoding = encoding.reshape(-1, self.memory_size // 2)
        return {name: head(encoding).squeeze(1) for name, head in self.value_heads.items()}, memories

    def value(self, group_obs: Sequence[torch.Tensor], present: torch.Tensor) -> dict[str, torch.Tensor]:
        """V per reward signal [n] of groups given as every member's observations [n, E, *shape]
        (the agent and its teammates) and present [n, E] (bool)."""
        return self._heads(self.obs_embedding(self._encode(group_obs)), present)[0]

    def value_memory(self, group_obs: Sequence[torch.Tensor], present: torch.Tensor, memories: torch.Tensor,
                     sequence_length: int = 1) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """``value`` of a recurrent critic from the critic memories [1, n_seq, m]: (V, memories after)."""
        return self._heads(self.obs_embedding(self._encode(group_obs)), present, memories, sequence_length)

    def baseline(self, obs: Sequence[torch.Tensor], mates_obs: Sequence[torch.Tensor], mates_continuous: torch.Tensor,
                 mates_discrete: torch.Tensor, mates_present: torch.Tensor) -> dict[str, torch.Tensor]:
        """b per reward signal [n]: the agent's observations [n, *shape] without its action, the
        teammates' observations [n, M, *shape] with their actions ([n, M, c], [n, M, b]),
        mates_present [n, M] (bool)."""
        return self._heads(*self._baseline_entities(obs, mates_obs, mates_continuous, mates_discrete, mates_present))[0]

    def baseline_memory(self, obs: Sequence[torch.Tensor], mates_obs: Sequence[torch.Tensor],
                        mates_continuous: torch.Tensor, mates_discrete: torch.Tensor, mates_present: torch.Tensor,
                        memories: torch.Tensor, sequence_length: int = 1
                        ) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """``baseline`` of a recurrent critic from the baseline memories [1, n_seq, m]: (b, memories after)."""
        entities, present = self._baseline_entities(obs, mates_obs, mates_continuous, mates_discrete, mates_present)
        return self._heads(entities, present, memories, sequence_length)

    def _baseline_entities(self, obs, mates_obs, mates_continuous, mates_discrete, mates_present
                           ) -> tuple[torch.Tensor, torch.Tensor]:
        """The baseline's entities [n, 1 + M, h] (the agent first, without its action) and present."""
        own = self.obs_embedding(self._encode([o.unsqueeze(1) for o in obs]))
        if mates_present.shape[1] == 0:
            return own, torch.ones(own.shape[:2], dtype=torch.bool, device=own.device)
        mates = self._encode(mates_obs)
        mates = self.obs_action_embedding(torch.cat([mates, self._actions(mates_continuous, mates_discrete)], dim=-1))
        present = torch.cat([torch.ones((len(mates_present), 1), dtype=torch.bool, device=mates_present.device), mates_present], dim=1)
        return torch.cat([own, mates], dim=1), present

    def update_normalization(self, observations: Sequence[torch.Tensor]) -> None:
        self.obs_encoder.update_normalization(observations)
