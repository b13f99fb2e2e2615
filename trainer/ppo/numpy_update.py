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

import math

import numpy as np
import torch
from torch import nn

from trainer.ppo import fast_actor
from trainer.ppo.adam import Adam
from trainer.ppo.distributions import EPSILON, MASKED_LOGIT_OFFSET

_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))
_TWO_PI_E = 2 * math.pi * math.e


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
    """Minibatch steps for one PPOTrainer; ``prepare`` once per update, ``step`` per minibatch,
    ``finish`` at the end (bumps the torch version counters)."""

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
        self.param_arrays = [p.detach().numpy() for p in optimizer.params]
        # Adam's moments as two flat vectors for the update (written back by ``finish``)
        sizes = [a.size for a in self.param_arrays]
        self.bounds = list(zip(np.cumsum([0] + sizes[:-1]).tolist(), np.cumsum(sizes).tolist()))
        self.exp_avg = np.concatenate([t.numpy().reshape(-1) for t in optimizer.exp_avg]).astype(np.float32)
        self.exp_avg_sq = np.concatenate([t.numpy().reshape(-1) for t in optimizer.exp_avg_sq]).astype(np.float32)
        self.flat_grad = np.empty_like(self.exp_avg)
        self._scratch = np.empty_like(self.exp_avg)  # Adam's one temporary

    def prepare(self, obs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Normalised inputs of the whole buffer for the actor and the critic (their statistics
        do not change during an update)."""
        return _normalized(self.actor.network_body, obs), _normalized(self.critic.network_body, obs)

    # ------------------------------------------------------------------ one minibatch
    def step(self, batch: dict[str, np.ndarray], actor_in: np.ndarray, critic_in: np.ndarray,
             learning_rate: float, beta: float, epsilon: float) -> dict[str, float]:
        grads: dict[int, np.ndarray] = {}
        n = len(actor_in)
        # ---- actor forward
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
        # ---- critic forward
        hc, critic_cache = self.critic_body.forward(critic_in)
        values = {name: (hc @ w.T + b)[:, 0] for name, (w, b) in self.heads.items()}
        # ---- loss
        advantages = batch["advantages"][:, None]
        ratio = np.exp(log_probs - batch["log_probs"])
        unclipped = ratio * advantages
        clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
        policy_term = -np.mean(np.minimum(unclipped, clipped))
        errors = {name: values[name] - batch[f"returns:{name}"] for name in values}
        value_term = np.mean([np.mean(e ** 2) for e in errors.values()])
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
        self._adam(grads, learning_rate)
        loss_entropy = float(np.mean(ent))
        return {"Losses/Policy Loss": abs(float(policy_term)), "Losses/Value Loss": float(value_term),
                "Policy/Entropy": loss_entropy}

    def _adam(self, grads: dict[int, np.ndarray], learning_rate: float) -> None:
        """Adam.step's arithmetic, on all parameters as one flat vector."""
        optimizer = self.optimizer
        group = optimizer.param_groups[0]
        (beta1, beta2), eps = group["betas"], group["eps"]
        optimizer.step_count += 1
        t = optimizer.step_count
        g = self.flat_grad
        for param, (start, end) in zip(optimizer.params, self.bounds):
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
        for array, (start, end) in zip(self.param_arrays, self.bounds):
            array -= update[start:end].reshape(array.shape)

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
