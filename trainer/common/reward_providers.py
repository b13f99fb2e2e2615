"""Intrinsic reward signals: curiosity (ICM), random network distillation (RND) and GAIL.

Each provider turns experiences into one reward per step (``evaluate``, before ``strength``),
learns from a minibatch (``update``, its own Adam) and has a value head of its own in the
critic. PPO and SAC share them: PPO rewards each trajectory once and updates on every PPO
minibatch; SAC rewards every sampled replay minibatch afresh and updates on minibatches of
their own (docs/sac.md). Each is built from its signal's ``SignalNetwork``
(common/hyperparams.py). Behaviour as in ML-Agents Release 22 (docs/ppo.md, "PPO details that affect results"):

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
* GAIL: see ``GAILProvider``.
* Checkpoint keys as the reference names its modules: ``Module:Curiosity``, ``Module:RND-pred``,
  ``Module:RND-target``, ``Module:GAIL``; plus each provider's optimizer state.
"""
from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from typing import Any, ClassVar, Sequence

import numpy as np
import torch
from torch import nn

from trainer.common.adam import Adam
from trainer.common.hyperparams import SignalNetwork
from trainer.common.layers import KAIMING_NORMAL, Swish, linear_layer
from trainer.common.masked import masked_mean
from trainer.common.networks import NetworkBody
from protos.types import ActionSpec, BehaviorSpec

logger = logging.getLogger("mlagents_like")

CURIOSITY_HIDDEN = 256  # the inverse and forward models' hidden width (fixed in the reference)
FORWARD_WEIGHT = 0.2  # loss = LOSS_MULTIPLIER * (0.2 forward + 0.8 inverse)
LOSS_MULTIPLIER = 10.0
EPSILON = 1e-10


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
    recurrent minibatches the masks [n] that are 0 on sequence padding; ``done`` [n] (1 where the
    step ended its episode) for the providers that read it (``needs_done``)."""

    def __init__(self, obs, next_obs, continuous, discrete, masks=None, done=None) -> None:
        self.obs = [_tensor(o) for o in obs]
        self.next_obs = None if next_obs is None else [_tensor(o) for o in next_obs]
        self.continuous = _tensor(continuous)
        self.discrete = _tensor(discrete, torch.int64)
        self.masks = None if masks is None else _tensor(masks)
        self.done = None if done is None else _tensor(done)


class CuriosityNetwork(nn.Module):
    def __init__(self, spec: BehaviorSpec, network: SignalNetwork) -> None:
        super().__init__()
        self.action_spec: ActionSpec = spec.action_spec
        self.state_encoder = NetworkBody(spec.observation_specs, network)
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


class RewardProvider(ABC):
    """What PPO, POCA and SAC ask of an intrinsic reward signal (curiosity, rnd, gail)."""

    stat_name: ClassVar[str]  # <Name> of its statistics (Policy/<Name> Reward, ...)
    ignore_done: ClassVar[bool]  # True: its returns bootstrap through the end of an episode
    needs_next_obs: ClassVar[bool]  # its Experience carries the next observations
    needs_done: bool = False  # its Experience carries the done flags (gail with use_actions)
    strength: float
    optimizer: Adam  # its own learner's

    @abstractmethod
    def evaluate(self, exp: Experience) -> np.ndarray:
        """float32 [n]: the reward of each experience, before ``strength``."""

    @abstractmethod
    def update(self, exp: Experience) -> dict[str, float]:
        """One step of its learner on a minibatch; its loss statistics."""

    @abstractmethod
    def modules(self) -> list[nn.Module]:
        """Its networks (whose observation normalisers the data-parallel ranks keep in step)."""

    @abstractmethod
    def state_dict(self) -> dict[str, Any]: ...

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None: ...


class CuriosityProvider(RewardProvider):
    stat_name = "Curiosity"
    ignore_done = True  # returns bootstrap through the end of an episode
    needs_next_obs = True

    def __init__(self, spec: BehaviorSpec, strength: float, network: SignalNetwork) -> None:
        self.strength = float(strength)
        self.network = CuriosityNetwork(spec, network)
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

    def modules(self) -> list[nn.Module]:
        return [self.network]

    def state_dict(self) -> dict[str, Any]:
        return {"Module:Curiosity": self.network.state_dict(),
                "Optimizer:Curiosity": {**self.optimizer.state_dict(),
                                        "has_updated": torch.tensor(self.has_updated)}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.network.load_state_dict(state["Module:Curiosity"])
        optimizer = dict(state["Optimizer:Curiosity"])
        self.has_updated = bool(optimizer.pop("has_updated"))
        self.optimizer.load_state_dict(optimizer)


class RNDProvider(RewardProvider):
    stat_name = "Rnd"  # the reference capitalises its class name "RND"
    ignore_done = True
    needs_next_obs = False

    def __init__(self, spec: BehaviorSpec, strength: float, network: SignalNetwork) -> None:
        self.strength = float(strength)
        self.target = NetworkBody(spec.observation_specs, network)
        self.predictor = NetworkBody(spec.observation_specs, network)
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

    def modules(self) -> list[nn.Module]:
        return [self.target, self.predictor]

    def state_dict(self) -> dict[str, Any]:
        return {"Module:RND-pred": self.predictor.state_dict(), "Module:RND-target": self.target.state_dict(),
                "Optimizer:RND": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.predictor.load_state_dict(state["Module:RND-pred"])
        self.target.load_state_dict(state["Module:RND-target"])
        self.optimizer.load_state_dict(state["Optimizer:RND"])


# --------------------------------------------------------------------------- GAIL
GAIL_Z_SIZE = 128  # VAIL's bottleneck width
GAIL_GRADIENT_PENALTY = 10.0
GAIL_VAIL_ALPHA = 0.0005  # VAIL's beta step
GAIL_MUTUAL_INFORMATION = 0.5  # VAIL's information constraint I_c
GAIL_EPSILON = 1e-7
CONTINUOUS_CLIP = 3.0  # PPO's env actions: clamp(a, -3, 3) / 3 (trainer/common/policy.py)


class DiscriminatorNetwork(nn.Module):
    """D(s[, a, done]) in (0, 1): how much a step looks like the demonstration's.

    A network body over the observations (the signal's network_settings); with ``use_actions``
    the actions (continuous, then one-hot branches) and the done flag join the encoded
    observations before the hidden layers. With ``use_vail`` a Gaussian code z of 128 (mean
    Linear(hidden, 128), a learned sigma) sits between the body and the estimator
    Sigmoid(Linear(., 1))."""

    def __init__(self, spec: BehaviorSpec, network: SignalNetwork) -> None:
        super().__init__()
        a = spec.action_spec
        self.action_spec = a
        self.use_actions, self.use_vail = network.use_actions, network.use_vail
        extra = a.continuous_size + sum(a.discrete_branches) + 1 if self.use_actions else 0
        self.encoder = NetworkBody(spec.observation_specs, network, extra)
        size = self.encoder.output_size
        if self.use_vail:
            self.z_sigma = nn.Parameter(torch.ones(GAIL_Z_SIZE))
            self.z_mu_layer = linear_layer(size, GAIL_Z_SIZE, KAIMING_NORMAL, 0.1)
            self.beta = nn.Parameter(torch.tensor(0.0), requires_grad=False)  # adapted by the update, saved
            size = GAIL_Z_SIZE
        self.estimator = nn.Sequential(linear_layer(size, 1, gain=0.2), nn.Sigmoid())

    def action_input(self, continuous: torch.Tensor, discrete: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
        parts = []
        if self.action_spec.continuous_size:
            parts.append(continuous)
        if self.action_spec.discrete_branches:
            parts.append(_one_hot(discrete, self.action_spec.discrete_branches))
        return torch.cat([*parts, done.reshape(-1, 1)], dim=1)

    def estimate(self, obs: list[torch.Tensor], actions: torch.Tensor | None, noise: torch.Tensor | None
                 ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(D [n], the code's mean [n, 128] or None); ``noise`` [n, 128] samples the VAIL code."""
        hidden = self.encoder(obs, actions)
        z_mu = None
        if self.use_vail:
            z_mu = self.z_mu_layer(hidden)
            hidden = z_mu if noise is None else z_mu + noise * self.z_sigma
        return self.estimator(hidden).squeeze(1), z_mu


class GAILProvider(RewardProvider):
    """Generative adversarial imitation: a discriminator learns to tell the policy's steps from a
    demonstration's, and the policy is rewarded for steps it takes for the demonstration's.
    Behaviour as in ML-Agents Release 22 (docs/demonstrations.md):

    * reward (before ``strength``) = -log(1 - D (1 - 1e-7)), D without VAIL noise; returns end at
      a terminal step (``done`` is not ignored);
    * per PPO minibatch of n policy steps, n demonstration experiences drawn with replacement;
      the body's normaliser (when the signal's network_settings normalise) is updated with them;
      loss = -mean(log(D_expert + 1e-7) + log(1 - D_policy + 1e-7)) + 10 x the gradient penalty
      mean((|grad D(x~)| - 1)^2) at x~ = a random mix u x_policy + (1 - u) x_expert, the gradient
      taken with respect to the first observation as the reference does; with VAIL the KL of
      the codes plus beta (KL - 0.5), beta <- max(0, beta + 0.0005 (KL - 0.5)) after each step;
    * statistics ``Losses/GAIL Loss``, ``Policy/GAIL Policy Estimate``, ``Policy/GAIL Expert
      Estimate``, ``Policy/GAIL Grad Mag Loss``, with VAIL ``Policy/GAIL Beta`` and ``Losses/GAIL
      KL Loss``; the trainer adds ``Policy/Gail Reward`` and ``Policy/Gail Value Estimate``.

    One deliberate difference: the demonstration's continuous actions are what the environment
    received (in [-1, 1]); the reference compares them with the policy's raw Gaussian samples,
    which the environment receives as clamp(a, -3, 3) / 3, so a discriminator with
    ``use_actions`` can tell the two apart by scale alone. Here the policy's actions go through
    the same clamp and division first.
    """

    stat_name = "Gail"  # the reference: "GAIL".capitalize()
    ignore_done = False
    needs_next_obs = False

    def __init__(self, spec: BehaviorSpec, strength: float, network: SignalNetwork) -> None:
        self.strength = float(strength)
        self.network = DiscriminatorNetwork(spec, network)
        self.needs_done = network.use_actions
        self.optimizer = Adam([p for p in self.network.parameters() if p.requires_grad], lr=network.learning_rate)
        self.generator = torch.Generator()
        self.generator.manual_seed(int(torch.randint(0, 2**31 - 1, ())))  # from the provider's seed (make_providers)
        self.demo = None  # (obs tensors, continuous, discrete, done) of the demonstration

    def set_demonstrations(self, demo) -> None:
        """The expert's experiences (trainer.demonstrations.DemoExperiences)."""
        self.demo = ([torch.as_tensor(o) for o in demo.obs], torch.as_tensor(demo.continuous),
                     torch.as_tensor(demo.discrete), torch.as_tensor(demo.done, dtype=torch.float32))

    def _policy_inputs(self, exp: Experience) -> tuple[list[torch.Tensor], torch.Tensor | None]:
        actions = None
        if self.network.use_actions:
            done = exp.done if exp.done is not None else torch.zeros(len(exp.continuous))
            acted = torch.clamp(exp.continuous, -CONTINUOUS_CLIP, CONTINUOUS_CLIP) / CONTINUOUS_CLIP
            actions = self.network.action_input(acted, exp.discrete, done)
        return exp.obs, actions

    def _expert_inputs(self, n: int) -> tuple[list[torch.Tensor], torch.Tensor | None]:
        obs, continuous, discrete, done = self.demo
        rows = torch.randint(0, len(done), (n,), generator=self.generator)
        actions = (self.network.action_input(continuous[rows], discrete[rows], done[rows])
                   if self.network.use_actions else None)
        return [o[rows] for o in obs], actions

    def _noise(self, n: int) -> torch.Tensor | None:
        return torch.randn((n, GAIL_Z_SIZE), generator=self.generator) if self.network.use_vail else None

    def evaluate(self, exp: Experience) -> np.ndarray:
        """float32 [n], before ``strength``: -log(1 - D (1 - 1e-7))."""
        with torch.no_grad():
            estimate, _ = self.network.estimate(*self._policy_inputs(exp), None)
            return (-torch.log(1.0 - estimate * (1.0 - GAIL_EPSILON))).numpy().astype(np.float32)

    def update(self, exp: Experience) -> dict[str, float]:
        net = self.network
        n = len(exp.continuous)
        policy_obs, policy_actions = self._policy_inputs(exp)
        expert_obs, expert_actions = self._expert_inputs(n)
        with torch.no_grad():
            net.encoder.update_normalization(expert_obs)
        policy_d, policy_mu = net.estimate(policy_obs, policy_actions, self._noise(n))
        expert_d, expert_mu = net.estimate(expert_obs, expert_actions, self._noise(n))
        loss = -(torch.log(expert_d + GAIL_EPSILON) + torch.log(1.0 - policy_d + GAIL_EPSILON)).mean()
        stats = {"Policy/GAIL Policy Estimate": policy_d.mean().item(),
                 "Policy/GAIL Expert Estimate": expert_d.mean().item(), "Losses/GAIL Loss": loss.item()}
        total = loss
        if net.use_vail:
            variance = net.z_sigma ** 2
            kl = torch.mean(-torch.sum(1 + variance.log() - 0.5 * expert_mu ** 2 - 0.5 * policy_mu ** 2 - variance,
                                       dim=1))
            with torch.no_grad():  # beta steps first: the reference's gradient already sees the new value
                net.beta.copy_(torch.clamp(net.beta + GAIL_VAIL_ALPHA * (kl - GAIL_MUTUAL_INFORMATION), min=0.0))
            total = total + net.beta.detach().clone() * (kl - GAIL_MUTUAL_INFORMATION)
            stats.update({"Policy/GAIL Beta": net.beta.item(), "Losses/GAIL KL Loss": kl.item()})
        penalty = GAIL_GRADIENT_PENALTY * self.gradient_penalty(policy_obs, policy_actions, expert_obs, expert_actions)
        stats["Policy/GAIL Grad Mag Loss"] = penalty.item()
        total = total + penalty
        self.optimizer.zero_grad()
        total.backward()
        self.optimizer.step()
        return stats

    def gradient_penalty(self, policy_obs, policy_actions, expert_obs, expert_actions) -> torch.Tensor:
        """mean((|dD/dx~| - 1)^2) at random mixes x~ of policy and expert inputs (WGAN-GP), the
        gradient with respect to the first observation."""
        mixed = []
        for p, e in zip(policy_obs, expert_obs):
            u = torch.rand(p.shape, generator=self.generator)
            mixed.append((u * p + (1 - u) * e).requires_grad_(True))
        actions = None
        if policy_actions is not None:
            u = torch.rand(policy_actions.shape, generator=self.generator)
            actions = (u * policy_actions + (1 - u) * expert_actions).detach().requires_grad_(True)
        estimate, _ = self.network.estimate(mixed, actions, self._noise(len(mixed[0])))
        (gradient,) = torch.autograd.grad(estimate.sum(), mixed[0], create_graph=True)
        norm = torch.sqrt(torch.sum(gradient.reshape(len(gradient), -1) ** 2, dim=1) + GAIL_EPSILON)
        return torch.mean((norm - 1.0) ** 2)

    def modules(self) -> list[nn.Module]:
        return [self.network]

    def state_dict(self) -> dict[str, Any]:
        return {"Module:GAIL": self.network.state_dict(),
                "Optimizer:GAIL": {**self.optimizer.state_dict(), "generator": self.generator.get_state()}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.network.load_state_dict(state["Module:GAIL"])
        optimizer = dict(state["Optimizer:GAIL"])
        generator = optimizer.pop("generator", None)
        if generator is not None:
            self.generator.set_state(generator)
        self.optimizer.load_state_dict(optimizer)


PROVIDERS = {"curiosity": CuriosityProvider, "rnd": RNDProvider, "gail": GAILProvider}


def make_providers(spec: BehaviorSpec, reward_signals: dict[str, tuple[float, float]],
                   networks: dict[str, SignalNetwork], seed: int) -> dict[str, RewardProvider]:
    """One provider per intrinsic signal of ``reward_signals`` (name -> (gamma, strength), an
    algorithm view's), built from its entry of ``networks`` (the view's ``reward_signal_networks``)
    and initialised from its own seed (``seed`` + its position), in the order of the YAML."""
    providers = {}
    for index, (name, (_gamma, strength)) in enumerate(reward_signals.items()):
        if name in PROVIDERS:
            with torch.random.fork_rng(devices=[]):
                torch.manual_seed(seed + index)
                providers[name] = PROVIDERS[name](spec, strength, networks[name])
    return providers


def load_providers(providers: dict[str, RewardProvider], state: dict) -> None:
    """Restore each provider from a checkpoint (PPO, POCA and SAC alike); one the checkpoint lacks
    (a signal added since) starts untrained, with one warning."""
    for name, provider in providers.items():
        keys = provider.state_dict().keys()
        if all(key in state for key in keys):
            provider.load_state_dict(state)
        else:
            logger.warning("The checkpoint has no %s reward signal (%s): it starts untrained.",
                           name, ", ".join(sorted(k for k in keys if k not in state)))
