"""``behavioral_cloning``: the policy learns to take the demonstration's actions, beside RL.

One ``BehavioralCloning`` per brain, called by its trainer after each of the trainer's own
updates (PPO: ``PPOTrainer.update``; SAC: ``SACTrainer.update``). Behaviour as in ML-Agents
Release 22 (docs/demonstrations.md):

* its own Adam over the actor's parameters, learning rate = the policy's learning rate x
  ``strength``; with ``steps`` > 0 that rate decays linearly to 1e-10 over ``steps`` trainer
  steps (set after each update, as the reference does), with ``steps`` 0 it stays;
* per update ``num_epoch`` (default 3, whatever the trainer's) shuffles of the demonstration, cut into
  minibatches of ``batch_size`` (default: the trainer's) experiences, at most
  ``samples_per_update`` experiences per epoch (0 = all);
* loss per minibatch: for continuous actions the mean squared error between a sampled action, as
  the environment would receive it, and the demonstration's action; for each discrete branch the
  cross-entropy of the unmasked policy with the demonstrated choice (mean over the branches);
* ``Losses/Pretraining Loss``: the mean minibatch loss of the update.

One deliberate difference: the reference compares the demonstration's actions (what Unity
received, in [-1, 1]) with the raw Gaussian sample, which the environment receives divided by 3
(clamp(a, -3, 3) / 3); a policy cloned that way acts at a third of the expert's amplitude. Here
the sample goes through the same clamp and division first (SAC: through its tanh), so the
cloned actions are the expert's.

A recurrent policy (network_settings.memory) clones whole sequences of ``sequence_length``
experiences, each starting from a zero memory as in the reference: the demonstration is cut into
episodes, each padded with zeros to whole sequences, and the padding is left out of the loss
(the reference averages over it too). ``batch_size`` is then rounded down to whole sequences (at
least one) and ``samples_per_update`` counts experiences, padding included.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from trainer.demonstrations import DemoExperiences
from trainer.common.adam import Adam
from trainer.common.schedules import LEARNING_RATE_FLOOR, decay

DEFAULT_NUM_EPOCH = 3  # the reference's, for PPO and SAC alike
CONTINUOUS_CLIP = 3.0  # PPO's actions reach the environment as clamp(a, -3, 3) / 3 (trainer/common/policy.py)


class BehavioralCloning:
    def __init__(self, policy, settings, demo: DemoExperiences, policy_learning_rate: float,
                 default_batch_size: int, seed: int) -> None:
        self.policy = policy
        self.demo = demo
        self.initial_lr = policy_learning_rate * settings.strength
        self.current_lr = self.initial_lr
        self.anneal_steps = settings.steps
        self.memory_size = getattr(policy, "memory_size", 0)
        self.sequence_length = policy.hyperparams.sequence_length if self.memory_size else 1
        columns = [*demo.obs, demo.continuous, demo.discrete, np.ones(len(demo), np.float32)]
        if self.memory_size:
            columns = _whole_sequences(columns, demo.done, self.sequence_length)
        *obs, continuous, discrete, valid = columns
        rows = len(valid)
        # whole sequences per minibatch (one experience each without memory), at least one
        self.sequences_per_batch = max(min(settings.batch_size or default_batch_size, rows) // self.sequence_length, 1)
        self.batch_size = self.sequences_per_batch * self.sequence_length
        self.num_epoch = settings.num_epoch or DEFAULT_NUM_EPOCH
        self.samples_per_update = settings.samples_per_update
        self.optimizer = Adam([p for p in policy.actor.parameters() if p.requires_grad], lr=self.initial_lr)
        self.generator = torch.Generator()
        self.generator.manual_seed(seed)
        self._obs = [torch.as_tensor(o) for o in obs]
        self._continuous = torch.as_tensor(continuous)
        self._discrete = torch.as_tensor(discrete)
        self._valid = torch.as_tensor(valid)  # 0 on sequence padding

    def _learning_rate(self, step: int) -> float:
        schedule = "linear" if self.anneal_steps > 0 else "constant"
        return decay(schedule, self.initial_lr, LEARNING_RATE_FLOOR, step, self.anneal_steps)

    def loss(self, index: torch.Tensor) -> torch.Tensor:
        """The cloning loss of the demonstration rows ``index`` (with grad; with memory, whole
        sequences in order)."""
        actor = self.policy.actor
        obs = [o[index] for o in self._obs]
        valid = self._valid[index]
        if self.memory_size:
            start = torch.zeros((1, len(index) // self.sequence_length, self.memory_size))
            encoding, _ = actor.network_body.forward_memory(obs, start, self.sequence_length)
        else:
            encoding = actor.network_body(obs)
        mu, logits = actor.heads_of(encoding, None)
        loss = torch.zeros(())
        if mu is not None:
            sigma = torch.exp(actor.log_sigma_of(encoding, mu))
            sample = mu + torch.randn(mu.shape, generator=self.generator) * sigma
            if self.policy.SQUASHED:
                acted = torch.tanh(sample)
            else:
                acted = torch.clamp(sample, -CONTINUOUS_CLIP, CONTINUOUS_CLIP) / CONTINUOUS_CLIP
            loss = loss + _masked_mean(torch.mean((acted - self._continuous[index]) ** 2, dim=1), valid)
        if logits:
            expert = self._discrete[index]
            per_branch = [torch.nn.functional.cross_entropy(branch, expert[:, b], reduction="none")
                          for b, branch in enumerate(logits)]
            loss = loss + _masked_mean(torch.mean(torch.stack(per_branch, dim=1), dim=1), valid)
        return loss

    def update(self, step: int) -> dict[str, float]:
        """One round of cloning after a trainer update at trainer step ``step``."""
        if self.current_lr <= LEARNING_RATE_FLOOR:
            return {"Losses/Pretraining Loss": 0.0}
        rows, length = len(self._valid), self.sequence_length
        per_epoch = rows if self.samples_per_update <= 0 else min(rows, self.samples_per_update)
        batches = max(per_epoch // self.batch_size, 1)
        within = torch.arange(length)
        losses = []
        for _ in range(self.num_epoch):
            order = torch.randperm(rows // length, generator=self.generator)  # whole sequences
            order = (order[:, None] * length + within).reshape(-1)
            for b in range(batches):
                loss = self.loss(order[b * self.batch_size:(b + 1) * self.batch_size])
                self.optimizer.zero_grad()
                loss.backward()
                self.optimizer.step()
                losses.append(loss.item())
        self.current_lr = self._learning_rate(step)
        for group in self.optimizer.param_groups:
            group["lr"] = self.current_lr
        return {"Losses/Pretraining Loss": float(np.mean(losses))}

    def state_dict(self) -> dict[str, Any]:
        return {"Optimizer:BC": {**self.optimizer.state_dict(), "current_lr": torch.tensor(self.current_lr),
                                 "generator": self.generator.get_state()}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        saved = dict(state["Optimizer:BC"])
        self.current_lr = float(saved.pop("current_lr"))
        self.generator.set_state(saved.pop("generator"))
        self.optimizer.load_state_dict(saved)


def _masked_mean(values: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    return torch.sum(values * valid) / torch.clamp(torch.sum(valid), min=1.0)


def _whole_sequences(columns: list[np.ndarray], done: np.ndarray, length: int) -> list[np.ndarray]:
    """Each column cut into episodes (an experience with ``done`` ends one), each episode padded
    with zeros to a multiple of ``length`` rows."""
    ends = (np.flatnonzero(done) + 1).tolist()
    if not ends or ends[-1] != len(done):
        ends.append(len(done))
    out: list[list[np.ndarray]] = [[] for _ in columns]
    start = 0
    for end in ends:
        pad = -(end - start) % length
        for parts, column in zip(out, columns):
            parts.append(column[start:end])
            if pad:
                parts.append(np.zeros((pad, *column.shape[1:]), column.dtype))
        start = end
    return [np.concatenate(parts) for parts in out]
