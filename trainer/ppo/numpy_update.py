"""PPO minibatch steps in numpy with hand-written gradients, for vector-observation networks.

Why: a minibatch of ML-Agents-sized networks (64 samples, 2 x 128 units) is a few dozen tiny
tensor ops, and in torch most of its ~3 ms go to per-op dispatch and the autograd engine
(measured: backward alone 36 % of an update). The same arithmetic as numpy matmuls takes a
fraction of that. The torch modules stay the single source of truth: their parameters are
updated in place through shared memory, and their version counters are bumped afterwards so
the numpy actor/critic copies, checkpoints and ONNX export all see the new weights.
tests/unit/test_ppo_numpy_update.py checks losses, and weights after several steps, against
the torch path (autograd + Adam), for continuous, discrete with masks and hybrid policies.

Math (what ``PPOTrainer._minibatch_loss`` + ``Adam.step`` compute; shapes n = batch):
    body:    z = clip((x - mean)/std, -5, 5) per input, concatenated; h_l = swish(h_{l-1} W_l^T + b_l)
    actor:   mu = h W_mu^T + b_mu, sigma = exp(log_sigma);   logits_b = (h W_b^T + b_b) masked
    logp:    Gaussian per dimension, log(p[a] + 1e-7) per branch -> [n, c + B]
    entropy: mean_c 0.5 log(2 pi e sigma^2 + 1e-7) + sum_b -sum p log(p + 1e-7)
    loss:    -mean(min(r A, clip(r, 1 +- eps) A)) + 0.5 mean_k mean (R_k - V_k)^2 - beta mean(entropy)
The value term is (R - V)^2 because the trainer anchors the value clip at the returns (see
PPOTrainer._minibatch_loss); with old values = returns the clipped branch never exceeds it.
"""
from __future__ import annotations

import logging
import math
import mmap
import os
import signal
import sys
import threading

import numpy as np
import torch
from torch import nn

from trainer.ppo import fast_actor
from trainer.ppo.adam import Adam
from trainer.ppo.distributions import EPSILON, MASKED_LOGIT_OFFSET
from trainer.envs.cpus import usable_cpus

logger = logging.getLogger(__name__)
_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))
_TWO_PI_E = 2 * math.pi * math.e


# rows x critic parameters of an update below which forking costs more than it saves: the fork
# of a ~250 MB trainer takes ~8 ms. Measured on 2 vCPUs: basic (24 minibatches x 32 rows, 461
# critic parameters) 12 -> 20 ms per update; ball3d (562 x 64 rows, 17.7k) 0.55 -> 0.40 s.
FORK_MIN_WORK = 50e6


def fork_pays_off(work: float) -> bool:
    """Run the critic's half in a child process? Only on Linux (fork is not safe with the
    system BLAS of macOS, and absent on Windows), with a second CPU for it, no other Python
    thread that could hold a lock across the fork, and enough ``work`` (rows x parameters)."""
    return (sys.platform.startswith("linux") and hasattr(os, "fork") and usable_cpus() >= 2
            and threading.active_count() == 1 and work >= FORK_MIN_WORK)


def supports(trainer) -> bool:
    return (trainer.device.type == "cpu" and isinstance(trainer.optimizer, Adam)
            and fast_actor.supports(trainer.policy.actor) and fast_actor.supports(trainer.critic))


def _normalized(network_body, obs: list[np.ndarray]) -> np.ndarray:
    """The body's input (normalised, clipped, concatenated) for the whole buffer at once."""
    return fast_actor.body_input(obs, fast_actor.body_normalizers(network_body))


class _Body:
    """Live numpy views of a NetworkBody's hidden Linear layers (shared memory with torch)."""

    def __init__(self, network_body) -> None:
        self.linears = [m for m in network_body.hidden if isinstance(m, nn.Linear)]
        self.params = [(m.weight.detach().numpy(), m.bias.detach().numpy()) for m in self.linears]

    # The elementwise steps below run in place on fresh arrays (one pass, no temporaries) and
    # do the same float32 operations, in the same order, as the plain expressions they replace.
    def forward(self, h: np.ndarray) -> tuple[np.ndarray, list]:
        cache = []
        for weight, bias in self.params:
            a = h @ weight.T
            a += bias
            s = np.negative(a)  # s = 1 / (1 + exp(-a))
            np.exp(s, out=s)
            s += 1.0
            np.reciprocal(s, out=s)
            cache.append((h, a, s))
            h = a * s
        return h, cache

    def backward(self, grad_h: np.ndarray, cache: list, grads: dict) -> None:
        last = len(cache) - 1
        for index, ((weight, _), linear, (h_in, a, s)) in enumerate(
                zip(reversed(self.params), reversed(self.linears), reversed(cache))):
            grad_a = a * s  # grad_h * (s + a * s * (1 - s))
            grad_a *= 1.0 - s
            grad_a += s
            grad_a *= grad_h
            grads[id(linear.weight)] = grad_a.T @ h_in
            grads[id(linear.bias)] = np.add.reduce(grad_a, axis=0)
            if index < last:  # the first layer's input (the observations) needs no gradient
                grad_h = grad_a @ weight


class NumpyPPO:
    """Minibatch steps for one PPOTrainer; ``prepare`` once per update, then ``run``, ``finish``
    at the end (bumps the torch version counters).

    The actor and the critic are separate networks here (a shared body keeps the torch path,
    see ``supports``), so their halves of a minibatch step never touch each other's arrays:
    the policy and entropy terms reach only the actor's parameters, the value term only the
    critic's, and Adam is elementwise. ``run`` therefore steps the actor through every
    minibatch and then the critic (the same arithmetic as alternating them), and when it pays
    off, the critic's half runs at the same time in a forked child process (``_CriticChild``)
    on the CPU the simulator leaves idle while the trainer updates. Weights, moments and
    statistics are bit-for-bit those of the sequential steps.
    """

    ACTOR_KEYS = ("continuous_actions", "discrete_actions", "allowed", "advantages", "log_probs")

    def __init__(self, trainer) -> None:
        actor, critic = trainer.policy.actor, trainer.critic
        self.actor, self.critic = actor, critic
        self.actor_body, self.critic_body = _Body(actor.network_body), _Body(critic.network_body)
        self.mu = (actor.mu.weight.detach().numpy(), actor.mu.bias.detach().numpy()) if actor.mu is not None else None
        self.log_sigma = actor.log_sigma.detach().numpy() if actor.mu is not None else None
        self.branches = [(b.weight.detach().numpy(), b.bias.detach().numpy()) for b in actor.discrete_branches]
        self.offsets = list(actor._mask_offsets)
        self.heads = {name: (h.weight.detach().numpy(), h.bias.detach().numpy())
                      for name, h in critic.value_heads.items()}
        optimizer: Adam = trainer.optimizer
        self.optimizer = optimizer
        # Adam's moments as two flat vectors for the update (written back by ``finish``); the
        # optimizer holds the actor's parameters, then the critic's (PPOTrainer builds it so)
        arrays = [p.detach().numpy() for p in optimizer.params]
        sizes = [a.size for a in arrays]
        bounds = list(zip(np.cumsum([0] + sizes[:-1]).tolist(), np.cumsum(sizes).tolist()))
        self.bounds = bounds
        self.exp_avg = np.concatenate([t.numpy().reshape(-1) for t in optimizer.exp_avg]).astype(np.float32)
        self.exp_avg_sq = np.concatenate([t.numpy().reshape(-1) for t in optimizer.exp_avg_sq]).astype(np.float32)
        actor_ids = {id(p) for p in actor.parameters()}
        split = sum(id(p) in actor_ids for p in optimizer.params)
        if any(id(p) not in actor_ids for p in optimizer.params[:split]):
            raise ValueError("the optimizer must hold the actor's parameters before the critic's")
        self._adam_parts = {
            half: _AdamPart(optimizer.params[lo:hi], arrays[lo:hi], bounds[lo:hi], self.exp_avg, self.exp_avg_sq)
            for half, (lo, hi) in (("actor", (0, split)), ("critic", (split, len(arrays))))
        }

    def prepare(self, obs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Normalised inputs of the whole buffer for the actor and the critic (their statistics
        do not change during an update)."""
        return _normalized(self.actor.network_body, obs), _normalized(self.critic.network_body, obs)

    # ------------------------------------------------------------------ a whole update
    def run(self, data: dict[str, np.ndarray], actor_in: np.ndarray, critic_in: np.ndarray,
            orders: list[np.ndarray], learning_rate: float, beta: float, epsilon: float,
            parallel: bool | None = None) -> list[dict[str, float]]:
        """One ``step`` per minibatch (row indices ``orders``); ``parallel``: the critic's
        half in a forked child process (``_CriticChild``); None: when ``fork_pays_off``.
        Returns each minibatch's statistics."""
        if parallel is None:
            parallel = fork_pays_off(sum(map(len, orders)) * self._adam_parts["critic"].exp_avg.size)
        first_t = self.optimizer.step_count + 1
        actor_keys = [k for k in self.ACTOR_KEYS if k in data]
        critic_keys = [f"returns:{name}" for name in self.heads]

        def actor_half(k: int, index: np.ndarray) -> tuple[float, float]:
            batch = {key: data[key][index] for key in actor_keys}
            return self.actor_step(batch, actor_in[index], learning_rate, beta, epsilon, first_t + k)

        def critic_half(k: int, index: np.ndarray) -> float:
            batch = {key: data[key][index] for key in critic_keys}
            return self.critic_step(batch, critic_in[index], learning_rate, first_t + k)

        # the halves are independent: all actor steps, then all critic steps, give the same
        # arithmetic as alternating them; ``parallel`` runs the critic's in a child process
        child = _CriticChild.start(self._adam_parts["critic"], critic_half, orders) if parallel else None
        try:
            actor = [actor_half(k, index) for k, index in enumerate(orders)]
        except BaseException:
            if child is not None:
                child.abandon()
            raise
        values = child.collect() if child is not None else None
        if values is None:  # sequential, or the child failed (the critic here is untouched)
            values = [critic_half(k, index) for k, index in enumerate(orders)]
        self.optimizer.step_count = first_t - 1 + len(orders)
        return [_stats(policy_term, value_term, entropy)
                for (policy_term, entropy), value_term in zip(actor, values)]

    # ------------------------------------------------------------------ one minibatch
    def actor_step(self, batch: dict[str, np.ndarray], actor_in: np.ndarray, learning_rate: float,
                   beta: float, epsilon: float, t: int) -> tuple[float, float]:
        """The policy and entropy terms' gradients and Adam step (number ``t``) for the actor.
        Returns (policy term, mean entropy)."""
        grads: dict[int, np.ndarray] = {}
        n = len(actor_in)
        h, actor_cache = self.actor_body.forward(actor_in)
        logp_parts, ent = [], np.zeros(n, dtype=np.float32)
        back = []  # per output column group: what the backward pass needs
        if self.mu is not None:
            w_mu, b_mu = self.mu
            mu = h @ w_mu.T + b_mu
            sigma = np.exp(self.log_sigma)  # [1, c]
            denom = 2 * sigma ** 2 + EPSILON
            diff = batch["continuous_actions"] - mu
            logp_parts.append(-(diff ** 2) / denom - np.log(sigma + EPSILON) - _LOG_SQRT_2PI)
            ent = ent + np.mean(0.5 * np.log(_TWO_PI_E * sigma ** 2 + EPSILON))
            back.append(("gaussian", diff, sigma, denom))
        allowed = batch.get("allowed")
        for index, (weight, bias) in enumerate(self.branches):
            logits = h @ weight.T + bias
            start, end = self.offsets[index], self.offsets[index + 1]
            a = allowed[:, start:end] if allowed is not None else None
            if a is not None:
                logits = logits * a - MASKED_LOGIT_OFFSET * (1.0 - a)
            z = np.exp(logits - logits.max(axis=1, keepdims=True))
            probs = z / z.sum(axis=1, keepdims=True)
            action = batch["discrete_actions"][:, index]
            chosen = probs[np.arange(n), action]
            logp_parts.append(np.log(chosen + EPSILON)[:, None])
            log_p = np.log(probs + EPSILON)
            ent = ent - np.sum(probs * log_p, axis=1)
            back.append(("categorical", index, probs, chosen, action, log_p, a))
        log_probs = np.concatenate(logp_parts, axis=1)
        # ---- policy term
        advantages = batch["advantages"][:, None]
        ratio = np.exp(log_probs - batch["log_probs"])
        unclipped = ratio * advantages
        clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
        policy_term = -np.mean(np.minimum(unclipped, clipped))
        # ---- gradients: policy and entropy terms -> actor outputs
        grad_logp = np.where(unclipped <= clipped, -unclipped / log_probs.size, 0.0).astype(np.float32)
        grad_h = np.zeros_like(h)
        column = 0
        for item in back:
            if item[0] == "gaussian":
                _, diff, sigma, denom = item
                c = diff.shape[1]
                g = grad_logp[:, column:column + c]
                column += c
                grad_mu = g * 2.0 * diff / denom
                grad_ls = np.sum(g * (diff ** 2 * 4.0 * sigma ** 2 / denom ** 2 - sigma / (sigma + EPSILON)),
                                 axis=0, keepdims=True)
                grad_ls += -beta / c * (_TWO_PI_E * sigma ** 2 / (_TWO_PI_E * sigma ** 2 + EPSILON))
                w_mu, _ = self.mu
                grads[id(self.actor.mu.weight)] = grad_mu.T @ h
                grads[id(self.actor.mu.bias)] = grad_mu.sum(axis=0)
                grads[id(self.actor.log_sigma)] = grad_ls
                grad_h += grad_mu @ w_mu
            else:
                _, index, probs, chosen, action, log_p, a = item
                g = grad_logp[:, column]
                column += 1
                onehot = np.zeros_like(probs)
                onehot[np.arange(n), action] = 1.0
                grad_logits = (g * chosen / (chosen + EPSILON))[:, None] * (onehot - probs)
                # entropy -sum p log(p + eps): d/dp_j = -log(p_j + eps) - p_j / (p_j + eps)
                d_ent = -log_p - probs / (probs + EPSILON)
                grad_ent = probs * (d_ent - np.sum(probs * d_ent, axis=1, keepdims=True))
                grad_logits += (-beta / n) * grad_ent
                if a is not None:
                    grad_logits = grad_logits * a
                weight, _ = self.branches[index]
                branch = self.actor.discrete_branches[index]
                grads[id(branch.weight)] = grad_logits.T @ h
                grads[id(branch.bias)] = grad_logits.sum(axis=0)
                grad_h += grad_logits @ weight
        self.actor_body.backward(grad_h, actor_cache, grads)
        self._adam_parts["actor"].step(grads, learning_rate, t, self.optimizer.param_groups[0])
        return float(policy_term), float(np.mean(ent))

    def critic_step(self, batch: dict[str, np.ndarray], critic_in: np.ndarray, learning_rate: float,
                    t: int) -> float:
        """The value term's gradients and Adam step (number ``t``) for the critic. Returns the
        value term."""
        grads: dict[int, np.ndarray] = {}
        n = len(critic_in)
        hc, critic_cache = self.critic_body.forward(critic_in)
        values = {name: (hc @ w.T + b)[:, 0] for name, (w, b) in self.heads.items()}
        errors = {name: values[name] - batch[f"returns:{name}"] for name in values}
        value_term = np.mean([np.mean(e ** 2) for e in errors.values()])
        # ---- value term -> critic
        grad_hc = np.zeros_like(hc)
        scale = 0.5 * 2.0 / (n * len(errors))
        for name, error in errors.items():
            w, _ = self.heads[name]
            g = (scale * error)[:, None].astype(np.float32)
            head = self.critic.value_heads[name]
            grads[id(head.weight)] = g.T @ hc
            grads[id(head.bias)] = g.sum(axis=0)
            grad_hc += g @ w
        self.critic_body.backward(grad_hc, critic_cache, grads)
        self._adam_parts["critic"].step(grads, learning_rate, t, self.optimizer.param_groups[0])
        return float(value_term)

    def finish(self) -> None:
        """Write Adam's moments back and tell torch the tensors changed (numpy writes do not
        bump version counters)."""
        optimizer = self.optimizer
        with torch.no_grad():
            for index, (start, end) in enumerate(self.bounds):
                shape = optimizer.exp_avg[index].shape
                optimizer.exp_avg[index].copy_(torch.from_numpy(self.exp_avg[start:end].reshape(shape)))
                optimizer.exp_avg_sq[index].copy_(torch.from_numpy(self.exp_avg_sq[start:end].reshape(shape)))
            for tensor in optimizer.params:
                tensor.add_(0.0)


def _stats(policy_term: float, value_term: float, entropy: float) -> dict[str, float]:
    return {"Losses/Policy Loss": abs(policy_term), "Losses/Value Loss": value_term, "Policy/Entropy": entropy}


class _AdamPart:
    """Adam.step's arithmetic for some of the optimizer's parameters (one network's), on their
    stretch of the flat moment vectors. Elementwise, so stepping the parts one by one gives
    what one step over all parameters gives."""

    def __init__(self, params: list, arrays: list[np.ndarray], bounds: list[tuple[int, int]],
                 exp_avg: np.ndarray, exp_avg_sq: np.ndarray) -> None:
        self.params, self.arrays = params, arrays
        start, end = (bounds[0][0], bounds[-1][1]) if bounds else (0, 0)
        self.bounds = [(lo - start, hi - start) for lo, hi in bounds]
        self.exp_avg, self.exp_avg_sq = exp_avg[start:end], exp_avg_sq[start:end]  # views
        self.flat_grad = np.empty_like(self.exp_avg)
        self._scratch = np.empty_like(self.exp_avg)  # the one temporary

    def step(self, grads: dict[int, np.ndarray], learning_rate: float, t: int, group: dict) -> None:
        (beta1, beta2), eps = group["betas"], group["eps"]
        g = self.flat_grad
        for param, (start, end) in zip(self.params, self.bounds):
            g[start:end] = grads[id(param)].reshape(-1)
        m, v = self.exp_avg, self.exp_avg_sq
        step = np.subtract(g, m, out=self._scratch)  # m += (1 - beta1) * (g - m)
        step *= 1 - beta1
        m += step
        v *= beta2
        np.multiply(g, 1 - beta2, out=step)  # v += (1 - beta2) * g * g
        step *= g
        v += step
        update = np.sqrt(v, out=step)  # m / (sqrt(v) / sqrt(1 - beta2^t) + eps)
        update /= math.sqrt(1 - beta2 ** t)
        update += eps
        np.divide(m, update, out=update)
        update *= learning_rate / (1 - beta1 ** t)
        for array, (start, end) in zip(self.arrays, self.bounds):
            array -= update[start:end].reshape(array.shape)


class _CriticChild:
    """The critic's half of an update in a forked child process, its result copied back.

    The child shares the parent's memory copy-on-write: the buffer, the critic's weights and
    Adam moments as they were at the fork. It runs every critic step, then writes the
    critic's parameters, its stretch of the moments and the value terms into an anonymous
    shared mapping and exits (``os._exit``: no cleanup, no atexit, nothing flushed). The
    parent's critic is untouched until ``collect`` copies the result in, so a child that fails
    or is killed costs only time: ``collect`` returns None and the parent steps the critic
    itself.
    """

    def __init__(self, pid: int, shared: mmap.mmap, arrays: list[np.ndarray], count: int) -> None:
        self.pid, self.shared, self.arrays, self.count = pid, shared, arrays, count

    @classmethod
    def start(cls, part: "_AdamPart", critic_half, orders: list) -> "_CriticChild | None":
        arrays = [*part.arrays, part.exp_avg, part.exp_avg_sq]
        shared = mmap.mmap(-1, sum(a.nbytes for a in arrays) + 8 * len(orders))
        try:
            pid = os.fork()
        except OSError:
            shared.close()
            return None
        if pid == 0:  # the child: never returns
            code = 1
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
                values = np.array([critic_half(k, index) for k, index in enumerate(orders)], dtype=np.float64)
                out, offset = memoryview(shared), 0
                for array in [*arrays, values]:
                    out[offset:offset + array.nbytes] = np.ascontiguousarray(array).reshape(-1).view(np.uint8)
                    offset += array.nbytes
                out.release()
                code = 0
            finally:
                os._exit(code)
        return cls(pid, shared, arrays, len(orders))

    def collect(self) -> list[float] | None:
        """Wait for the child; copy its critic in and return its value terms (None if it failed)."""
        try:
            try:
                _, status = os.waitpid(self.pid, 0)
            except OSError as error:  # e.g. reaped by someone else: its result cannot be trusted
                status = f"unknown: {error}"
            if status != 0:
                logger.warning("The critic's update in a child process failed (wait status %s); "
                               "the trainer steps the critic itself.", status)
                return None
            offset = 0
            for array in self.arrays:
                np.copyto(array, np.frombuffer(self.shared, dtype=array.dtype, count=array.size,
                                               offset=offset).reshape(array.shape))
                offset += array.nbytes
            return np.frombuffer(self.shared, dtype=np.float64, count=self.count, offset=offset).tolist()
        finally:
            self.shared.close()

    def abandon(self) -> None:
        """The parent gave up on this update: stop the child and reap it."""
        try:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        except OSError:
            pass
        self.shared.close()
