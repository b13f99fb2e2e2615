"""PPO minibatch steps in numpy with hand-written gradients, for vector-observation networks.

Why: a minibatch of ML-Agents-sized networks (64 samples, 2 x 128 units) is a few dozen tiny
tensor ops, and in torch most of its ~3 ms go to per-op dispatch and the autograd engine
(measured: backward alone 36 % of an update). The same arithmetic as numpy matmuls takes a
fraction of that. The networks are those of networks.py, read through numpy_net.py: forward
and backward run on numpy views of the torch parameters, and Adam (adam.py, the one optimiser)
steps them in place, so torch, acting, checkpoints and ONNX export see every change.
tests/unit/test_ppo_numpy_update.py checks the gradients against autograd on the same modules, and losses and weights after several steps
against the torch path (autograd + the same Adam), for continuous, discrete with masks and
hybrid policies.

Math (what ``PPOTrainer._minibatch_loss`` + ``Adam.step`` compute; shapes n = batch):
    body:    z = clip((x - mean)/std, -5, 5) per input, concatenated; h_l = swish(h_{l-1} W_l^T + b_l)
    actor:   mu = h W_mu^T + b_mu, sigma = exp(log_sigma);   logits_b = (h W_b^T + b_b) masked
    logp:    Gaussian per dimension, log(p[a] + 1e-7) per branch -> [n, c + B]
    entropy: mean_c 0.5 log(2 pi e sigma^2 + 1e-7) + sum_b -sum p log(p + 1e-7)
    loss:    -mean(min(r A, clip(r, 1 +- eps) A)) + 0.5 mean_k mean (R_k - V_k)^2 - beta mean(entropy)
The value term is (R - V)^2 because the trainer anchors the value clip at the returns (see
PPOTrainer._minibatch_loss); with old values = returns the clipped branch never exceeds it.

The critic's half in a forked child (``_CriticChild``): while the trainer updates, the simulators
wait for its actions, so the second CPU is idle. The actor's and the critic's halves of the steps
touch disjoint parameters, so the child steps the critic while the parent steps the actor, and
the result is bit for bit that of one process. It pays only with an idle second CPU, which is what
the simulators leave during an update on a machine of our own, and with 1 BLAS thread per process
(2 oversubscribe the CPUs); the measurements: docs/performance.md, "The PPO update in numpy and on
two CPUs". A child that dies, or
does not finish within max(FORK_TIMEOUT_MIN, FORK_TIMEOUT_FACTOR x the parent's own half),
is killed and reaped; the parent then steps the critic itself (its critic is untouched until a
child's result is copied in), says so once, and stops forking for the rest of the run.
"""
from __future__ import annotations

import logging
import mmap
import os
import select
import signal
import sys
import threading
import time

import numpy as np

from trainer.envs.cpus import usable_cpus
from trainer.common import numpy_net
from trainer.common.adam import Adam, Stretch
from trainer.common import numpy_distributions as nd

logger = logging.getLogger(__name__)


# rows x critic parameters of an update below which forking costs more than it saves: the fork
# of a ~250 MB trainer takes ~8 ms. Measured on 2 vCPUs: basic (24 minibatches x 32 rows, 461
# critic parameters) 12 -> 20 ms per update; ball3d (562 x 64 rows, 17.7k) 0.33 -> 0.18 s (see above).
FORK_MIN_WORK = 50e6
FORK_TIMEOUT_MIN = 30.0  # seconds a child may take at least ...
FORK_TIMEOUT_FACTOR = 5.0  # ... or this many times the parent's half of the same update


def fork_pays_off(work: float) -> bool:
    """Run the critic's half in a child process? Only on Linux (fork is not safe with the
    system BLAS of macOS, and absent on Windows), with a second CPU for it, no other Python
    thread that could hold a lock across the fork, and enough ``work`` (rows x parameters)."""
    return (sys.platform.startswith("linux") and hasattr(os, "fork") and usable_cpus() >= 2
            and threading.active_count() == 1 and work >= FORK_MIN_WORK)


def supports(trainer) -> bool:
    return (trainer.device.type == "cpu" and isinstance(trainer.optimizer, Adam)
            and numpy_net.supports(trainer.policy.actor) and numpy_net.supports(trainer.critic))


class NumpyPPO:
    """Minibatch steps for one PPOTrainer (one instance for its lifetime): ``prepare`` once
    per update, then ``run``.

    The actor and the critic are separate networks here (a shared body keeps the torch path,
    see ``supports``), so their halves of a minibatch step never touch each other's arrays:
    the policy and entropy terms reach only the actor's parameters, the value term only the
    critic's, and Adam is elementwise. ``run`` therefore steps the actor through every
    minibatch and then the critic (the same arithmetic as alternating them), and when it pays
    off, the critic's half runs at the same time in a forked child process (``_CriticChild``).
    Weights, moments and statistics are bit-for-bit those of the sequential steps.
    """

    ACTOR_KEYS = ("continuous_actions", "discrete_actions", "allowed", "advantages", "log_probs")

    def __init__(self, actor: numpy_net.NumpyActor, critic: numpy_net.NumpyCritic, optimizer: Adam) -> None:
        self.actor, self.critic, self.optimizer = actor, critic, optimizer
        # the optimizer holds the actor's parameters, then the critic's (PPOTrainer builds it so)
        self.actor_part: Stretch = optimizer.stretch(p for p in actor.module.parameters() if p.requires_grad)
        self.critic_part: Stretch = optimizer.stretch(p for p in critic.module.parameters() if p.requires_grad)
        self.fork_failed = False  # a child failed once: this trainer steps its critic itself

    def prepare(self, obs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Normalised inputs of the whole buffer for the actor and the critic (their statistics
        do not change during an update)."""
        return self.actor.body.input(obs), self.critic.body.input(obs)

    # ------------------------------------------------------------------ a whole update
    def run(self, data: dict[str, np.ndarray], actor_in: np.ndarray, critic_in: np.ndarray,
            orders: list[np.ndarray], learning_rate: float, beta: float, epsilon: float,
            parallel: bool | None = None) -> list[dict[str, float]]:
        """One step per minibatch (row indices ``orders``) at ``learning_rate``; ``parallel``:
        the critic's half in a forked child process; None: when ``fork_pays_off``. Returns each
        minibatch's statistics."""
        if self.optimizer.reduce is not None:  # data-parallel ranks
            return self._run_together(data, actor_in, critic_in, orders, learning_rate, beta, epsilon)
        if parallel is None:
            parallel = not self.fork_failed and fork_pays_off(sum(map(len, orders)) * self.critic_part.exp_avg.size)
        self.optimizer.param_groups[0]["lr"] = learning_rate
        first_t = self.optimizer.step_count + 1
        actor_keys = [k for k in self.ACTOR_KEYS if k in data]
        critic_keys = [f"returns:{name}" for name in self.critic.heads]

        def actor_half(k: int, index: np.ndarray) -> tuple[float, float]:
            batch = {key: data[key][index] for key in actor_keys}
            return self.actor_step(batch, actor_in[index], beta, epsilon, first_t + k)

        def critic_half(k: int, index: np.ndarray) -> float:
            batch = {key: data[key][index] for key in critic_keys}
            return self.critic_step(batch, critic_in[index], first_t + k)

        # the halves are independent: all actor steps, then all critic steps, give the same
        # arithmetic as alternating them; ``parallel`` runs the critic's in a child process
        started = time.monotonic()
        child = _CriticChild.start(self.critic_part, critic_half, orders) if parallel else None
        try:
            actor = [actor_half(k, index) for k, index in enumerate(orders)]
        except BaseException:
            if child is not None:
                child.abandon()
            raise
        values = None
        if child is not None:
            values, failure = child.collect(max(FORK_TIMEOUT_MIN, FORK_TIMEOUT_FACTOR * (time.monotonic() - started)))
            if failure is not None:
                self.fork_failed = True
                logger.warning("The critic's update in a child process failed (%s); the trainer steps "
                               "the critic itself from now on.", failure)
        if values is None:  # sequential, or the child failed (the critic here is untouched)
            values = [critic_half(k, index) for k, index in enumerate(orders)]
        self.optimizer.step_count = first_t - 1 + len(orders)
        return [_stats(policy_term, value_term, entropy)
                for (policy_term, entropy), value_term in zip(actor, values)]

    def _run_together(self, data: dict[str, np.ndarray], actor_in: np.ndarray, critic_in: np.ndarray,
                      orders: list[np.ndarray], learning_rate: float, beta: float, epsilon: float
                      ) -> list[dict[str, float]]:
        """``run`` for data-parallel ranks (trainer/distributed.py): each minibatch's actor and
        critic gradients go into ONE buffer, averaged across the ranks by the optimizer's
        ``reduce`` (one all-reduce per minibatch, not two), then one Adam step of both networks:
        the same arithmetic as ``run``'s separate halves (Adam is elementwise). No child process:
        it could not take part in the ranks' collectives."""
        self.optimizer.param_groups[0]["lr"] = learning_rate
        first_t = self.optimizer.step_count + 1
        both = self.optimizer.stretch([*self.actor_part.params, *self.critic_part.params])
        actor_keys = [k for k in self.ACTOR_KEYS if k in data]
        critic_keys = [f"returns:{name}" for name in self.critic.heads]
        results = []
        for k, index in enumerate(orders):
            grads, policy_term, entropy = self.actor_gradients(
                {key: data[key][index] for key in actor_keys}, actor_in[index], beta, epsilon)
            critic_grads, value_term = self.critic_gradients(
                {key: data[key][index] for key in critic_keys}, critic_in[index])
            grads.update(critic_grads)
            both.step([grads[id(p)] for p in both.params], first_t + k)
            results.append(_stats(policy_term, value_term, entropy))
        self.optimizer.step_count = first_t - 1 + len(orders)
        return results

    # ------------------------------------------------------------------ one minibatch
    def actor_step(self, batch: dict[str, np.ndarray], actor_in: np.ndarray, beta: float, epsilon: float,
                   t: int) -> tuple[float, float]:
        """The actor's Adam step number ``t`` on one minibatch. Returns (policy term, mean entropy)."""
        grads, policy_term, entropy = self.actor_gradients(batch, actor_in, beta, epsilon)
        self.actor_part.step([grads[id(p)] for p in self.actor_part.params], t)
        return policy_term, entropy

    def actor_gradients(self, batch: dict[str, np.ndarray], actor_in: np.ndarray, beta: float, epsilon: float
                        ) -> tuple[dict[int, np.ndarray], float, float]:
        """The policy and entropy terms' gradients for every actor parameter (keyed by id of the
        torch parameter), the policy term and the mean entropy."""
        grads: dict[int, np.ndarray] = {}
        n = len(actor_in)
        body, actor = self.actor.body, self.actor.module
        actor_cache: list = []
        h = body.forward(actor_in, actor_cache)
        logp_parts, ent = [], np.zeros(n, dtype=np.float32)
        back = []  # per output column group: what the backward pass needs
        if self.actor.mu is not None:
            w_mu, b_mu = self.actor.mu  # W^T, b
            mu = h @ w_mu + b_mu
            log_sigma = self.actor.log_sigma  # [1, c]
            terms = nd.gaussian_terms(log_sigma)  # once for the log-probs and both gradients
            actions = batch["continuous_actions"]
            logp_parts.append(nd.gaussian_log_prob(actions, mu, log_sigma, terms=terms))
            ent = ent + np.mean(nd.gaussian_entropy(log_sigma))
            back.append(("gaussian", actions, mu, log_sigma, terms))
        allowed = batch.get("allowed")
        offsets = self.actor.offsets
        for index, (weight, bias) in enumerate(self.actor.branches):
            logits = h @ weight + bias
            start, end = offsets[index], offsets[index + 1]
            a = allowed[:, start:end] if allowed is not None else None
            if a is not None:
                logits = nd.mask_logits(logits, a)
            probs = nd.softmax(logits)
            action = batch["discrete_actions"][:, index]
            logp_parts.append(nd.categorical_log_prob(probs, action)[:, None])
            option_log_probs = nd.categorical_option_log_probs(probs)  # for the entropy and its gradient
            ent = ent + nd.categorical_entropy(probs, option_log_probs)
            back.append(("categorical", index, probs, action, a, option_log_probs))
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
                _, actions, mu, log_sigma, terms = item
                c = actions.shape[1]
                g = grad_logp[:, column:column + c]
                column += c
                grad_mu, grad_ls = nd.gaussian_log_prob_grads(actions, mu, log_sigma, g, terms)
                grad_ls = np.sum(grad_ls, axis=0, keepdims=True)  # one log_sigma for all rows
                grad_ls += -beta / c * nd.gaussian_entropy_grad(log_sigma, terms)
                w_mu, _ = self.actor.mu
                grads[id(actor.mu.weight)] = (h.T @ grad_mu).T  # W^T contiguous, as stored
                grads[id(actor.mu.bias)] = grad_mu.sum(axis=0)
                grads[id(actor.log_sigma)] = grad_ls
                grad_h += grad_mu @ w_mu.T
            else:
                _, index, probs, action, a, option_log_probs = item
                g = grad_logp[:, column]
                column += 1
                grad_logits = nd.categorical_log_prob_grad(probs, action, g)
                grad_logits += (-beta / n) * nd.categorical_entropy_grad(probs, option_log_probs)
                if a is not None:
                    grad_logits = grad_logits * a
                weight, _ = self.actor.branches[index]
                branch = actor.discrete_branches[index]
                grads[id(branch.weight)] = (h.T @ grad_logits).T
                grads[id(branch.bias)] = grad_logits.sum(axis=0)
                grad_h += grad_logits @ weight.T
        body.backward(grad_h, actor_cache, grads)
        return grads, float(policy_term), float(np.mean(ent))

    def critic_step(self, batch: dict[str, np.ndarray], critic_in: np.ndarray, t: int) -> float:
        """The critic's Adam step number ``t`` on one minibatch. Returns the value term."""
        grads, value_term = self.critic_gradients(batch, critic_in)
        self.critic_part.step([grads[id(p)] for p in self.critic_part.params], t)
        return value_term

    def critic_gradients(self, batch: dict[str, np.ndarray], critic_in: np.ndarray
                         ) -> tuple[dict[int, np.ndarray], float]:
        """0.5 x the value term's gradients for every critic parameter (keyed by id of the torch
        parameter), and the value term."""
        grads: dict[int, np.ndarray] = {}
        n = len(critic_in)
        body, heads = self.critic.body, self.critic.heads
        cache: list = []
        hc = body.forward(critic_in, cache)
        values = {name: (hc @ w + b)[:, 0] for name, (w, b) in heads.items()}
        errors = {name: values[name] - batch[f"returns:{name}"] for name in values}
        value_term = np.mean([np.mean(e ** 2) for e in errors.values()])
        # ---- value term -> critic
        grad_hc = np.zeros_like(hc)
        scale = 0.5 * 2.0 / (n * len(errors))
        for name, error in errors.items():
            w, _ = heads[name]
            g = (scale * error)[:, None].astype(np.float32)
            head = self.critic.module.value_heads[name]
            grads[id(head.weight)] = (hc.T @ g).T
            grads[id(head.bias)] = g.sum(axis=0)
            grad_hc += g @ w.T
        body.backward(grad_hc, cache, grads)
        return grads, float(value_term)


def _stats(policy_term: float, value_term: float, entropy: float) -> dict[str, float]:
    return {"Losses/Policy Loss": abs(policy_term), "Losses/Value Loss": value_term, "Policy/Entropy": entropy}


class _CriticChild:
    """The critic's half of an update in a forked child process, its result copied back.

    The child shares the parent's memory copy-on-write: the buffer, the critic's weights and
    Adam moments as they were at the fork. It runs every critic step, writes the critic's
    parameters, its stretch of the moments and the value terms into an anonymous shared
    mapping and exits (``os._exit``: no cleanup, no atexit, nothing flushed), which closes its
    end of a pipe: the parent waits for that end-of-file with a timeout. The parent's critic is
    untouched until ``collect`` copies the result in, so a child that fails, hangs or is killed
    costs only time: ``collect`` reports the failure and the parent steps the critic itself.
    """

    def __init__(self, pid: int, shared: mmap.mmap, arrays: list[np.ndarray], count: int, done: int) -> None:
        self.pid, self.shared, self.arrays, self.count, self.done = pid, shared, arrays, count, done

    @classmethod
    def start(cls, part: Stretch, critic_half, orders: list) -> "_CriticChild | None":
        arrays = [*part.arrays, part.exp_avg, part.exp_avg_sq]
        shared = mmap.mmap(-1, sum(a.nbytes for a in arrays) + 8 * len(orders))
        done, child_end = os.pipe()
        try:
            pid = os.fork()
        except OSError:
            for fd in (done, child_end):
                os.close(fd)
            shared.close()
            return None
        if pid == 0:  # the child: never returns
            code = 1
            try:
                os.close(done)
                signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
                values = np.array([critic_half(k, index) for k, index in enumerate(orders)], dtype=np.float64)
                out, offset = memoryview(shared), 0
                for array in [*arrays, values]:
                    out[offset:offset + array.nbytes] = np.ascontiguousarray(array).reshape(-1).view(np.uint8)
                    offset += array.nbytes
                out.release()
                code = 0
            finally:
                os._exit(code)  # closes child_end: the parent's ``done`` reads end-of-file
        os.close(child_end)
        return cls(pid, shared, arrays, len(orders), done)

    def collect(self, timeout: float) -> tuple[list[float] | None, str | None]:
        """Wait up to ``timeout`` seconds for the child; copy its critic in and return (its
        value terms, None), or (None, what went wrong) after killing and reaping it."""
        try:
            finished, _, _ = select.select([self.done], [], [], timeout)
            if not finished:
                self._kill()
                return None, f"no result after {timeout:.1f} s"
            try:
                _, status = os.waitpid(self.pid, 0)
            except OSError as error:  # e.g. reaped by someone else: its result cannot be trusted
                return None, f"wait failed: {error}"
            if status != 0:
                return None, f"wait status {status}"
            offset = 0
            for array in self.arrays:
                np.copyto(array, np.frombuffer(self.shared, dtype=array.dtype, count=array.size,
                                               offset=offset).reshape(array.shape))
                offset += array.nbytes
            return np.frombuffer(self.shared, dtype=np.float64, count=self.count, offset=offset).tolist(), None
        finally:
            self._close()

    def abandon(self) -> None:
        """The parent gave up on this update: stop the child and reap it."""
        self._kill()
        self._close()

    def _kill(self) -> None:
        try:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        except OSError:
            pass

    def _close(self) -> None:
        if self.done >= 0:
            os.close(self.done)
            self.done = -1
        self.shared.close()
