"""Intrinsic reward signals: curiosity (ICM) and random network distillation (RND).

Each provider turns experiences into one reward per step (``evaluate``, before ``strength``),
learns from a minibatch (``update``, its own Adam) and has a value head of its own in the
critic. PPO and SAC share them: PPO rewards each trajectory once and updates on every PPO
minibatch; SAC rewards every sampled replay minibatch afresh and updates on minibatches of
their own (docs/sac.md). ``hyperparams`` is either room's dataclass (the network fields are
named alike). Behaviour as in ML-Agents Release 22 (docs/ppo.md §10):

* Both ignore ``done``: their returns are always bootstrapped with V(next obs).
* Curiosity: a state encoder phi (a network body with the signal's network_settings), an inverse
  model [phi(s), phi(s')] -> Linear(256)+Swish -> the action (continuous: the raw sample, squared
  error; discrete: one softmax per branch, cross-entropy) and a forward model
  [phi(s), action (continuous, then one-hot branches)] -> Linear(256)+Swish -> Linear(hidden)
  predicting phi(s'). reward = sum 0.5 (phi(s') - forward)^2, capped at 1/strength and 0 until
  the first update; loss = 10 (0.2 forward + 0.8 inverse), forward = mean of that reward.
* RND: a frozen random body and a trained body of the same shape; reward = loss per sample =
  sum (trained(s) - random(s))^2. Both bodies update their normalisers on every pass (when the
  signal's network_settings normalise), as the reference does.
* Statistics: ``Losses/Curiosity Forward Loss``, ``Losses/Curiosity Inverse Loss``,
  ``Losses/RND Loss`` per update; the trainer adds ``Policy/<Name> Reward`` per episode and
  ``Policy/<Name> Value Estimate`` per trajectory, with ``<Name>`` = Curiosity | Rnd.
* Checkpoint keys as the reference names its modules: ``Module:Curiosity``, ``Module:RND-pred``,
  ``Module:RND-target``; plus each provider's optimizer state.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Sequence

import numpy as np
import torch
from torch import nn

from trainer.ppo.adam import Adam
from trainer.ppo.hyperparams import PPOHyperparams, SignalNetwork
from trainer.ppo.layers import KAIMING_NORMAL, Swish, linear_layer
from trainer.ppo.losses import masked_mean
from trainer.ppo.networks import NetworkBody
from protos.types import ActionSpec, BehaviorSpec

CURIOSITY_HIDDEN = 256  # the inverse and forward models' hidden width (fixed in the reference)
FORWARD_WEIGHT = 0.2  # loss = LOSS_MULTIPLIER * (0.2 forward + 0.8 inverse)
LOSS_MULTIPLIER = 10.0
EPSILON = 1e-10


def _body_hyperparams(base: PPOHyperparams, network: SignalNetwork) -> PPOHyperparams:
    return dataclasses.replace(base, hidden_units=network.hidden_units, num_layers=network.num_layers,
                               normalize=network.normalize, vis_encode_type=network.vis_encode_type,
                               memory_size=0)  # the reference ignores memory in these encoders


def _tensor(array: Any, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """A numpy array or a tensor (PPO minibatches come as either) as a tensor of ``dtype``."""
    return array.to(dtype) if isinstance(array, torch.Tensor) else torch.as_tensor(np.asarray(array), dtype=dtype)


def _one_hot(discrete: torch.Tensor, branches: Sequence[int]) -> torch.Tensor:
    """int [n, B] -> float [n, sum(branches)], one block per branch."""
    return torch.cat([nn.functional.one_hot(discrete[:, b].long(), size).float()
                      for b, size in enumerate(branches)], dim=1)


class Experience:
    """The columns a provider reads: observations [n, ...] per input, the next observations,
    the raw continuous actions [n, c] and the discrete actions [n, B] (numpy or torch), and for
    recurrent minibatches the masks [n] that are 0 on sequence padding."""

    def __init__(self, obs, next_obs, continuous, discrete, masks=None) -> None:
        self.obs = [_tensor(o) for o in obs]
        self.next_obs = None if next_obs is None else [_tensor(o) for o in next_obs]
        self.continuous = _tensor(continuous)
        self.discrete = _tensor(discrete, torch.int64)
        self.masks = None if masks is None else _tensor(masks)


class CuriosityNetwork(nn.Module):
    def __init__(self, spec: BehaviorSpec, hyperparams: PPOHyperparams, network: SignalNetwork) -> None:
        super().__init__()
        self.action_spec: ActionSpec = spec.action_spec
        self.state_encoder = NetworkBody(spec.observation_specs, _body_hyperparams(hyperparams, network))
        hidden = self.state_encoder.output_size
        a = self.action_spec
        self.inverse_encoder = nn.Sequential(
            linear_layer(2 * hidden, CURIOSITY_HIDDEN, KAIMING_NORMAL, 1.0), Swish())
        self.continuous_prediction = (linear_layer(CURIOSITY_HIDDEN, a.continuous_size)
                                      if a.continuous_size else None)
        self.discrete_prediction = (linear_layer(CURIOSITY_HIDDEN, sum(a.discrete_branches))
                                    if a.discrete_branches else None)
        self.forward_model = nn.Sequential(
            linear_layer(hidden + a.continuous_size + sum(a.discrete_branches), CURIOSITY_HIDDEN,
                         KAIMING_NORMAL, 1.0),
            Swish(),
            linear_layer(CURIOSITY_HIDDEN, hidden),
        )

    def flat_actions(self, exp: Experience) -> torch.Tensor:
        parts = []
        if self.action_spec.continuous_size:
            parts.append(exp.continuous)
        if self.action_spec.discrete_branches:
            parts.append(_one_hot(exp.discrete, self.action_spec.discrete_branches))
        return torch.cat(parts, dim=1)

    def forward_error(self, exp: Experience) -> torch.Tensor:
        """[n]: sum 0.5 (phi(s') - forward(phi(s), a))^2 (the reward and the forward loss)."""
        state = self.state_encoder(exp.obs)
        predicted = self.forward_model(torch.cat([state, self.flat_actions(exp)], dim=1))
        target = self.state_encoder(exp.next_obs)
        return torch.sum(0.5 * (target - predicted) ** 2, dim=1)

    def inverse_loss(self, exp: Experience) -> torch.Tensor:
        """Mean (over unpadded rows) of the action-prediction error."""
        hidden = self.inverse_encoder(
            torch.cat([self.state_encoder(exp.obs), self.state_encoder(exp.next_obs)], dim=1))
        loss = torch.zeros(())
        if self.continuous_prediction is not None:
            loss = loss + masked_mean(torch.sum((exp.continuous - self.continuous_prediction(hidden)) ** 2, dim=1),
                                      exp.masks)
        if self.discrete_prediction is not None:
            logits = self.discrete_prediction(hidden)
            probs = torch.cat([torch.softmax(block, dim=1) for block in
                               torch.split(logits, list(self.action_spec.discrete_branches), dim=1)], dim=1)
            true = _one_hot(exp.discrete, self.action_spec.discrete_branches)
            loss = loss + masked_mean(torch.sum(-torch.log(probs + EPSILON) * true, dim=1), exp.masks)
        return loss


class CuriosityProvider:
    stat_name = "Curiosity"
    ignore_done = True  # returns bootstrap through the end of an episode
    needs_next_obs = True

    def __init__(self, spec: BehaviorSpec, hyperparams: PPOHyperparams, strength: float,
                 network: SignalNetwork) -> None:
        self.strength = float(strength)
        self.network = CuriosityNetwork(spec, hyperparams, network)
        self.optimizer = Adam([p for p in self.network.parameters() if p.requires_grad], lr=network.learning_rate)
        self.has_updated = False

    def evaluate(self, exp: Experience) -> np.ndarray:
        """float32 [n], before ``strength``: min(forward error, 1/strength); 0 before any update."""
        if not self.has_updated:
            return np.zeros(len(exp.continuous), dtype=np.float32)
        with torch.no_grad():
            error = self.network.forward_error(exp).numpy()
        return np.minimum(error, 1.0 / self.strength).astype(np.float32)

    def update(self, exp: Experience) -> dict[str, float]:
        self.has_updated = True
        forward = masked_mean(self.network.forward_error(exp), exp.masks)
        inverse = self.network.inverse_loss(exp)
        loss = LOSS_MULTIPLIER * (FORWARD_WEIGHT * forward + (1.0 - FORWARD_WEIGHT) * inverse)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return {"Losses/Curiosity Forward Loss": forward.item(), "Losses/Curiosity Inverse Loss": inverse.item()}

    def state_dict(self) -> dict[str, Any]:
        return {"Module:Curiosity": self.network.state_dict(),
                "Optimizer:Curiosity": {**self.optimizer.state_dict(),
                                        "has_updated": torch.tensor(self.has_updated)}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.network.load_state_dict(state["Module:Curiosity"])
        optimizer = dict(state["Optimizer:Curiosity"])
        self.has_updated = bool(optimizer.pop("has_updated"))
        self.optimizer.load_state_dict(optimizer)


class RNDProvider:
    stat_name = "Rnd"  # the reference capitalises its class name "RND"
    ignore_done = True
    needs_next_obs = False

    def __init__(self, spec: BehaviorSpec, hyperparams: PPOHyperparams, strength: float,
                 network: SignalNetwork) -> None:
        self.strength = float(strength)
        body = _body_hyperparams(hyperparams, network)
        self.target = NetworkBody(spec.observation_specs, body)
        self.predictor = NetworkBody(spec.observation_specs, body)
        for p in self.target.parameters():
            p.requires_grad_(False)
        self.optimizer = Adam([p for p in self.predictor.parameters() if p.requires_grad], lr=network.learning_rate)

    def _error(self, exp: Experience) -> torch.Tensor:
        with torch.no_grad():
            target = self.target(exp.obs)
            self.target.update_normalization(exp.obs)
        prediction = self.predictor(exp.obs)
        with torch.no_grad():
            self.predictor.update_normalization(exp.obs)
        return torch.sum((prediction - target) ** 2, dim=1)

    def evaluate(self, exp: Experience) -> np.ndarray:
        with torch.no_grad():
            return self._error(exp).numpy().astype(np.float32)

    def update(self, exp: Experience) -> dict[str, float]:
        loss = torch.mean(self._error(exp))  # over padding rows too: the reference's RND does not mask
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return {"Losses/RND Loss": loss.item()}

    def state_dict(self) -> dict[str, Any]:
        return {"Module:RND-pred": self.predictor.state_dict(), "Module:RND-target": self.target.state_dict(),
                "Optimizer:RND": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.predictor.load_state_dict(state["Module:RND-pred"])
        self.target.load_state_dict(state["Module:RND-target"])
        self.optimizer.load_state_dict(state["Optimizer:RND"])


PROVIDERS = {"curiosity": CuriosityProvider, "rnd": RNDProvider}


def make_providers(spec: BehaviorSpec, hyperparams: PPOHyperparams, seed: int) -> dict[str, Any]:
    """One provider per intrinsic reward signal of ``hyperparams``, each initialised from its own
    seed (``seed`` + its position), in the order of the YAML."""
    providers = {}
    for index, (name, (_gamma, strength)) in enumerate(hyperparams.reward_signals.items()):
        if name in PROVIDERS:
            with torch.random.fork_rng(devices=[]):
                torch.manual_seed(seed + index)
                providers[name] = PROVIDERS[name](spec, hyperparams, strength,
                                                  hyperparams.reward_signal_networks[name])
    return providers
