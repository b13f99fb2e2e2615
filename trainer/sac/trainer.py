"""SACTrainer: trajectories into a replay buffer, then soft actor-critic gradient steps.

One trainer per brain, behind the run loop's ``Trainer`` (trainer/common/trainer_interface.py:
``process_trajectory``, ``ready_to_update``, ``update``, ``state_dict``, ``export_onnx``); a recurrent
critic's value estimates as PPO's (common/recurrent_critic.py). Networks (docs/sac.md):

* the policy: networks.Actor, squashed (tanh; state-dependent sigma);
* a value network V(s) and its target copy (soft-updated with ``tau`` after every step);
* twin Q networks Q1, Q2 (s, continuous actions) -> a value per discrete option (or one);
* log entropy coefficients: one for the continuous block, one per discrete branch;
* curiosity / rnd learners (trainer/common/reward_providers.py, shared with PPO), which reward
  each sampled minibatch afresh and learn on minibatches of their own, one per
  ``reward_signal_steps_per_update`` agent steps (as the reference does).

Each gradient step samples ``batch_size`` experiences and steps three Adams (adam.py): the policy
on its loss, V + Q1 + Q2 on theirs, the log alphas on theirs; for vector observations without
memory on the CPU in numpy with hand-written gradients (numpy_step.py says why), otherwise in
autograd. Gradient steps keep pace with experience: after ``buffer_init_steps`` agent steps, one
step per ``steps_per_update`` agent steps.
"""
from __future__ import annotations

from itertools import chain
from typing import Any

import numpy as np
import torch
from torch import nn

from protos.types import BehaviorSpec
from trainer.common import numpy_net
from trainer.common.adam import Adam
from trainer.common.encoders import VectorInput
from trainer.common.networks import Critic, NetworkBody
from trainer.common.recurrent_critic import RecurrentCriticValues
from trainer.common.reward_providers import Experience, load_providers, make_providers
from trainer.common.schedules import LEARNING_RATE_FLOOR, decay
from trainer.common.numpy_policy import noise_state, set_noise_state
from trainer.common.trainer_interface import Trainer
from trainer.common.trajectory import Trajectory
from trainer.sac import losses, numpy_step
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.policy import SACPolicy
from trainer.sac.replay_buffer import ReplayBuffer


class TwinQ(nn.Module):
    """Q1 and Q2 (checkpoint key ``Optimizer:q_network``, as in the reference)."""

    def __init__(self, q1: Critic, q2: Critic):
        super().__init__()
        self.q1_network, self.q2_network = q1, q2


class EntropyCoefficients(nn.Module):
    """log alpha of the continuous block [1] and of every discrete branch [b]."""

    def __init__(self, init_entcoef: float, has_continuous: bool, branches: int):
        super().__init__()
        start = float(np.log(init_entcoef))
        self.continuous = nn.Parameter(torch.full((1,), start)) if has_continuous else None
        self.discrete = nn.Parameter(torch.full((branches,), start)) if branches else None


@torch.no_grad()
def copy_normalization(source: NetworkBody, target: NetworkBody) -> None:
    """The target body's observation normalisers take the source's statistics."""
    for src, dst in zip(source.observation_encoder.encoders, target.observation_encoder.encoders):
        if (isinstance(src, VectorInput) and src.normalizer is not None
                and isinstance(dst, VectorInput) and dst.normalizer is not None):
            for name, buffer in src.normalizer.named_buffers():
                getattr(dst.normalizer, name).copy_(buffer)


def _obs_key(index: int) -> str:
    return f"obs_{index}"


def _next_obs_key(index: int) -> str:
    return f"next_obs_{index}"


class SACTrainer(RecurrentCriticValues, Trainer):
    def __init__(self, brain_name: str, behavior_spec: BehaviorSpec, hyperparams: SACHyperparams,
                 seed: int, device: str = "cpu", use_numpy_update: bool = True):
        super().__init__(brain_name, behavior_spec, hyperparams, device)
        spec = behavior_spec.action_spec
        self.branches = list(spec.discrete_branches)
        self.policy = SACPolicy(behavior_spec, hyperparams, seed, device)
        names = list(hyperparams.reward_signals)
        obs_specs = behavior_spec.observation_specs
        q_outputs = max(sum(self.branches), 1)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed + 2)
            self.critic = Critic(obs_specs, names, hyperparams).to(self.device)
            self.q_network = TwinQ(*(Critic(obs_specs, names, hyperparams, action_size=spec.continuous_size,
                                            outputs_per_signal=q_outputs) for _ in range(2))).to(self.device)
            self.target_network = Critic(obs_specs, names, hyperparams).to(self.device)
        losses.soft_update(self.critic, self.target_network, 1.0)
        # parameter lists walked every gradient step (nn.Module's own walk costs more than the ops)
        self._q1_params = list(self.q_network.q1_network.parameters())
        self._critic_params = list(self.critic.parameters())
        self._target_params = list(self.target_network.parameters())
        self.log_ent_coef = EntropyCoefficients(hyperparams.init_entcoef, spec.continuous_size > 0,
                                                len(self.branches)).to(self.device)
        self.target_entropy = losses.target_entropies(spec.continuous_size, self.branches)
        lr = hyperparams.learning_rate
        self.policy_optimizer = Adam([p for p in self.policy.actor.parameters() if p.requires_grad],
                                     lr=lr)  # adam.py says why not torch.optim
        self.value_optimizer = Adam(chain(self.critic.parameters(), self.q_network.parameters()), lr=lr)
        self.entropy_optimizer = Adam(self.log_ent_coef.parameters(), lr=lr)
        # LSTM: experiences are stored and sampled in whole sequences (replay_buffer.py); the
        # critic's memory at the end of an episode's last trajectory is where its next one starts
        self.sequence_length = hyperparams.sequence_length if hyperparams.memory_size else 1
        self._critic_memory: dict[Any, np.ndarray] = {}  # episode -> float32 [memory_size]
        step = self.sequence_length
        self.buffer = ReplayBuffer(-(-hyperparams.buffer_size // step) * step)
        self.sample_generator = torch.Generator()
        self.sample_generator.manual_seed(seed + 3)
        self.noise_generator = torch.Generator(device=self.device)  # the update's policy samples
        self.noise_generator.manual_seed(seed + 4)
        # curiosity / rnd: their own networks and optimizers, seeded after the SAC networks
        self.providers = make_providers(behavior_spec, hyperparams.reward_signals,
                                        hyperparams.reward_signal_networks, seed + 5)
        self._episode_intrinsic: dict[Any, dict[str, float]] = {}  # episode -> reward sums so far
        self.step = 0
        self.update_steps = 1  # gradient steps taken + 1 (the reference's counter, kept on resume)
        self.reward_signal_update_steps = 1  # reward-signal learner steps + 1 (likewise)
        self._numpy_critic = numpy_net.NumpyCritic(self.critic) if (
            numpy_net.supports(self.critic, recurrent=True) and self.device.type == "cpu") else None
        self.behavioral_cloning = None  # trainer/behavioral_cloning.py, set by behavior.make_trainer
        # vector observations without memory on the CPU: gradient steps in numpy (numpy_step.py says
        # why); MLAGENTS_LIKE_NUMPY_UPDATE=0 (``use_numpy_update`` False) keeps autograd, as for PPO
        self._numpy_step = numpy_step.NumpySAC(self) if use_numpy_update and numpy_step.supports(self) else None

    # ------------------------------------------------------------------ experience
    def _tensors(self, arrays) -> list[torch.Tensor]:
        return [torch.as_tensor(np.asarray(a, dtype=np.float32), device=self.device) for a in arrays]

    def process_trajectory(self, traj: Trajectory) -> dict[str, float]:
        """Normalise (once per trajectory, as PPO) and store the experiences; report V(s)."""
        length = len(traj)
        obs = [np.asarray(o, np.float32) for o in traj.obs]
        if self.hyperparams.normalize:
            self.policy.actor.update_normalization(self._tensors(obs))
        fields: dict[str, np.ndarray] = {}
        for index, (o, last) in enumerate(zip(obs, traj.next_obs)):
            fields[_obs_key(index)] = o
            fields[_next_obs_key(index)] = np.concatenate([o[1:], np.asarray(last, np.float32)[None]], axis=0)
        fields["continuous_actions"] = np.asarray(traj.continuous_actions, np.float32).reshape(length, -1)
        fields["discrete_actions"] = np.asarray(traj.discrete_actions, np.int64).reshape(length, -1)
        mask_width = sum(self.branches)
        fields["action_masks"] = (np.zeros((length, mask_width), dtype=bool) if traj.action_masks is None
                                  else np.asarray(traj.action_masks, dtype=bool))
        fields["rewards"] = np.asarray(traj.rewards, np.float32)
        done = np.zeros(length, dtype=np.float32)  # an interrupted episode bootstraps from its last obs
        done[-1] = float(traj.done and not traj.interrupted)
        fields["done"] = done
        stats = self._intrinsic_rewards(traj, fields)
        copy_normalization(self.policy.actor.network_body, self.critic.network_body)
        if self.hyperparams.memory_size:
            values, _, critic_memories = self._value_estimates_by_sequence(traj)
            fields = self._in_whole_sequences(traj, fields, critic_memories)
        elif self._numpy_critic is not None:
            values = self._numpy_critic(obs)
        else:
            with torch.inference_mode():
                values = {k: v.cpu().numpy() for k, v in self.critic(self._tensors(obs)).items()}
        self.buffer.add(fields)
        self.step += length
        stats.update({f"Policy/{self._stat_name(name)} Value": float(np.mean(v)) for name, v in values.items()})
        return stats

    def _stat_name(self, signal: str) -> str:
        provider = self.providers.get(signal)
        return provider.stat_name if provider is not None else signal.capitalize()

    def _experience(self, columns: dict[str, np.ndarray]) -> Experience:
        """What a reward provider reads, from replay-buffer columns (a trajectory's or a minibatch)."""
        n_obs = len(self.behavior_spec.observation_specs)
        return Experience([columns[_obs_key(i)] for i in range(n_obs)],
                          [columns[_next_obs_key(i)] for i in range(n_obs)],
                          columns["continuous_actions"], columns["discrete_actions"], columns.get("masks"))

    def _intrinsic_rewards(self, traj: Trajectory, fields: dict[str, np.ndarray]) -> dict[str, float]:
        """Each provider's reward x strength summed over the episode, reported as
        ``Policy/<Name> Reward`` when it ends (the reference's per-episode statistic; the
        rewards SAC learns from are computed again on every sampled minibatch)."""
        if not self.providers:
            return {}
        stats: dict[str, float] = {}
        experience = self._experience(fields)
        sums = self._episode_intrinsic.setdefault(traj.episode, {})
        for name, provider in self.providers.items():
            rewards = provider.evaluate(experience) * np.float32(provider.strength)
            sums[name] = sums.get(name, 0.0) + float(np.sum(rewards))
            if traj.done:
                stats[f"Policy/{provider.stat_name} Reward"] = sums[name]
        if traj.done:
            self._episode_intrinsic.pop(traj.episode, None)
        return stats

    def forget_episodes(self) -> None:
        """After a RESET or a simulator restart the unfinished episodes never continue: drop their
        intrinsic reward sums and critic memories."""
        self._episode_intrinsic.clear()
        self._critic_memory.clear()

    # ------------------------------------------------------------------ update
    def _updates_due(self) -> bool:
        h = self.hyperparams
        return (self.step - h.buffer_init_steps) / self.update_steps > h.steps_per_update

    def _reward_signal_updates_due(self) -> bool:
        h = self.hyperparams
        return bool(self.providers) and (
            (self.step - h.buffer_init_steps) / self.reward_signal_update_steps > h.reward_signal_steps_per_update)

    def ready_to_update(self) -> bool:
        h = self.hyperparams
        return (len(self.buffer) >= h.batch_size and self.step >= h.buffer_init_steps
                and (self._updates_due() or self._reward_signal_updates_due()))

    def learning_rate(self) -> float:
        h = self.hyperparams
        return decay(h.learning_rate_schedule, h.learning_rate, LEARNING_RATE_FLOOR, self.step, h.max_steps)

    def update(self, rows: int | None = None) -> dict[str, float]:
        """Gradient steps until they caught up with the agent steps (one per steps_per_update).

        ``rows`` is the data-parallel ranks' agreed buffer length (trainer/distributed.py); SAC
        runs as one rank only (several are refused at start), where it is always None."""
        learning_rate = self.learning_rate()
        for optimizer in (self.policy_optimizer, self.value_optimizer, self.entropy_optimizer):
            optimizer.param_groups[0]["lr"] = learning_rate
        actor_body = self.policy.actor.network_body
        for network in (self.critic, self.target_network, self.q_network.q1_network, self.q_network.q2_network):
            copy_normalization(actor_body, network.network_body)
        collected: dict[str, list[float]] = {}
        while self._updates_due():
            stats = self.gradient_step(self._sample())
            if self.behavioral_cloning is not None:  # after every gradient step, as the reference does
                stats.update(self.behavioral_cloning.update(self.step))
            for key, value in stats.items():
                collected.setdefault(key, []).append(value)
            self.update_steps += 1
        # then the reward-signal learners catch up, on minibatches of their own (the reference
        # updates them after the policy, at their own pace: reward_signal_steps_per_update)
        while self._reward_signal_updates_due():
            experience = self._experience(self._sample())
            for provider in self.providers.values():
                for key, value in provider.update(experience).items():
                    collected.setdefault(key, []).append(value)
            self.reward_signal_update_steps += 1
        result = {key: float(np.mean(values)) for key, values in collected.items()}
        result["Policy/Learning Rate"] = learning_rate
        return result

    def _sample(self) -> dict[str, np.ndarray]:
        """A minibatch of ``batch_size`` rows: single experiences, or with memory whole sequences
        (batch_size // sequence_length of them, at least one, as the reference)."""
        size, step = self.hyperparams.batch_size, self.sequence_length
        if step == 1:
            return self.buffer.sample(size, self.sample_generator)
        return self.buffer.sample_sequences(max(size // step, 1), step, self.sample_generator)

    def _rewards(self, batch: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Each signal's reward x strength of the minibatch's rows, float32 [n]: the stored
        environment reward, or the provider's current reward of the experiences."""
        experience = self._experience(batch) if self.providers else None
        rewards = {}
        for name, (_, strength) in self.hyperparams.reward_signals.items():
            provider = self.providers.get(name)
            rewards[name] = (batch["rewards"] if provider is None else provider.evaluate(experience)
                             ) * np.float32(strength)
        return rewards

    def gradient_step(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One SAC step on a sampled minibatch (numpy columns of the replay buffer): in numpy
        (numpy_step.py) for vector observations without memory, else in torch autograd."""
        if self._numpy_step is not None:
            return self._numpy_step.step(batch, self._rewards(batch))
        return self._torch_gradient_step(batch)

    def _torch_gradient_step(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One SAC step in torch autograd (memory, visual observations, a GPU; the reference
        for numpy_step.py in the tests).

        With memory the rows are sequences: the policy starts each from its stored memory, V
        from the stored critic memory, Q1 and Q2 from zero (the reference's choice: they have
        no memory at inference), and the target V from V's memory one step in; the losses
        average over the unpadded rows only."""
        spec = self.behavior_spec.action_spec
        n_obs = len(self.behavior_spec.observation_specs)
        t = {key: torch.as_tensor(value, device=self.device) for key, value in batch.items()}
        obs = [t[_obs_key(i)] for i in range(n_obs)]
        next_obs = [t[_next_obs_key(i)] for i in range(n_obs)]
        allowed = (~t["action_masks"]).float() if self.branches else None
        step = self.sequence_length
        if self.hyperparams.memory_size:
            memories = t["memory"][::step].unsqueeze(0)
            value_memories = t["critic_memory"][::step].unsqueeze(0)
            q_memories = torch.zeros_like(value_memories)

            def run(network, inputs, actions=None, start=q_memories):
                return network.forward_memory(inputs, start, step, actions)[0]

            with torch.no_grad():
                next_memories = self.critic.forward_memory([o[::step] for o in obs], value_memories, 1)[1]
        else:
            memories = value_memories = next_memories = None

            def run(network, inputs, actions=None, start=None):
                return network(inputs, actions)

        actions, cont_log_probs, probs, all_log_probs, entropy = self.policy.sample_with_grad(
            obs, allowed, self.noise_generator, memories, step)
        stored = t["continuous_actions"] if spec.continuous_size else None
        q1, q2 = self.q_network.q1_network, self.q_network.q2_network
        # Q1 of the policy's own actions with Q1's parameters held constant: the policy loss's
        # gradient reaches the policy only, so one backward pass serves all three losses
        for p in self._q1_params:
            p.requires_grad_(False)
        try:
            q1_policy = run(q1, obs, actions)
        finally:
            for p in self._q1_params:
                p.requires_grad_(True)
        with torch.no_grad():
            q2_policy = run(q2, obs, actions)
            next_values = run(self.target_network, next_obs, start=next_memories)
        q1_taken, q2_taken = run(q1, obs, stored), run(q2, obs, stored)
        values = run(self.critic, obs, start=value_memories)
        names = list(self.hyperparams.reward_signals)
        rewards = {name: torch.as_tensor(r, device=self.device) for name, r in self._rewards(batch).items()}
        if self.hyperparams.memory_size:  # from here on, the unpadded rows only
            keep = t["masks"] > 0

            def real(x):
                return None if x is None else {k: v[keep] for k, v in x.items()} if isinstance(x, dict) else x[keep]

            q1_policy, q2_policy, next_values, q1_taken, q2_taken, values, rewards = map(
                real, (q1_policy, q2_policy, next_values, q1_taken, q2_taken, values, rewards))
            cont_log_probs, probs, all_log_probs = map(real, (cont_log_probs, probs, all_log_probs))
            entropy = entropy[keep.cpu().numpy()]
            t = {key: t[key][keep] for key in ("done", "discrete_actions")}
        alpha_c = self.log_ent_coef.continuous.exp().detach() if spec.continuous_size else None
        alpha_d = self.log_ent_coef.discrete.exp().detach() if self.branches else None
        q1_losses, q2_losses, value_losses = [], [], []
        for name in names:
            gamma = self.hyperparams.reward_signals[name][0]
            provider = self.providers.get(name)
            backup = losses.q_backup(rewards[name], t["done"], next_values[name], gamma,
                                     use_dones=provider is None or not provider.ignore_done)
            taken1, taken2 = q1_taken[name], q2_taken[name]
            if self.branches:
                discrete = t["discrete_actions"]
                taken1 = losses.chosen_q(taken1, discrete, self.branches)
                taken2 = losses.chosen_q(taken2, discrete, self.branches)
            q1_losses.append(losses.q_loss(taken1, backup))
            q2_losses.append(losses.q_loss(taken2, backup))
            v_target = losses.value_target(q1_policy[name], q2_policy[name], cont_log_probs, alpha_c,
                                           probs, all_log_probs, alpha_d, self.branches)
            value_losses.append(0.5 * torch.mean((values[name] - v_target) ** 2))
        q1_loss, q2_loss = torch.stack(q1_losses).mean(), torch.stack(q2_losses).mean()
        value_loss = torch.stack(value_losses).mean()
        mean_q1_policy = torch.stack([q1_policy[name] for name in names]).mean(dim=0)
        policy_loss = losses.policy_loss(mean_q1_policy, cont_log_probs, alpha_c, probs, all_log_probs,
                                         alpha_d, self.branches)
        entropy_loss = losses.entropy_loss(
            self.log_ent_coef.continuous, None if cont_log_probs is None else cont_log_probs.detach(),
            self.target_entropy[0], self.log_ent_coef.discrete,
            None if probs is None else probs.detach(), None if all_log_probs is None else all_log_probs.detach(),
            self.target_entropy[1], self.branches)

        # each loss reaches only its own parameters (targets and alphas are constants in the
        # others), so the sum's gradient is each optimiser's own
        optimizers = (self.policy_optimizer, self.value_optimizer, self.entropy_optimizer)
        for optimizer in optimizers:
            optimizer.zero_grad()
        (policy_loss + q1_loss + q2_loss + value_loss + entropy_loss).backward()
        for optimizer in optimizers:
            optimizer.step()
        losses.soft_update(self._critic_params, self._target_params, self.hyperparams.tau)
        stats = {
            "Losses/Policy Loss": policy_loss.item(),
            "Losses/Value Loss": value_loss.item(),
            "Losses/Q1 Loss": q1_loss.item(),
            "Losses/Q2 Loss": q2_loss.item(),
            "Policy/Entropy": float(np.mean(entropy)),
        }
        if spec.continuous_size:
            stats["Policy/Continuous Entropy Coeff"] = float(self.log_ent_coef.continuous.detach().exp().mean())
        if self.branches:
            stats["Policy/Discrete Entropy Coeff"] = float(self.log_ent_coef.discrete.detach().exp().mean())
        return stats

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict[str, Any]:
        """checkpoint.pt content: the reference's keys, plus the entropy coefficients (which the
        reference does not save), the update counter and the generators (``RNG``)."""
        bc = {} if self.behavioral_cloning is None else self.behavioral_cloning.state_dict()
        return {
            **bc,
            "Policy": self.policy.actor.state_dict(),
            "global_step": {"step": torch.tensor(self.step, dtype=torch.int64)},
            "Optimizer:q_network": self.q_network.state_dict(),
            "Optimizer:value_network": self.critic.state_dict(),
            "Optimizer:target_network": self.target_network.state_dict(),
            "Optimizer:policy_optimizer": self.policy_optimizer.state_dict(),
            "Optimizer:value_optimizer": self.value_optimizer.state_dict(),
            "Optimizer:entropy_optimizer": self.entropy_optimizer.state_dict(),
            "Optimizer:entropy_coefficients": self.log_ent_coef.state_dict(),
            "SAC": {"update_steps": torch.tensor(self.update_steps, dtype=torch.int64),
                    "reward_signal_update_steps": torch.tensor(self.reward_signal_update_steps, dtype=torch.int64)},
            "RNG": {
                "policy_sampling": self.policy.generator.get_state(),
                "policy_noise": torch.from_numpy(noise_state(self.policy.sampler.noise)),
                "replay_sampling": self.sample_generator.get_state(),
                "update_noise": self.noise_generator.get_state(),
            },
            **{key: value for provider in self.providers.values() for key, value in provider.state_dict().items()},
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if "Optimizer:q_network" not in state:
            raise KeyError("the checkpoint has no SAC networks (Optimizer:q_network); was it written by PPO?")
        self.policy.actor.load_state_dict(state["Policy"])
        self.q_network.load_state_dict(state["Optimizer:q_network"])
        self.critic.load_state_dict(state["Optimizer:value_network"])
        self.target_network.load_state_dict(state["Optimizer:target_network"])
        self.policy_optimizer.load_state_dict(state["Optimizer:policy_optimizer"])
        self.value_optimizer.load_state_dict(state["Optimizer:value_optimizer"])
        if "Optimizer:entropy_coefficients" in state:
            self.log_ent_coef.load_state_dict(state["Optimizer:entropy_coefficients"])
            self.entropy_optimizer.load_state_dict(state["Optimizer:entropy_optimizer"])
        self.step = int(state["global_step"]["step"])
        sac = state.get("SAC")
        self.update_steps = (int(sac["update_steps"]) if sac is not None
                             else int(max(1, self.step / self.hyperparams.steps_per_update)))
        self.reward_signal_update_steps = (
            int(sac["reward_signal_update_steps"]) if sac is not None and "reward_signal_update_steps" in sac
            else int(max(1, self.step / self.hyperparams.reward_signal_steps_per_update)))
        load_providers(self.providers, state)
        if self.behavioral_cloning is not None and "Optimizer:BC" in state:
            self.behavioral_cloning.load_state_dict(state)
        rng = state.get("RNG")
        if rng is not None:
            self.policy.generator.set_state(rng["policy_sampling"])
            if "policy_noise" in rng:  # the numpy acting noise (numpy_policy.py); older checkpoints: none
                set_noise_state(self.policy.sampler.noise, rng["policy_noise"].numpy())
            self.sample_generator.set_state(rng["replay_sampling"])
            self.noise_generator.set_state(rng["update_noise"])

    def restart_counters(self) -> None:
        """--initialize-from: the weights stay, the step and update counters start over."""
        self.step = 0
        self.update_steps = 1
        self.reward_signal_update_steps = 1

    @property
    def saves_replay_buffer(self) -> bool:
        return self.hyperparams.save_replay_buffer

    def replay_buffer_size(self) -> int:
        return len(self.buffer)

    def save_replay_buffer(self, path: str) -> None:
        self.buffer.save(path)

    def load_replay_buffer(self, path: str) -> None:
        self.buffer.load(path)

    def export_onnx(self, path: str) -> None:
        from trainer.artifacts.onnx_export import export_policy

        export_policy(self.policy, path)
