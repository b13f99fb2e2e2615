"""Deciding actions in numpy: sampling from the actor's heads, with no torch.

The acting half of policy.py (PPO's Gaussian and categorical sampling) and of
trainer/sac/policy.py (the tanh-squashed Gaussian), for a numpy_net.NumpyActor. The torch
policies act through it for vector-observation actors on the CPU, and before torch is loaded a
run's first actions are decided by it alone, with the actor initial_parameters.py drew
(docs/performance.md, "Start-up and exit"). Its noise is a numpy generator seeded from the
policy's seed, handed from the first-steps policy to the torch one: the noise stream does not
depend on when torch finished importing, so a seeded run is reproducible.

PPO: continuous actions are sampled from an unbounded Gaussian; the raw sample is kept for
log-probs and the environment receives clamp(a, -3, 3) / 3. SAC (``squashed``): the environment
and the replay buffer get tanh(sample). Discrete actions: a multinomial sample per branch.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
# numpy 2 loads numpy.random on first use (noise_generator): imported with this module, while the
# simulators boot, not between the handshake and the first actions (trainer/run.py's numpy.ma too)
import numpy.random  # noqa: F401

from protos.types import ActionTuple
from trainer.common import numpy_distributions as nd
from trainer.common.numpy_net import NumpyActor

CONTINUOUS_CLIP = 3.0
_MAX, _SUM = np.maximum.reduce, np.add.reduce  # ndarray.max/sum without their Python wrappers


def noise_generator(seed: int) -> np.random.Generator:
    """The acting noise of a policy seeded ``seed`` (its torch generator, for torch-only actors, is seed + 1 too)."""
    return np.random.Generator(np.random.PCG64(seed + 1))


def noise_state(generator: np.random.Generator) -> np.ndarray:
    """The generator's state as uint8 [48] (a checkpoint stores tensors, never pickled objects)."""
    state = generator.bit_generator.state
    words = [state["state"]["state"], state["state"]["inc"]]
    raw = b"".join(w.to_bytes(16, "little") for w in words)
    extra = np.array([state["has_uint32"], state["uinteger"]], dtype=np.uint64).tobytes()
    return np.frombuffer(raw + extra, dtype=np.uint8).copy()


def set_noise_state(generator: np.random.Generator, data: np.ndarray) -> None:
    """``noise_state``'s inverse."""
    raw = np.asarray(data, dtype=np.uint8).tobytes()
    has_uint32, uinteger = np.frombuffer(raw[32:48], dtype=np.uint64)
    generator.bit_generator.state = {
        "bit_generator": "PCG64",
        "state": {"state": int.from_bytes(raw[:16], "little"), "inc": int.from_bytes(raw[16:32], "little")},
        "has_uint32": int(has_uint32), "uinteger": int(uinteger)}


@dataclass(frozen=True)
class PolicyOutput:
    """What one call to ``act`` produced for n agents."""

    env_actions: ActionTuple  # continuous float32 [n, c] in [-1, 1]; discrete int32 [n, b]
    continuous_raw: np.ndarray  # float32 [n, c] unclamped samples (stored for log-probs); SAC: squashed
    discrete: np.ndarray  # int32 [n, b]
    log_probs: np.ndarray  # float32 [n, c + b], per continuous dimension then per discrete branch
    # computes ``entropy`` when first read: the rollout never reads it, so deciding skips it
    entropy_of: Callable[[], np.ndarray] = field(repr=False, compare=False)
    memories: np.ndarray | None = None  # float32 [n, memory_size]: each agent's next memory (LSTM only)

    @functools.cached_property
    def entropy(self) -> np.ndarray:
        """float32 [n]: mean over the Gaussian's dimensions + sum over the discrete branches."""
        return self.entropy_of()


def _entropy(n: int, continuous_entropy: np.ndarray | None, branch_probs: list[np.ndarray]) -> np.ndarray:
    """float32 [n]: the Gaussian's entropy per dimension ([1, c] or [n, c]; None without continuous
    actions) averaged, plus each discrete branch's entropy."""
    return nd.combined_entropy(continuous_entropy, [nd.categorical_entropy(probs) for probs in branch_probs], n)


def squashed_entropy(n: int, log_sigma: np.ndarray | None, branch_probs: list[np.ndarray]) -> np.ndarray:
    """SAC, for ``Policy/Entropy``: the Gaussian's mean entropy *before* the tanh (the squashed one
    has no closed form), log_sigma [n, c], plus the entropy of each of ``branch_probs`` ([n, k]
    each; one array of every branch side by side sums them all). float32 [n]."""
    return _entropy(n, None if log_sigma is None else nd.gaussian_entropy(log_sigma), branch_probs)


class NumpyPolicy:
    """Samples actions from ``actor`` (None: the caller computes the heads, in torch, and calls
    ``sample_squashed``/``sample_discrete``) with the numpy generator ``noise``."""

    def __init__(self, actor: NumpyActor | None, noise: np.random.Generator, squashed: bool,
                 deterministic: bool = False) -> None:
        self.actor, self.noise, self.squashed, self.deterministic = actor, noise, squashed, deterministic

    @property
    def memory_size(self) -> int:
        """> 0: a recurrent actor; ``act`` takes and returns each agent's memory."""
        return 0 if self.actor is None else self.actor.body.memory_size

    def act(self, obs: Sequence[np.ndarray], action_mask: np.ndarray | None = None,
            deterministic: bool = False, memories: np.ndarray | None = None) -> PolicyOutput:
        """Actions for n agents in one forward pass. obs: one float32 array [n, size_i] per
        observation; action_mask: bool [n, sum(branches)], True = masked, or None;
        ``deterministic`` (or the hyperparameter) takes mean / argmax; memories: float32 [n, m]
        for a recurrent actor (None = all zero).

        Runs once per decision step, often for one agent, so it is written for numpy's per-call
        cost: reductions through the ufuncs, no copies of arrays that already have their dtype."""
        deterministic = deterministic or self.deterministic
        if self.squashed:
            h, memories_out = self.actor.hidden(list(obs), memories)
            mu, logits = self.actor.heads_of(h, action_mask)
            log_sigma = self.actor.log_sigma_of(h) if mu is not None else None
            return self.sample_squashed(mu, log_sigma, logits, len(obs[0]), deterministic, memories_out)
        mu, logits, memories_out = self.actor.heads(list(obs), action_mask, memories)
        n = len(obs[0])
        log_parts: list[np.ndarray] = []
        gaussian_entropy = None
        if mu is not None:
            sigma, gaussian_entropy, terms = self.actor.gaussian()  # cached while log_sigma is unchanged
            raw = mu if deterministic else mu + self.noise.standard_normal(mu.shape, dtype=np.float32) * sigma
            log_parts.append(nd.gaussian_log_prob(raw, mu, self.actor.log_sigma, float64_constant=True, terms=terms))
            raw = raw.astype(np.float32, copy=False)
            env_continuous = np.minimum(np.maximum(raw, -CONTINUOUS_CLIP), CONTINUOUS_CLIP) / CONTINUOUS_CLIP
        else:
            raw = env_continuous = np.zeros((n, 0), dtype=np.float32)
        discrete, branch_probs = self.sample_discrete(logits, n, deterministic, log_parts)
        log_probs = log_parts[0] if len(log_parts) == 1 else np.concatenate(log_parts, axis=1)
        return PolicyOutput(
            env_actions=ActionTuple(env_continuous, discrete),
            continuous_raw=raw,
            discrete=discrete,
            log_probs=log_probs.astype(np.float32, copy=False),
            entropy_of=functools.partial(_entropy, n, gaussian_entropy, branch_probs),
            memories=memories_out,
        )

    def sample_squashed(self, mu: np.ndarray | None, log_sigma: np.ndarray | None, logits: list[np.ndarray],
                        n: int, deterministic: bool, memories_out: np.ndarray | None) -> PolicyOutput:
        """SAC's actions from its heads: tanh(mu + noise * sigma) (tanh(mu) if ``deterministic``)
        and the discrete branches' samples."""
        log_parts: list[np.ndarray] = []
        if mu is not None:
            if deterministic:
                raw, continuous = mu, np.tanh(mu)
            else:
                raw, continuous = nd.squashed_sample(mu, log_sigma,
                                                     self.noise.standard_normal(mu.shape, dtype=np.float32))
            log_parts.append(nd.squashed_log_prob(raw, mu, log_sigma))
            continuous = continuous.astype(np.float32, copy=False)
        else:
            continuous = np.zeros((n, 0), dtype=np.float32)
        discrete, branch_probs = self.sample_discrete(logits, n, deterministic, log_parts)
        log_probs = np.concatenate(log_parts, axis=1) if log_parts else np.zeros((n, 0), np.float32)
        return PolicyOutput(
            env_actions=ActionTuple(continuous, discrete),
            continuous_raw=continuous,
            discrete=discrete,
            log_probs=log_probs.astype(np.float32, copy=False),
            entropy_of=functools.partial(squashed_entropy, n, log_sigma, branch_probs),
            memories=memories_out,
        )

    def sample_discrete(self, logits: list[np.ndarray], n: int, deterministic: bool,
                        log_parts: list[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
        """One option per branch from masked logits [n, k_b] (argmax if ``deterministic``, else
        the noise generator): (discrete int32 [n, b], probabilities per branch); each branch's
        log-prob [n, 1] is appended to ``log_parts``."""
        discrete = np.empty((n, len(logits)), dtype=np.int32)
        branch_probs = []
        for index, branch_logits in enumerate(logits):
            probs = nd.softmax(branch_logits)
            if deterministic:
                action = probs.argmax(axis=1)
            else:
                u = self.noise.random(n, dtype=np.float32)[:, None]
                action = _SUM(probs.cumsum(axis=1) <= u, axis=1)  # an option with probability > 0
                if n and _MAX(action) >= probs.shape[1]:
                    # rounding pushed some u past the last cumulative sum: the last allowed option
                    last_allowed = probs.shape[1] - 1 - (probs[:, ::-1] > 0).argmax(axis=1)
                    action = np.minimum(action, last_allowed)
            discrete[:, index] = action
            log_parts.append(nd.categorical_log_prob(probs, action)[:, None])
            branch_probs.append(probs)
        return discrete, branch_probs
