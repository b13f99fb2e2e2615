"""POCATrainer: MA-POCA for a behavior whose agents act in groups (docs/poca.md).

PPO's trainer with a centralised critic (networks.POCACritic); everything else is PPO's: the
actor and its sampling, the update buffer and minibatches, Adam, the schedules, curiosity / rnd,
checkpoints and the ONNX export of the actor. Per trajectory (rollout.GroupTracker adds the
teammates' columns) and reward signal:

* the extrinsic reward of a step is the agent's reward and group reward plus its teammates' own
  rewards of that step (as the reference's extrinsic signal with POCA);
* values V_t of the group (the agent and the teammates present at t) and the bootstrap V of the
  group after the last step; the group's episode is over (no bootstrap) only when the agent's
  episode ended, every teammate's had too and none was interrupted. An agent that leaves before
  its group is thus credited, through V of the teammates it left behind, with what the group
  earns after it left;
* lambda returns G_t = r_t + gamma ((1 - lambda) V_{t+1} + lambda G_{t+1}), which are GAE's
  returns (gae.py), and the advantage G_t - b_t with b_t the agent's baseline (its teammates'
  observations and actions, its own action left out); the mean over signals is the advantage;
* loss = policy loss + 0.5 (value loss + 0.5 baseline loss) - beta entropy; the value loss is the
  squared error to the returns (anchored at the returns, as PPO's, trainer/ppo/trainer.py says
  why), the baseline's is clipped around the baseline estimates of the trajectory.

With network_settings.memory the actor is PPO's recurrent actor (its memories kept per agent by
rollout.GroupTracker, exported to ONNX with recurrent_in / recurrent_out) and the critic has an
LSTM whose value and baseline memories are carried per agent episode across its trajectories
(``estimates_by_sequence``); experiences are buffered as whole padded sequences with the three
memories each sequence starts from, and the losses ignore the padding (docs/poca.md).
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import torch

from protos.types import BehaviorSpec
from trainer.errors import ConfigError
from trainer.poca.networks import POCACritic
from trainer.common.trajectory import GroupColumns, Trajectory
from trainer.common.gae import gae
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.masked import masked_mean
from trainer.ppo.losses import policy_loss, ppo_loss, value_loss
from trainer.ppo.trainer import PPOTrainer, _obs_key

GROUP_FIELDS = ("mates_continuous", "mates_discrete", "mates_present")


def _mates_obs_key(index: int) -> str:
    return f"mates_obs_{index}"


def pad_mates(array: np.ndarray, width: int, axis: int = 1) -> np.ndarray:
    """``array`` with its teammate axis zero-padded to ``width`` slots (absent)."""
    missing = width - array.shape[axis]
    if missing <= 0:
        return array
    pad = [(0, 0)] * array.ndim
    pad[axis] = (0, missing)
    return np.pad(array, pad)


def lonely_group(traj: Trajectory, spec: BehaviorSpec) -> GroupColumns:
    """The group columns of an agent without teammates (group id 0)."""
    n, a = len(traj), spec.action_spec
    shapes = [tuple(o.shape) for o in spec.observation_specs]
    return GroupColumns([np.zeros((n, 0, *s), np.float32) for s in shapes], np.zeros((n, 0, a.continuous_size), np.float32),
                        np.zeros((n, 0, a.discrete_size), np.int32), np.zeros((n, 0), bool), np.zeros((n, 0), np.float32),
                        [np.zeros((0, *s), np.float32) for s in shapes], np.zeros(0, bool), True)


def with_agent(mates_present: torch.Tensor) -> torch.Tensor:
    """[n, M] teammates present -> [n, 1 + M] with the agent itself (always present) first; also
    for M = 0 (no group: ``present[:, :1]`` would then be empty)."""
    own = torch.ones((mates_present.shape[0], 1), dtype=torch.bool, device=mates_present.device)
    return torch.cat([own, mates_present], dim=1)


class POCATrainer(PPOTrainer):
    uses_groups = True  # the run loop assembles this behavior's trajectories with rollout.GroupTracker

    def __init__(self, brain_name: str, behavior_spec: BehaviorSpec, hyperparams: PPOHyperparams,
                 seed: int, device: str = "cpu"):
        if hyperparams.shared_critic:
            raise ConfigError(f"behavior {brain_name!r}: POCA has no shared_critic (its critic sees the group)")
        super().__init__(brain_name, behavior_spec, hyperparams, seed, device, use_numpy_update=False)
        self.group_width = 0  # teammate slots of the buffered experiences (the widest group seen)

    def _make_critic(self) -> torch.nn.Module:
        spec = self.behavior_spec
        return POCACritic(spec.observation_specs, spec.action_spec, list(self.hyperparams.reward_signals),
                          self.hyperparams)

    # ------------------------------------------------------------------ experience
    def estimates(self, traj: Trajectory, group: GroupColumns) -> tuple[dict, dict, dict]:
        """(values [T], baselines [T], value after the last step) per reward signal."""
        with torch.inference_mode():
            own, mates, actions, present, everyone, with_self, after, after_present = self._group_tensors(traj, group)
            values = self.critic.value(everyone, with_self)
            baselines = self.critic.baseline(own, mates, *actions, present)
            next_values = self.critic.value(after, after_present)
        return ({k: v.cpu().numpy() for k, v in values.items()}, {k: v.cpu().numpy() for k, v in baselines.items()},
                {k: float(v[0]) for k, v in next_values.items()})

    def _group_tensors(self, traj: Trajectory, group: GroupColumns) -> tuple:
        """The critic's inputs of a trajectory: own obs [T, *s], teammates' obs [T, M, *s], their
        actions, present [T, M], the whole group's obs [T, 1 + M, *s] and present, and the group
        after the last step ([1, 1 + M2, *s], [1, 1 + M2])."""
        t = lambda a: torch.as_tensor(np.asarray(a), device=self.device)  # noqa: E731
        own = [t(np.asarray(o, np.float32)) for o in traj.obs]
        mates = [t(o) for o in group.obs]
        present = t(group.present)
        everyone = [torch.cat([o.unsqueeze(1), m], dim=1) for o, m in zip(own, mates)]
        after = [torch.cat([t(np.asarray(n, np.float32))[None], t(m)], dim=0)[None]
                 for n, m in zip(traj.next_obs, group.next_obs)]
        after_present = t(np.concatenate([[True], group.next_present]))[None]
        actions = (t(group.continuous_actions), t(group.discrete_actions))
        return own, mates, actions, present, everyone, with_agent(present), after, after_present

    def estimates_by_sequence(self, traj: Trajectory, group: GroupColumns) -> tuple[dict, dict, dict, np.ndarray, np.ndarray]:
        """``estimates`` of a recurrent critic, run sequence by sequence as PPO's
        (``_value_estimates_by_sequence``): the value and the baseline each carry their own
        memory on from the agent's previous trajectory of the episode. Also returns the critic
        and the baseline memory each step's sequence starts from ([T, m] each)."""
        length, step, size = len(traj), self.sequence_length, self.hyperparams.memory_size
        zeros = torch.zeros((1, 1, size), device=self.device)
        value_memory, baseline_memory = self._critic_memory.pop(traj.episode, (zeros, zeros))
        value_starts = np.zeros((length, size), np.float32)
        baseline_starts = np.zeros((length, size), np.float32)
        values: dict[str, list] = {}
        baselines: dict[str, list] = {}
        with torch.inference_mode():
            own, mates, actions, present, everyone, with_self, after, after_present = self._group_tensors(traj, group)
            for begin in range(0, length, step):  # the last sequence may be short
                end = min(begin + step, length)
                value_starts[begin:end] = value_memory[0, 0].cpu().numpy()
                baseline_starts[begin:end] = baseline_memory[0, 0].cpu().numpy()
                v, value_memory = self.critic.value_memory([e[begin:end] for e in everyone], with_self[begin:end],
                                                           value_memory, end - begin)
                b, baseline_memory = self.critic.baseline_memory(
                    [o[begin:end] for o in own], [m[begin:end] for m in mates], actions[0][begin:end],
                    actions[1][begin:end], present[begin:end], baseline_memory, end - begin)
                for name in v:
                    values.setdefault(name, []).append(v[name])
                    baselines.setdefault(name, []).append(b[name])
            next_values, _ = self.critic.value_memory(after, after_present, value_memory, 1)
        if not traj.done:
            self._critic_memory[traj.episode] = (value_memory, baseline_memory)
        return ({k: torch.cat(v).cpu().numpy() for k, v in values.items()},
                {k: torch.cat(v).cpu().numpy() for k, v in baselines.items()},
                {k: float(v[0]) for k, v in next_values.items()}, value_starts, baseline_starts)

    def process_trajectory(self, traj: Trajectory) -> dict[str, float]:
        """Normalise, estimate values and baselines, lambda returns and advantages per reward
        signal (module docstring), and buffer the experiences with their teammates' columns."""
        group = traj.group if traj.group is not None else lonely_group(traj, self.behavior_spec)
        if group.width:  # the teammates' own rewards join the extrinsic reward (curiosity / rnd ignore it)
            traj = dataclasses.replace(traj, rewards=(traj.rewards + group.rewards.sum(axis=1)).astype(np.float32))
        if self.hyperparams.normalize:
            obs_tensors = self._tensors(traj.obs)
            self.policy.actor.update_normalization(obs_tensors)
            self.critic.update_normalization(obs_tensors)
        if self.hyperparams.memory_size:
            values, baselines, next_values, critic_memories, baseline_memories = self.estimates_by_sequence(traj, group)
        else:
            values, baselines, next_values = self.estimates(traj, group)
        group_over = traj.done and not traj.interrupted and group.all_done
        fields: dict[str, np.ndarray] = {_obs_key(i): np.asarray(o, np.float32) for i, o in enumerate(traj.obs)}
        experience = self._provider_experience(traj, fields)
        advantages = []
        stats: dict[str, float] = {}
        for name, (gamma, strength) in self.hyperparams.reward_signals.items():
            rewards, bootstrap = self._signal_rewards(name, strength, traj, experience, group_over, next_values[name],
                                                      stats)
            _, returns = gae(rewards, values[name], bootstrap, gamma, self.hyperparams.lambd)
            advantages.append(returns - baselines[name])
            fields[f"baselines:{name}"] = baselines[name]
            fields[f"returns:{name}"] = returns
            provider = self.providers.get(name)
            label = name.capitalize() if provider is None else provider.stat_name
            stats[f"Policy/{label} Value Estimate"] = float(np.mean(values[name]))
            stats[f"Policy/{label} Baseline Estimate"] = float(np.mean(baselines[name]))
        if traj.done:
            self._episode_intrinsic.pop(traj.episode, None)
        fields["advantages"] = np.mean(np.stack(advantages), axis=0).astype(np.float32)
        self._add_action_fields(traj, fields)
        self._widen(group.width)
        width = self.group_width
        for i, o in enumerate(group.obs):
            fields[_mates_obs_key(i)] = pad_mates(np.asarray(o, np.float32), width)
        fields["mates_continuous"] = pad_mates(group.continuous_actions.astype(np.float32), width)
        fields["mates_discrete"] = pad_mates(group.discrete_actions.astype(np.int64), width)
        fields["mates_present"] = pad_mates(group.present, width)
        if self.hyperparams.memory_size:  # whole sequences, as PPO's; the baseline's memory padded alike
            fields["baseline_memory"] = baseline_memories
            fields = self._in_whole_sequences(traj, fields, critic_memories)
        self.buffer.append(fields)
        self.step += len(traj)
        return stats

    def _widen(self, width: int) -> None:
        """More teammate slots than buffered so far: pad what the buffer holds to ``width``."""
        if width <= self.group_width:
            return
        self.group_width = width
        for name in self.buffer.field_names:
            if name in GROUP_FIELDS or name.startswith("mates_obs_"):
                self.buffer.rewrite(name, lambda array: pad_mates(array, width))

    # ------------------------------------------------------------------ update
    def _minibatch_loss(self, batch: dict[str, torch.Tensor], beta: float, epsilon: float
                        ) -> tuple[torch.Tensor, dict[str, float]]:
        n_obs = len(self.behavior_spec.observation_specs)
        obs = [batch[_obs_key(i)] for i in range(n_obs)]
        mates = [batch[_mates_obs_key(i)] for i in range(n_obs)]
        present = batch["mates_present"]
        allowed = batch["allowed"] if self.behavior_spec.action_spec.discrete_branches else None
        everyone = [torch.cat([o.unsqueeze(1), m], dim=1) for o, m in zip(obs, mates)]
        actions = (batch["mates_continuous"], batch["mates_discrete"])
        mask = None
        if self.hyperparams.memory_size:  # rows are whole sequences; each starts from its stored memories
            step = self.sequence_length
            mask = batch["masks"]
            start = lambda key: batch[key][::step].unsqueeze(0)  # noqa: E731
            log_probs, entropy = self.policy.evaluate(obs, allowed, batch["continuous_actions"],
                                                      batch["discrete_actions"], start("memory"), step)
            values, _ = self.critic.value_memory(everyone, with_agent(present), start("critic_memory"), step)
            baselines, _ = self.critic.baseline_memory(obs, mates, *actions, present, start("baseline_memory"), step)
        else:
            log_probs, entropy = self.policy.evaluate(obs, allowed, batch["continuous_actions"],
                                                      batch["discrete_actions"])
            values = self.critic.value(everyone, with_agent(present))
            baselines = self.critic.baseline(obs, mates, *actions, present)
        names = list(values)
        returns = {n: batch[f"returns:{n}"] for n in names}
        policy_term = policy_loss(batch["advantages"], log_probs, batch["log_probs"], epsilon, mask)
        value_term = value_loss(values, returns, returns, epsilon, mask)
        baseline_term = value_loss(baselines, {n: batch[f"baselines:{n}"] for n in names}, returns, epsilon, mask)
        loss = ppo_loss(policy_term, value_term + 0.5 * baseline_term, entropy, beta, mask)
        return loss, {
            "Losses/Policy Loss": abs(policy_term.item()),
            "Losses/Value Loss": value_term.item(),
            "Losses/Baseline Loss": baseline_term.item(),
            "Policy/Entropy": masked_mean(entropy, mask).item(),
        }

    # ------------------------------------------------------------------ persistence
    def load_state_dict(self, state: dict[str, Any]) -> None:
        if not any(key.startswith("attention.") for key in state.get("Optimizer:critic", {})):
            raise KeyError("the checkpoint has no POCA critic (Optimizer:critic without attention); "
                           "was it written by PPO or SAC?")
        super().load_state_dict(state)
