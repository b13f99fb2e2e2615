"""The acting policy: one batched forward pass for every deciding agent of a behavior.

Vector-observation actors on the CPU decide in numpy (numpy_policy.py, with numpy_net's views of
this actor's tensors); others in torch here. Continuous actions are sampled from an unbounded
Gaussian; the raw sample is kept for log-probs and the environment receives clamp(a, -3, 3) / 3.
Discrete actions are a multinomial sample per branch.
"""
from __future__ import annotations

import functools
from typing import Sequence

import numpy as np
import torch

from trainer.common import initial_parameters, numpy_net
from trainer.common.distributions import (
    categorical_entropy,
    categorical_log_prob,
    combined_entropy,
    gaussian_entropy,
    gaussian_log_prob,
)
from trainer.common.networks import Actor
from trainer.common.numpy_policy import CONTINUOUS_CLIP, NumpyPolicy, PolicyOutput, noise_generator
from trainer.common.hyperparams import NetworkHyperparams
from protos.types import ActionTuple, BehaviorSpec

__all__ = ["CONTINUOUS_CLIP", "Policy", "PolicyOutput", "allowed_from_mask", "initial_actor"]


def initial_actor(behavior_spec: BehaviorSpec, hyperparams: NetworkHyperparams, squashed: bool, seed: int
                  ) -> dict[str, np.ndarray] | None:
    """The actor's initial state dict drawn in numpy from ``seed`` (initial_parameters.py), or
    None for visual observations (then the torch modules initialise themselves)."""
    spec = behavior_spec.action_spec
    return initial_parameters.actor_parameters([tuple(o.shape) for o in behavior_spec.observation_specs],
                                               spec.continuous_size, spec.discrete_branches, hyperparams,
                                               squashed, seed)


def allowed_from_mask(action_mask: np.ndarray | None) -> torch.Tensor | None:
    """bool [n, sum(branches)] with True = masked -> float tensor with 1 = allowed (None stays None)."""
    if action_mask is None:
        return None
    return torch.from_numpy(np.logical_not(action_mask)).float()


class Policy:
    """Actor network plus sampling. ``act`` is the hot path used by the rollout for every decision.

    ``SQUASHED``: the actor kind (networks.Actor); SAC's policy (trainer/sac/policy.py) sets it."""

    SQUASHED = False

    def __init__(self, behavior_spec: BehaviorSpec, hyperparams: NetworkHyperparams, seed: int,
                 device: str = "cpu"):
        self.behavior_spec = behavior_spec
        self.action_spec = behavior_spec.action_spec
        self.hyperparams = hyperparams
        self.device = torch.device(device)
        initial = initial_actor(behavior_spec, hyperparams, self.SQUASHED, seed)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.actor = Actor(behavior_spec.observation_specs, self.action_spec, hyperparams,
                               squashed=self.SQUASHED)
        if initial is not None:  # strict: every name and shape of networks.Actor
            self.actor.load_state_dict({k: torch.from_numpy(v) for k, v in initial.items()})
        self.actor.to(self.device)
        self.generator = torch.Generator(device=self.device)  # the torch path's noise (visual, GPU)
        self.generator.manual_seed(seed + 1)
        # vector-only actors on the CPU decide in numpy (see numpy_net for why)
        use_numpy = self.device.type == "cpu" and numpy_net.supports(self.actor, recurrent=True)
        self.memory_size = hyperparams.memory_size  # > 0: act takes and returns each agent's memory
        self._numpy_actor = numpy_net.NumpyActor(self.actor) if use_numpy else None
        self.sampler = NumpyPolicy(self._numpy_actor, noise_generator(seed), self.SQUASHED,
                                   hyperparams.deterministic)

    @property
    def numpy_actor(self) -> numpy_net.NumpyActor | None:
        """The actor in numpy (vector observations on the CPU), or None: ``act`` uses torch."""
        return self._numpy_actor

    def take_over(self, first: NumpyPolicy) -> None:
        """Continue from the policy that decided a run's first actions before torch was loaded
        (trainer/first_steps.py): the actor loads exactly its arrays and the noise generator
        continues where it is, so acting goes on as if this policy had decided from the start."""
        self.actor.load_state_dict({k: torch.from_numpy(np.asarray(v)) for k, v in first.actor.params.items()})
        self.sampler.noise = first.noise

    def reseed_noise(self, seed: int) -> None:
        """Data-parallel ranks (trainer/distributed.py): this rank's own sampling seed."""
        self.generator.manual_seed(seed)
        self.sampler.noise = noise_generator(seed - 1)

    def _to_tensors(self, obs: Sequence[np.ndarray]) -> list[torch.Tensor]:
        return [torch.as_tensor(np.asarray(o, dtype=np.float32), device=self.device) for o in obs]

    def act(self, obs: Sequence[np.ndarray], action_mask: np.ndarray | None = None,
            deterministic: bool = False, memories: np.ndarray | None = None) -> PolicyOutput:
        """Sample actions for n agents in one forward pass.

        obs: one float32 array [n, *shape_i] per observation. action_mask: bool [n, sum(branches)],
        True = masked, or None. ``deterministic`` (or hyperparams.deterministic) uses mean / argmax.
        memories: float32 [n, memory_size] for a recurrent actor (None = all zero, new episodes).
        """
        deterministic = deterministic or self.hyperparams.deterministic
        if self._numpy_actor is not None:
            return self.sampler.act(obs, action_mask, deterministic, memories)
        allowed = allowed_from_mask(action_mask)
        with torch.inference_mode():
            tensors = self._to_tensors(obs)
            if allowed is not None:
                allowed = allowed.to(self.device)
            n = tensors[0].shape[0]
            memories_out = None
            if self.memory_size:
                memory_in = (torch.zeros((n, self.memory_size)) if memories is None
                             else torch.as_tensor(np.asarray(memories, dtype=np.float32)))
                mu, logits, memories_out = self.actor.heads_with_memory(
                    tensors, allowed, memory_in.to(self.device).unsqueeze(0), 1)
                memories_out = memories_out[0].cpu().numpy()
            else:
                mu, logits = self.actor.heads(tensors, allowed)
            log_prob_parts: list[torch.Tensor] = []
            discrete_entropies: list[torch.Tensor] = []
            continuous_entropy = None
            raw = torch.zeros((n, 0), device=self.device)
            if mu is not None:
                log_sigma = self.actor.log_sigma.expand_as(mu)
                raw = mu if deterministic else mu + torch.randn(
                    mu.shape, generator=self.generator, device=self.device
                ) * torch.exp(log_sigma)
                log_prob_parts.append(gaussian_log_prob(raw, mu, log_sigma))
                continuous_entropy = gaussian_entropy(log_sigma)
            chosen = []
            for branch_logits in logits:
                probs = torch.softmax(branch_logits, dim=1)
                if deterministic:
                    action = torch.argmax(probs, dim=1)
                else:
                    action = torch.multinomial(probs, 1, generator=self.generator).squeeze(1)
                chosen.append(action)
                log_prob_parts.append(categorical_log_prob(probs, action).unsqueeze(1))
                discrete_entropies.append(categorical_entropy(probs))
            discrete = torch.stack(chosen, dim=1) if chosen else torch.zeros((n, 0), dtype=torch.int64)
            log_probs = torch.cat(log_prob_parts, dim=1)
            entropy = combined_entropy(continuous_entropy, discrete_entropies)
            env_continuous = torch.clamp(raw, -CONTINUOUS_CLIP, CONTINUOUS_CLIP) / CONTINUOUS_CLIP
        discrete_np = discrete.to(torch.int32).cpu().numpy()
        return PolicyOutput(
            env_actions=ActionTuple(env_continuous.cpu().numpy(), discrete_np),
            continuous_raw=raw.cpu().numpy(),
            discrete=discrete_np,
            log_probs=log_probs.cpu().numpy(),
            entropy_of=functools.partial(np.asarray, entropy.cpu().numpy()),  # already computed
            memories=memories_out,
        )

    def evaluate(self, obs: Sequence[torch.Tensor], allowed: torch.Tensor | None,
                 continuous_actions: torch.Tensor, discrete_actions: torch.Tensor,
                 memories: torch.Tensor | None = None, sequence_length: int = 1
                 ) -> tuple[torch.Tensor, torch.Tensor]:
        """Log-probs [n, c + b] and entropy [n] of stored actions under the current actor (with grad).

        continuous_actions: raw samples [n, c]; discrete_actions: int [n, b]; allowed: float [n, sum(branches)].
        A recurrent actor reads the n rows as sequences of ``sequence_length`` starting from
        ``memories`` [1, n / sequence_length, memory_size].
        """
        if memories is not None:
            mu, logits, _ = self.actor.heads_with_memory(obs, allowed, memories, sequence_length)
        else:
            mu, logits = self.actor.heads(obs, allowed)
        parts: list[torch.Tensor] = []
        continuous_entropy = None
        if mu is not None:
            log_sigma = self.actor.log_sigma.expand_as(mu)
            parts.append(gaussian_log_prob(continuous_actions, mu, log_sigma))
            continuous_entropy = gaussian_entropy(log_sigma)
        discrete_entropies = []
        for index, branch_logits in enumerate(logits):
            probs = torch.softmax(branch_logits, dim=1)
            parts.append(categorical_log_prob(probs, discrete_actions[:, index]).unsqueeze(1))
            discrete_entropies.append(categorical_entropy(probs))
        return torch.cat(parts, dim=1), combined_entropy(continuous_entropy, discrete_entropies)
