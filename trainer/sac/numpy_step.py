"""SAC gradient steps in numpy with hand-written gradients, for vector observations without memory.

Why: SAC takes one gradient step per ``steps_per_update`` agent steps on five small networks
(policy, V, target V, Q1, Q2). In torch that step is about a thousand Python-level calls and
was the largest part of our trainer's time against the real mlagents-learn; the same arithmetic
in numpy is well under half as many calls and several times faster (bench/sac_step.py measures
it; the numbers: docs/sac.md, "Speed", and bench/RESULTS.md). As PPO's numpy_update.py: the networks are those of
networks.py read through numpy_net.py (numpy views of the torch parameters, no copies); Adam
(adam.py) steps them in place, so torch, acting, checkpoints and ONNX export see every change.
tests/unit/test_sac_numpy_step.py checks the gradients against autograd on the same modules and
losses and weights after several steps against the torch path, for continuous, discrete (with
masks) and hybrid actions. The torch path (``SACTrainer._torch_gradient_step``) remains for
what this does not cover: memory (LSTMs), visual observations, a GPU.

Math (what ``SACTrainer._torch_gradient_step`` computes; n rows, N reward signals, B branches,
K options in all, c continuous dimensions; every network normalises with the policy's statistics,
which ``SACTrainer.update`` copies into all of them first):
    policy:  h = body(x); mu = h W_mu + b; l = clip(h W_ls + b, -20, 2); s = exp(l);
             u = mu + eps s (eps from the trainer's noise generator); a = tanh(u);
             log pi_c = -(u - mu)^2 / (2 s^2 + 1e-7) - log(s + 1e-7) - log sqrt(2 pi) - 2 (log 2 - u - softplus(-2u));
             pi = softmax(masked logits) per branch, log(pi + 1e-7)
    Q_j(x, a_taken) and Q_j(x, a) for j = 1, 2 (one forward pass of 2n rows), V(x), V_target(x')
    Q loss   = 0.5 mean (r + gamma (1 - done) V_target(x') - Q_j(taken))^2   (per signal, averaged)
    V loss   = 0.5 mean (V(x) - [min(Q1, Q2)(x, a) - alpha_c sum log pi_c  (or the discrete form)])^2
    policy   = mean [alpha_c sum log pi_c - Q1(x, a)] (+ the discrete terms), Q1 held constant
    entropy  = -mean log alpha (log pi + target)
Gradients by hand: the Q and V losses reach their own networks, the policy loss reaches the policy
through a (via Q1's input) and log pi_c (both back through the sample:
numpy_distributions.squashed_sample_grads) and pi, the entropy loss the log alphas. Then three Adam steps (the trainer's optimisers) and the soft update of the target.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from trainer.common import numpy_distributions as nd
from trainer.common import numpy_net
from trainer.common.distributions import EPSILON
from trainer.common.numpy_net import LOG_SIGMA_MAX, LOG_SIGMA_MIN
from trainer.sac import losses
from trainer.sac.policy import policy_entropy


def supports(trainer) -> bool:
    """Vector observations, no memory, every network and optimiser on the CPU."""
    if trainer.device.type != "cpu" or trainer.hyperparams.memory_size or trainer.policy.numpy_actor is None:
        return False
    networks = (trainer.policy.actor, trainer.critic, trainer.target_network,
                trainer.q_network.q1_network, trainer.q_network.q2_network)
    optimizers = (trainer.policy_optimizer, trainer.value_optimizer, trainer.entropy_optimizer)
    return all(numpy_net.supports(m) for m in networks) and all(o.on_cpu for o in optimizers)


@dataclass
class _Sample:
    """The policy's fresh sample in one gradient step: the continuous block's (None without it) and
    the discrete branches' (None without them), with the entropy coefficients they are weighed by."""

    mu: np.ndarray | None
    ls_raw: np.ndarray | None = None  # log sigma before the clamp [n, c]
    log_sigma: np.ndarray | None = None
    noise: np.ndarray | None = None
    raw: np.ndarray | None = None  # mu + noise sigma
    action: np.ndarray | None = None  # tanh(raw)
    sum_log_pi: np.ndarray | None = None  # [n]
    alpha_c: np.ndarray | None = None  # [1]
    probs: np.ndarray | None = None  # [n, K], every branch side by side
    log_probs: np.ndarray | None = None  # log(probs + EPSILON)
    alpha_d: np.ndarray | None = None  # [B]
    alpha_rep: np.ndarray | None = None  # [K]: each branch's alpha over its options
    neg_entropy: np.ndarray | None = None  # [n, B]


def _head_outputs(h: np.ndarray, heads: dict) -> dict[str, np.ndarray]:
    """Each signal's head: [rows, outputs]."""
    return {name: h @ weight + bias for name, (weight, bias) in heads.items()}


class NumpySAC:
    """The gradient steps of one SACTrainer (built once; ``step`` per minibatch)."""

    def __init__(self, trainer) -> None:
        self.trainer = trainer
        self.actor = trainer.policy.numpy_actor
        self.critic = numpy_net.NumpyCritic(trainer.critic)
        self.target = numpy_net.NumpyCritic(trainer.target_network)
        self.q1 = numpy_net.NumpyCritic(trainer.q_network.q1_network)
        self.q2 = numpy_net.NumpyCritic(trainer.q_network.q2_network)
        spec = trainer.behavior_spec.action_spec
        self.continuous = spec.continuous_size
        self.branches = list(trainer.branches)
        self.starts = np.asarray(self.actor.offsets[:-1], dtype=np.intp)  # each branch's first column
        self.names = list(trainer.hyperparams.reward_signals)
        self.optimizers = (trainer.policy_optimizer, trainer.value_optimizer, trainer.entropy_optimizer)
        self.stretches = [o.stretch(o.params) for o in self.optimizers]
        coefficients = trainer.log_ent_coef
        self.log_alpha_c = numpy_net.view(coefficients.continuous) if coefficients.continuous is not None else None
        self.log_alpha_d = numpy_net.view(coefficients.discrete) if coefficients.discrete is not None else None
        # ids of the torch parameters the gradients are keyed by (nn.Module attribute reads are slow)
        self.head_ids = {id(network): {name: (id(head.weight), id(head.bias))
                                       for name, head in network.module.value_heads.items()}
                         for network in (self.critic, self.q1, self.q2)}
        actor = trainer.policy.actor
        self.mu_ids = self.log_sigma_ids = None
        if self.continuous:
            self.mu_ids = (id(actor.mu.weight), id(actor.mu.bias))
            self.log_sigma_ids = (id(actor.log_sigma_head.weight), id(actor.log_sigma_head.bias))
        self.branch_ids = [(id(b.weight), id(b.bias)) for b in actor.discrete_branches]
        self.alpha_ids = tuple(None if p is None else id(p) for p in (coefficients.continuous, coefficients.discrete))
        target_c, target_d = trainer.target_entropy
        self.target_c = np.float32(target_c)
        self.target_d = np.asarray(target_d, dtype=np.float32)

    # ------------------------------------------------------------------ forward
    def step(self, batch: dict[str, np.ndarray], rewards: dict[str, np.ndarray]) -> dict[str, float]:
        """One SAC step on a sampled minibatch (replay-buffer columns) with each signal's
        rewards x strength [n]; the optimisers step and the target moves. Returns the statistics."""
        grads, stats = self.gradients(batch, rewards)
        for optimizer, stretch in zip(self.optimizers, self.stretches):
            optimizer.step_count += 1
            stretch.step([grads[id(p)] for p in stretch.params], optimizer.step_count)
        t = self.trainer
        losses.soft_update(t._critic_params, t._target_params, t.hyperparams.tau)
        if self.continuous:
            stats["Policy/Continuous Entropy Coeff"] = float(np.exp(self.log_alpha_c).mean())
        if self.branches:
            stats["Policy/Discrete Entropy Coeff"] = float(np.exp(self.log_alpha_d).mean())
        return stats

    def gradients(self, batch: dict[str, np.ndarray], rewards: dict[str, np.ndarray]
                  ) -> tuple[dict[int, np.ndarray], dict[str, float]]:
        """Every trained parameter's gradient of the summed losses (keyed by id of the torch
        parameter) and the loss statistics; nothing is stepped."""
        trainer, c, branches = self.trainer, self.continuous, self.branches
        n_obs = len(trainer.behavior_spec.observation_specs)
        body = self.actor.body
        x = body.input([batch[f"obs_{i}"] for i in range(n_obs)])
        x_next = body.input([batch[f"next_obs_{i}"] for i in range(n_obs)])
        n, N = len(x), len(self.names)
        grads: dict[int, np.ndarray] = {}

        # ---- the policy's fresh sample
        actor_cache: list = []
        h = body.forward(x, actor_cache)
        masks = batch["action_masks"] if branches else None
        sample = self._sample(h, masks)
        action, sum_log_pi, alpha_c = sample.action, sample.sum_log_pi, sample.alpha_c
        probs, alpha_d, neg_entropy = sample.probs, sample.alpha_d, sample.neg_entropy

        # ---- Q1, Q2 of the stored actions (rows :n) and of the sample (rows n:), V, target V
        if c:
            q_in = np.concatenate([np.concatenate([x, batch["continuous_actions"]], axis=1),
                                   np.concatenate([x, action], axis=1)], axis=0)
        else:  # no continuous actions: the Qs of the sample are those of the stored rows
            q_in = x
        q1_cache: list = []
        q2_cache: list = []
        hq1 = self.q1.body.forward(q_in, q1_cache)
        hq2 = self.q2.body.forward(q_in, q2_cache)
        q1_out, q2_out = _head_outputs(hq1, self.q1.heads), _head_outputs(hq2, self.q2.heads)
        policy_rows = slice(n, 2 * n) if c else slice(0, n)
        v_cache: list = []
        hv = self.critic.body.forward(x, v_cache)
        values = {name: v[:, 0] for name, v in _head_outputs(hv, self.critic.heads).items()}
        next_values = {name: v[:, 0] for name, v in _head_outputs(self.target.body.forward(x_next),
                                                                  self.target.heads).items()}

        # ---- losses and the gradients of their outputs
        entropy_term = None
        if branches:
            entropy_term = np.add.reduce(alpha_d * neg_entropy, axis=1) / len(branches)
        if c:
            continuous_term = alpha_c * sum_log_pi
            entropy_term = continuous_term if entropy_term is None else entropy_term + continuous_term
        q_losses, value_losses, g_q1, g_q2, g_v = self._value_losses(
            batch, rewards, q1_out, q2_out, values, next_values, entropy_term, probs, policy_rows)
        mean_q1 = sum(q1_out[name][policy_rows] for name in self.names) / N  # [n, K or 1]
        stats = self._stats(sample, mean_q1, q_losses, value_losses)

        # ---- the policy loss through Q1's continuous-action input (Q1's weights held constant)
        if c:
            g_mean_q1 = (-2.0 / n) * probs if branches else np.full((n, 1), -1.0 / n, dtype=np.float32)
            for name in self.names:
                g_q1[name][n:] = g_mean_q1 / N
        # ---- value networks: heads, then bodies
        grad_hv = self._heads_backward(self.critic, hv, g_v, grads)
        self.critic.body.backward(grad_hv, v_cache, grads)
        grad_hq1 = self._heads_backward(self.q1, hq1, g_q1, grads, param_rows=n)
        grad_q_in = self.q1.body.backward(grad_hq1, q1_cache, grads, param_rows=n, input_grad=bool(c))
        grad_hq2 = self._heads_backward(self.q2, hq2[:n], g_q2, grads)
        self.q2.body.backward(grad_hq2, q2_cache, grads)

        # ---- the policy
        grad_h = self._policy_heads_backward(sample, h, grad_q_in[n:, -c:] if c else None, mean_q1, masks, grads)
        body.backward(grad_h, actor_cache, grads)

        # ---- the log alphas: -mean log alpha * gap
        if c:
            grads[self.alpha_ids[0]] = np.add.reduce(sum_log_pi + self.target_c, keepdims=True) / -n
        if branches:
            grads[self.alpha_ids[1]] = np.add.reduce(neg_entropy + self.target_d, axis=0) / (-n * len(branches))
        return grads, stats

    def _sample(self, h: np.ndarray, masks: np.ndarray | None) -> _Sample:
        """The policy's fresh sample from the body's output h [n, hidden] (noise from the trainer's
        generator) and what the losses read of it."""
        mu, logits = self.actor.heads_of(h, masks)
        sample = _Sample(mu=mu)
        if self.continuous:
            w_ls, b_ls = self.actor.log_sigma_head
            sample.ls_raw = h @ w_ls + b_ls
            sample.log_sigma = np.minimum(np.maximum(sample.ls_raw, LOG_SIGMA_MIN), LOG_SIGMA_MAX)
            sample.noise = torch.randn(mu.shape, generator=self.trainer.noise_generator).numpy()
            sample.raw, sample.action = nd.squashed_sample(mu, sample.log_sigma, sample.noise)
            sample.sum_log_pi = nd.squashed_log_prob(sample.raw, mu, sample.log_sigma).sum(axis=1)
            sample.alpha_c = np.exp(self.log_alpha_c)  # [1]
        if self.branches:
            parts = [nd.softmax(branch) for branch in logits]
            sample.probs = probs = np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]
            sample.log_probs = nd.categorical_option_log_probs(probs)
            sample.alpha_d = np.exp(self.log_alpha_d)  # [B]
            sample.alpha_rep = np.repeat(sample.alpha_d, self.branches)  # [K]
            sample.neg_entropy = np.add.reduceat(probs * sample.log_probs, self.starts, axis=1)  # [n, B]
        return sample

    def _stats(self, sample: _Sample, mean_q1: np.ndarray, q_losses: tuple[list, list], value_losses: list
               ) -> dict[str, float]:
        """The losses' statistics; the policy loss's value is computed here only (its gradient is
        taken by hand). ``mean_q1``: Q1 of the sample averaged over the signals [n, K or 1]."""
        n, N, probs = len(mean_q1), len(self.names), sample.probs
        per_row = np.zeros(n, dtype=np.float32)
        if self.branches:
            per_row = per_row + (sample.alpha_rep * probs * sample.log_probs - probs * mean_q1).sum(axis=1)
            expected_q = (probs * mean_q1).sum(axis=1)
        else:
            expected_q = mean_q1[:, 0]
        if self.continuous:
            per_row = per_row + sample.alpha_c * sample.sum_log_pi - expected_q
        return {
            "Losses/Policy Loss": float(np.add.reduce(per_row)) / n,
            "Losses/Value Loss": sum(value_losses) / N,
            "Losses/Q1 Loss": sum(q_losses[0]) / N,
            "Losses/Q2 Loss": sum(q_losses[1]) / N,
            "Policy/Entropy": float(policy_entropy(n, sample.log_sigma, [] if probs is None else [probs]).mean()),
        }

    def _value_losses(self, batch, rewards, q1_out, q2_out, values, next_values, entropy_term,
                      probs: np.ndarray | None, policy_rows: slice) -> tuple:
        """Per reward signal: the Q1, Q2 and V losses and the gradients of the networks' outputs
        (g_q1 for the stored rows only: the policy's rows are filled by the caller).
        Returns (Q losses (Q1's, Q2's), V losses, g_q1, g_q2, g_v), per-signal lists and dicts."""
        n, N, branches = len(batch["done"]), len(self.names), self.branches
        if branches:
            chosen = self.starts + batch["discrete_actions"]  # [n, B] columns of the options taken
            row_index = np.arange(n)[:, None]
        q_losses, value_losses = ([], []), []
        g_q1 = {name: np.zeros_like(out) for name, out in q1_out.items()}
        g_q2 = {}
        g_v = {}
        done = batch["done"]
        for name in self.names:
            gamma, _ = self.trainer.hyperparams.reward_signals[name]
            provider = self.trainer.providers.get(name)
            alive = 1.0 - done if provider is None or not provider.ignore_done else 1.0
            backup = rewards[name] + np.float32(gamma) * alive * next_values[name]
            g_q2[name] = np.zeros((n, q2_out[name].shape[1]), dtype=np.float32)
            for j, (out, g) in enumerate(((q1_out[name], g_q1[name]), (q2_out[name], g_q2[name]))):
                taken = out[:n]
                if branches:
                    error = np.add.reduce(taken[row_index, chosen], axis=1) / len(branches) - backup
                    g[row_index, chosen] = (error / (n * N * len(branches)))[:, None]
                else:
                    error = taken[:, 0] - backup
                    g[:n, 0] = error / (n * N)
                q_losses[j].append(0.5 * float(error @ error) / n)
            q1p, q2p = q1_out[name][policy_rows], q2_out[name][policy_rows]
            if branches:
                target = np.minimum(np.add.reduce(np.add.reduceat(q1p * probs, self.starts, axis=1), axis=1),
                                    np.add.reduce(np.add.reduceat(q2p * probs, self.starts, axis=1), axis=1)
                                    ) / len(branches)
            else:
                target = np.minimum(q1p[:, 0], q2p[:, 0])
            error = values[name] - (target - entropy_term)
            value_losses.append(0.5 * float(error @ error) / n)
            g_v[name] = (error / (n * N))[:, None]
        return q_losses, value_losses, g_q1, g_q2, g_v

    def _policy_heads_backward(self, sample: _Sample, h: np.ndarray, grad_action: np.ndarray | None,
                                  mean_q1: np.ndarray, masks: np.ndarray | None, grads: dict[int, np.ndarray]
                                  ) -> np.ndarray:
        """The policy loss back through the policy's heads: their gradients into ``grads``; returns
        d loss / d h. ``grad_action``: d loss / d the sampled continuous actions (through Q1's input)."""
        n, c = len(h), self.continuous
        grad_h = np.zeros_like(h)
        if c:
            # d loss / d a: through Q1's input; d loss / d log pi_c: alpha_c / n
            grad_mu, grad_ls = nd.squashed_sample_grads(sample.raw, sample.action, sample.mu, sample.log_sigma,
                                                        sample.noise, grad_action, sample.alpha_c / n)
            grad_ls = grad_ls * ((sample.ls_raw >= LOG_SIGMA_MIN) & (sample.ls_raw <= LOG_SIGMA_MAX))  # the clamp's
            for (weight_id, bias_id), (weight, _), g in ((self.mu_ids, self.actor.mu, grad_mu),
                                                         (self.log_sigma_ids, self.actor.log_sigma_head, grad_ls)):
                grads[weight_id] = (h.T @ g).T
                grads[bias_id] = np.add.reduce(g, axis=0)
                grad_h += g @ weight.T
        if self.branches:
            probs = sample.probs
            q_weight = 2.0 if c else 1.0  # the hybrid loss subtracts sum pi Q1 twice (losses.policy_loss)
            grad_probs = (sample.alpha_rep * (sample.log_probs + probs / (probs + EPSILON)) - q_weight * mean_q1) / n
            offsets = self.actor.offsets
            for index, (weight, _) in enumerate(self.actor.branches):
                start, end = offsets[index], offsets[index + 1]
                p, g = probs[:, start:end], grad_probs[:, start:end]
                grad_logits = p * (g - (p * g).sum(axis=1, keepdims=True))
                if masks is not None:
                    grad_logits = grad_logits * ~masks[:, start:end]
                weight_id, bias_id = self.branch_ids[index]
                grads[weight_id] = (h.T @ grad_logits).T
                grads[bias_id] = np.add.reduce(grad_logits, axis=0)
                grad_h += grad_logits @ weight.T
        return grad_h

    def _heads_backward(self, network: numpy_net.NumpyCritic, h: np.ndarray, g_out: dict[str, np.ndarray],
                        grads: dict[int, np.ndarray], param_rows: int | None = None) -> np.ndarray:
        """Each signal head's weight and bias gradients from d loss / d outputs [rows, outputs]
        (its first ``param_rows`` rows only, if given); returns d loss / d h."""
        grad_h = None
        ids = self.head_ids[id(network)]
        for name, g in g_out.items():
            weight, _ = network.heads[name]
            weight_id, bias_id = ids[name]
            rows_h, rows_g = (h, g) if param_rows is None else (h[:param_rows], g[:param_rows])
            grads[weight_id] = (rows_h.T @ rows_g).T
            grads[bias_id] = np.add.reduce(rows_g, axis=0)
            part = g @ weight.T
            grad_h = part if grad_h is None else grad_h + part
        return grad_h
