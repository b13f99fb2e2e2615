"""SAC's acting policy: a squashed Gaussian (tanh of a sample with a state-dependent sigma) for
continuous actions and the PPO policy's categorical sampling for discrete branches.

The environment receives tanh(sample) in (-1, 1) (no clipping), and the same squashed action is
what the replay buffer stores (``continuous_raw``): the Q networks take squashed actions.
Deterministic acting uses tanh(mu). As for PPO, vector-observation actors on the CPU decide in
numpy (numpy_net.py says why); both draw their noise in trainer/common/numpy_policy.py. With
network_settings.memory the actor's LSTM state travels with each agent as PPO's does (``act``
takes and returns memories; ``sample_with_grad`` reads rows as sequences).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from trainer.common.distributions import categorical_option_log_probs, squashed_log_prob, squashed_sample
from trainer.common.numpy_policy import PolicyOutput
from trainer.common.numpy_policy import squashed_entropy as policy_entropy  # (numpy_step.py's name)
from trainer.common.policy import Policy, allowed_from_mask


class SACPolicy(Policy):
    SQUASHED = True

    def act(self, obs: Sequence[np.ndarray], action_mask: np.ndarray | None = None,
            deterministic: bool = False, memories: np.ndarray | None = None) -> PolicyOutput:
        """Actions for n agents in one forward pass (see Policy.act for the arguments)."""
        deterministic = deterministic or self.hyperparams.deterministic
        n = len(obs[0])
        if self._numpy_actor is not None:
            return self.sampler.act(obs, action_mask, deterministic, memories)
        memories_out = None
        with torch.inference_mode():
            if self.memory_size:
                memory_in = (torch.zeros((n, self.memory_size)) if memories is None
                             else torch.as_tensor(np.asarray(memories, dtype=np.float32)))
                encoding, memories_t = self.actor.network_body.forward_memory(
                    self._to_tensors(obs), memory_in.to(self.device).unsqueeze(0), 1)
                memories_out = memories_t[0].cpu().numpy()
            else:
                encoding = self.actor.network_body(self._to_tensors(obs))
            allowed = allowed_from_mask(action_mask)
            mu_t, logits_t = self.actor.heads_of(encoding, None if allowed is None else allowed.to(self.device))
            log_sigma = None if mu_t is None else self.actor.log_sigma_of(encoding, mu_t).cpu().numpy()
            mu = None if mu_t is None else mu_t.cpu().numpy()
            logits = [branch.cpu().numpy() for branch in logits_t]
        return self.sampler.sample_squashed(mu, log_sigma, logits, n, deterministic, memories_out)

    def sample_with_grad(self, obs: Sequence[torch.Tensor], allowed: torch.Tensor | None, generator: torch.Generator,
                         memories: torch.Tensor | None = None, sequence_length: int = 1
                         ) -> tuple[torch.Tensor | None, torch.Tensor | None, torch.Tensor | None, torch.Tensor | None,
                                    np.ndarray]:
        """For the update, with gradients: (squashed actions [n, c] (reparameterised), their
        log-probs [n, c], the discrete probabilities [n, K] and log(p + eps) [n, K] of every
        option; None for an absent action kind), and without: the policy's entropy per row, float32
        [n] (``policy_entropy``). A recurrent actor reads the n rows as sequences
        of ``sequence_length`` starting from ``memories`` [1, n / sequence_length, m]."""
        if memories is not None:
            encoding, _ = self.actor.network_body.forward_memory(obs, memories, sequence_length)
        else:
            encoding = self.actor.network_body(obs)
        mu, logits = self.actor.heads_of(encoding, allowed)
        actions = log_probs = probs = all_log_probs = log_sigma = None
        if mu is not None:
            log_sigma = self.actor.log_sigma_of(encoding, mu)
            noise = torch.randn(mu.shape, generator=generator, device=mu.device)
            raw, actions = squashed_sample(mu, log_sigma, noise)
            log_probs = squashed_log_prob(raw, mu, log_sigma)
        if logits:
            probs = torch.cat([torch.softmax(branch, dim=1) for branch in logits], dim=1)
            all_log_probs = categorical_option_log_probs(probs)
        entropy = policy_entropy(len(encoding), None if log_sigma is None else log_sigma.detach().cpu().numpy(),
                                 [] if probs is None else [probs.detach().cpu().numpy()])  # all branches: their sum
        return actions, log_probs, probs, all_log_probs, entropy
