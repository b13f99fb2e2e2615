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
through a (via Q1's input, d/du = dL/da (1 - a^2)), log pi_c and pi, the entropy loss the log
alphas. Then three Adam steps (the trainer's optimisers) and the soft update of the target.
"""
from __future__ import annotations

import numpy as np
import torch

from trainer.common import numpy_distributions as nd
from trainer.common import numpy_net
from trainer.common.distributions import EPSILON
from trainer.common.numpy_net import LOG_SIGMA_MAX, LOG_SIGMA_MIN
from trainer.sac import losses
from trainer.common.numpy_policy import squashed_entropy as _entropy, squashed_log_prob as _numpy_squashed_log_prob


def supports(trainer) -> bool:
    """Vector observations, no memory, every network and optimiser on the CPU."""
    if trainer.device.type != "cpu" or trainer.hyperparams.memory_size or trainer.policy.numpy_actor is None:
        return False
    networks = (trainer.policy.actor, trainer.critic, trainer.target_network,
                trainer.q_network.q1_network, trainer.q_network.q2_network)
    optimizers = (trainer.policy_optimizer, trainer.value_optimizer, trainer.entropy_optimizer)
    return all(numpy_net.supports(m) for m in networks) and all(o.on_cpu for o in optimizers)


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
        mu, logits = self.actor.heads_of(h, masks)
        sum_log_pi = None
        if c:
            w_ls, b_ls = self.actor.log_sigma_head
            ls_raw = h @ w_ls + b_ls
            log_sigma = np.minimum(np.maximum(ls_raw, LOG_SIGMA_MIN), LOG_SIGMA_MAX)
            noise = torch.randn(mu.shape, generator=trainer.noise_generator).numpy()
            sigma = np.exp(log_sigma)
            raw = mu + noise * sigma
            action = np.tanh(raw)
            sum_log_pi = _numpy_squashed_log_prob(raw, mu, log_sigma).sum(axis=1)
            alpha_c = np.exp(self.log_alpha_c)  # [1]
        if branches:
            parts = [nd.softmax(branch) for branch in logits]
            probs = np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]
            log_probs = np.log(probs + EPSILON)
            alpha_d = np.exp(self.log_alpha_d)  # [B]
            alpha_rep = np.repeat(alpha_d, branches)  # [K]
            neg_entropy = np.add.reduceat(probs * log_probs, self.starts, axis=1)  # [n, B]

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
        if branches:
            chosen = self.starts + batch["discrete_actions"]  # [n, B] columns of the options taken
            row_index = np.arange(n)[:, None]
        entropy_term = None
        if branches:
            entropy_term = np.add.reduce(alpha_d * neg_entropy, axis=1) / len(branches)
        if c:
            continuous_term = alpha_c * sum_log_pi
            entropy_term = continuous_term if entropy_term is None else entropy_term + continuous_term
        q_losses, value_losses = ([], []), []
        g_q1 = {name: np.zeros_like(out) for name, out in q1_out.items()}
        g_q2 = {}
        g_v = {}
        done = batch["done"]
        for name in self.names:
            gamma, _ = trainer.hyperparams.reward_signals[name]
            provider = trainer.providers.get(name)
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
        mean_q1 = sum(q1_out[name][policy_rows] for name in self.names) / N  # [n, K or 1]
        per_row = np.zeros(n, dtype=np.float32)
        if branches:
            per_row = per_row + (alpha_rep * probs * log_probs - probs * mean_q1).sum(axis=1)
            expected_q = (probs * mean_q1).sum(axis=1)
        else:
            expected_q = mean_q1[:, 0]
        if c:
            per_row = per_row + alpha_c * sum_log_pi - expected_q
        stats = {
            "Losses/Policy Loss": float(np.add.reduce(per_row)) / n,
            "Losses/Value Loss": sum(value_losses) / N,
            "Losses/Q1 Loss": sum(q_losses[0]) / N,
            "Losses/Q2 Loss": sum(q_losses[1]) / N,
            "Policy/Entropy": float(_entropy(n, log_sigma if c else None, [probs] if branches else []).mean()),
        }

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
        grad_h = np.zeros_like(h)
        if c:
            k = alpha_c / n  # d loss / d log pi_c
            diff = raw - mu
            denom = 2.0 * sigma ** 2 + EPSILON
            gauss = 2.0 * diff / denom  # d log N / d mu = -d log N / d u
            grad_raw = grad_q_in[n:, -c:] * (1.0 - action ** 2) + k * (2.0 * action - gauss)
            grad_mu = grad_raw + k * gauss
            grad_sigma = noise * grad_raw + k * (diff ** 2 * 4.0 * sigma / denom ** 2 - 1.0 / (sigma + EPSILON))
            grad_ls = sigma * grad_sigma * ((ls_raw >= LOG_SIGMA_MIN) & (ls_raw <= LOG_SIGMA_MAX))
            for (weight_id, bias_id), (weight, _), g in ((self.mu_ids, self.actor.mu, grad_mu),
                                                         (self.log_sigma_ids, self.actor.log_sigma_head, grad_ls)):
                grads[weight_id] = (h.T @ g).T
                grads[bias_id] = np.add.reduce(g, axis=0)
                grad_h += g @ weight.T
        if branches:
            q_weight = 2.0 if c else 1.0  # the hybrid loss subtracts sum pi Q1 twice (losses.policy_loss)
            grad_probs = (alpha_rep * (log_probs + probs / (probs + EPSILON)) - q_weight * mean_q1) / n
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
        body.backward(grad_h, actor_cache, grads)

        # ---- the log alphas: -mean log alpha * gap
        if c:
            grads[self.alpha_ids[0]] = np.add.reduce(sum_log_pi + self.target_c, keepdims=True) / -n
        if branches:
            grads[self.alpha_ids[1]] = np.add.reduce(neg_entropy + self.target_d, axis=0) / (-n * len(branches))
        return grads, stats

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
