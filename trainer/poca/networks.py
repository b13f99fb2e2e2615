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
"""
from __future__ import annotations

from typing import Sequence

import torch
from torch import nn

from protos.types import ActionSpec, ObservationSpec
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.layers import XAVIER_UNIFORM, hidden_layers, linear_layer
from trainer.ppo.networks import ObservationEncoder


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
                 reward_signal_names: Sequence[str], hyperparams: PPOHyperparams):
        super().__init__()
        h = hyperparams.hidden_units
        self.branches = tuple(action_spec.discrete_branches)
        self.action_width = action_spec.continuous_size + sum(self.branches)
        self.obs_encoder = ObservationEncoder(observation_specs, h, hyperparams.vis_encode_type, hyperparams.normalize)
        size = self.obs_encoder.output_size
        self.obs_embedding = hidden_layers(size, h, 1)
        self.obs_action_embedding = hidden_layers(size + self.action_width, h, 1)
        self.attention = EntityAttention(h)
        self.hidden = hidden_layers(h, h, hyperparams.num_layers)
        self.value_heads = nn.ModuleDict({name: linear_layer(h, 1, XAVIER_UNIFORM, 1.0) for name in reward_signal_names})

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

    def _heads(self, entities: torch.Tensor, present: torch.Tensor) -> dict[str, torch.Tensor]:
        encoding = self.hidden(self.attention(entities, present))
        return {name: head(encoding).squeeze(1) for name, head in self.value_heads.items()}

    def value(self, group_obs: Sequence[torch.Tensor], present: torch.Tensor) -> dict[str, torch.Tensor]:
        """V per reward signal [n] of groups given as every member's observations [n, E, *shape]
        (the agent and its teammates) and present [n, E] (bool)."""
        return self._heads(self.obs_embedding(self._encode(group_obs)), present)

    def baseline(self, obs: Sequence[torch.Tensor], mates_obs: Sequence[torch.Tensor], mates_continuous: torch.Tensor,
                 mates_discrete: torch.Tensor, mates_present: torch.Tensor) -> dict[str, torch.Tensor]:
        """b per reward signal [n]: the agent's observations [n, *shape] without its action, the
        teammates' observations [n, M, *shape] with their actions ([n, M, c], [n, M, b]),
        mates_present [n, M] (bool)."""
        own = self.obs_embedding(self._encode([o.unsqueeze(1) for o in obs]))
        if mates_present.shape[1] == 0:
            return self._heads(own, torch.ones(own.shape[:2], dtype=torch.bool, device=own.device))
        mates = self._encode(mates_obs)
        mates = self.obs_action_embedding(torch.cat([mates, self._actions(mates_continuous, mates_discrete)], dim=-1))
        present = torch.cat([torch.ones((len(mates_present), 1), dtype=torch.bool, device=mates_present.device), mates_present], dim=1)
        return self._heads(torch.cat([own, mates], dim=1), present)

    def update_normalization(self, observations: Sequence[torch.Tensor]) -> None:
        self.obs_encoder.update_normalization(observations)
