"""The acting policy: one batched forward pass for every deciding agent of a behavior.

Continuous actions are sampled from an unbounded Gaussian; the raw sample is kept for log-probs and
the environment receives clamp(a, -3, 3) / 3. Discrete actions are a multinomial sample per branch.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import torch

from trainer.common import numpy_distributions as nd
from trainer.common import numpy_net
from trainer.common.distributions import (
    categorical_entropy,
    categorical_log_prob,
    combined_entropy,
    gaussian_entropy,
    gaussian_log_prob,
)
from trainer.common.networks import Actor
from trainer.common.hyperparams import NetworkHyperparams
from protos.types import ActionTuple, BehaviorSpec

CONTINUOUS_CLIP = 3.0
_MAX, _SUM = np.maximum.reduce, np.add.reduce  # ndarray.max/sum without their Python wrappers


@dataclass(frozen=True)
class PolicyOutput:
    """What one call to ``Policy.act`` produced for n agents."""

    env_actions: ActionTuple  # continuous float32 [n, c] in [-1, 1]; discrete int32 [n, b]
    continuous_raw: np.ndarray  # float32 [n, c] unclamped samples (stored for log-probs)
    discrete: np.ndarray  # int32 [n, b]
    log_probs: np.ndarray  # float32 [n, c + b], per continuous dimension then per discrete branch
    # computes ``entropy`` when first read: the rollout never reads it, so deciding skips it
    entropy_of: Callable[[], np.ndarray] = field(repr=False, compare=False)
    memories: np.ndarray | None = None  # float32 [n, memory_size]: each agent's next memory (LSTM only)

    @functools.cached_property
    def entropy(self) -> np.ndarray:
        """float32 [n]: mean over the Gaussian's dimensions + sum over the discrete branches."""
        return self.entropy_of()


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
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.actor = Actor(behavior_spec.observation_specs, self.action_spec, hyperparams,
                               squashed=self.SQUASHED).to(self.device)
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(seed + 1)
        # vector-only actors on the CPU decide in numpy (see numpy_net for why)
        use_numpy = self.device.type == "cpu" and numpy_net.supports(self.actor, recurrent=True)
        self.memory_size = hyperparams.memory_size  # > 0: act takes and returns each agent's memory
        self._numpy_actor = numpy_net.NumpyActor(self.actor) if use_numpy else None

    @property
    def numpy_actor(self) -> numpy_net.NumpyActor | None:
        """The actor in numpy (vector observations on the CPU), or None: ``act`` uses torch."""
        return self._numpy_actor
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
            return self._act_numpy(obs, action_mask, deterministic, memories)
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

    def _act_numpy(self, obs: Sequence[np.ndarray], action_mask: np.ndarray | None,
                   deterministic: bool, memories: np.ndarray | None = None) -> PolicyOutput:
        """``act`` in numpy: same distributions, noise drawn from the same torch generator.

        Runs once per decision step, often for one agent, so it is written for numpy's per-call
        cost: reductions through the ufuncs (``ndarray.max``/``sum`` add a Python wrapper each),
        no copies of arrays that already have their dtype."""
        mu, logits, memories_out = self._numpy_actor.heads(list(obs), action_mask, memories)
        n = len(obs[0])
        log_parts: list[np.ndarray] = []
        continuous_entropy = None
        if mu is not None:
            sigma, continuous_entropy = self._numpy_actor.gaussian()
            if deterministic:
                raw = mu
            else:
                noise = torch.randn(mu.shape, generator=self.generator).numpy()
                raw = mu + noise * sigma
            log_parts.append(nd.gaussian_log_prob(raw, mu, self._numpy_actor.log_sigma, float64_constant=True))
            raw = raw.astype(np.float32, copy=False)
            env_continuous = np.minimum(np.maximum(raw, -CONTINUOUS_CLIP), CONTINUOUS_CLIP) / CONTINUOUS_CLIP
        else:
            raw = env_continuous = np.zeros((n, 0), dtype=np.float32)
        discrete, branch_probs = self._sample_discrete_numpy(logits, n, deterministic, log_parts)
        log_probs = log_parts[0] if len(log_parts) == 1 else np.concatenate(log_parts, axis=1)
        return PolicyOutput(
            env_actions=ActionTuple(env_continuous, discrete),
            continuous_raw=raw,
            discrete=discrete,
            log_probs=log_probs.astype(np.float32, copy=False),
            entropy_of=lambda: nd.combined_entropy(
                continuous_entropy, [nd.categorical_entropy(probs) for probs in branch_probs], n),
            memories=memories_out,
        )

    def _sample_discrete_numpy(self, logits: list[np.ndarray], n: int, deterministic: bool,
                               log_parts: list[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
        """One option per branch from masked logits [n, k_b] (argmax if ``deterministic``, else
        the policy's torch generator): (discrete int32 [n, b], probabilities per branch); each
        branch's log-prob [n, 1] is appended to ``log_parts``."""
        discrete = np.empty((n, len(logits)), dtype=np.int32)
        branch_probs = []
        for index, branch_logits in enumerate(logits):
            probs = nd.softmax(branch_logits)
            if deterministic:
                action = probs.argmax(axis=1)
            else:
                u = torch.rand(n, generator=self.generator).numpy()[:, None]
                action = _SUM(probs.cumsum(axis=1) <= u, axis=1)  # an option with probability > 0
                if n and _MAX(action) >= probs.shape[1]:
                    # rounding pushed some u past the last cumulative sum: the last allowed option
                    last_allowed = probs.shape[1] - 1 - (probs[:, ::-1] > 0).argmax(axis=1)
                    action = np.minimum(action, last_allowed)
            discrete[:, index] = action
            log_parts.append(nd.categorical_log_prob(probs, action)[:, None])
            branch_probs.append(probs)
        return discrete, branch_probs

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
