"""A recurrent critic's value estimates over one trajectory, and a trajectory's columns in whole
sequences: the one implementation PPO and SAC share.

The critic runs over the trajectory sequence by sequence (whole sequences of ``sequence_length``
from the start, then the rest), its memory carried on from the agent's previous trajectory of the
same episode, as ML-Agents does for an LSTM critic (docs/ppo.md, "PPO details that affect results").
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import torch

if TYPE_CHECKING:
    from trainer.common.hyperparams import NetworkHyperparams
    from trainer.common.networks import Critic
    from trainer.common.numpy_net import NumpyCritic
    from trainer.common.trajectory import Trajectory


class RecurrentCriticValues:
    """Mixin for a trainer whose ``critic`` may have memory; the trainer sets the attributes below."""

    critic: Critic
    _numpy_critic: NumpyCritic | None  # the critic in numpy (vector observations on the CPU), or None
    _critic_memory: dict[Any, np.ndarray]  # episode -> float32 [memory_size] where its next trajectory starts
    sequence_length: int
    hyperparams: NetworkHyperparams
    device: torch.device

    def _value_estimates_by_sequence(self, traj: Trajectory
                                     ) -> tuple[dict[str, np.ndarray], dict[str, float], np.ndarray]:
        """(values [T] per signal, V(next) per signal, the critic memory each step's sequence starts
        from [T, m]); the memory after the trajectory is kept for the episode's next one."""
        length, step, size = len(traj), self.sequence_length, self.hyperparams.memory_size
        memory = self._critic_memory.pop(traj.episode, None)
        memory = np.zeros((1, size), np.float32) if memory is None else memory[None]
        starts = np.zeros((length, size), dtype=np.float32)
        parts: dict[str, list[np.ndarray]] = {}
        for begin in range(0, length, step):  # the last sequence may be short
            end = min(begin + step, length)
            starts[begin:end] = memory[0]
            values, memory = self._critic_with_memory([o[begin:end] for o in traj.obs], memory)
            for name, v in values.items():
                parts.setdefault(name, []).append(v)
        next_values, _ = self._critic_with_memory([n[None] for n in traj.next_obs], memory)
        next_values = {name: float(v[0]) for name, v in next_values.items()}
        if not traj.done:
            self._critic_memory[traj.episode] = memory[0]
        return {name: np.concatenate(v) for name, v in parts.items()}, next_values, starts

    def _in_whole_sequences(self, traj: Trajectory, fields: dict[str, np.ndarray], critic_memories: np.ndarray
                            ) -> dict[str, np.ndarray]:
        """A trajectory's buffer columns ``fields`` [T, ...] with each step's actor memory, the critic
        memory its sequence starts from (``critic_memories``) and masks 1, then padded with zeros
        (masks 0) to whole sequences of ``sequence_length``: a recurrent update reads sequences."""
        length = len(traj)
        fields["memory"] = np.asarray(traj.memories, np.float32)
        fields["critic_memory"] = critic_memories
        fields["masks"] = np.ones(length, dtype=np.float32)
        pad = -length % self.sequence_length
        if pad:
            fields = {k: np.concatenate([v, np.zeros((pad, *v.shape[1:]), v.dtype)]) for k, v in fields.items()}
        return fields

    def _critic_with_memory(self, obs: list[np.ndarray], memory: np.ndarray
                            ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """One sequence (all rows of ``obs``) through the recurrent critic from memory [1, m]:
        (values [rows] per signal, the memory after it [1, m]); numpy when it can."""
        if self._numpy_critic is not None:
            return self._numpy_critic.with_memory(obs, memory, len(obs[0]))
        tensors = [torch.as_tensor(np.asarray(o, dtype=np.float32), device=self.device) for o in obs]
        with torch.inference_mode():
            values, after = self.critic.forward_memory(
                tensors, torch.as_tensor(memory, device=self.device)[None], len(obs[0]))
        return {name: v.cpu().numpy() for name, v in values.items()}, after[0].cpu().numpy()
