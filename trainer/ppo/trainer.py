"""PPOTrainer: turns trajectories into buffered experiences and runs the PPO update.

One trainer per brain. The run loop calls ``process_trajectory`` for every finished or cut trajectory,
then ``update`` whenever ``ready_to_update`` says the buffer holds more than buffer_size experiences.
"""
from __future__ import annotations

import logging
from itertools import chain
from typing import Any

import numpy as np
import torch

from trainer.common import numpy_net
from trainer.ppo import numpy_update
from trainer.common.adam import Adam
from trainer.common.trajectory import Trajectory
from trainer.ppo.update_buffer import UpdateBuffer
from trainer.common.numpy_net import NumpyCritic
from trainer.common.gae import gae
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.masked import masked_mean
from trainer.ppo.losses import policy_loss, ppo_loss, value_loss
from trainer.common.networks import Critic
from trainer.common.policy import Policy
from trainer.common.recurrent_critic import RecurrentCriticValues
from trainer.common.reward_providers import Experience, load_providers, make_providers
from trainer.common.schedules import BETA_FLOOR, EPSILON_FLOOR, LEARNING_RATE_FLOOR, decay
from trainer.common.numpy_policy import noise_state, set_noise_state
from trainer.common.trainer_interface import Trainer
from protos.types import BehaviorSpec

ADVANTAGE_STD_EPSILON = 1e-10
logger = logging.getLogger("mlagents_like")


def _obs_key(index: int) -> str:
    return f"obs_{index}"


def _next_obs_key(index: int) -> str:
    return f"next_obs_{index}"


def normalize_advantages(advantages: np.ndarray, sum_across_ranks=None) -> np.ndarray:
    """(A - mean) / (std + 1e-10) over the whole buffer. float [N] -> float32 [N].
    ``sum_across_ranks``: data-parallel ranks (trainer/distributed.py) sum (N, sum A, sum A^2)
    over their buffers, so that every rank uses the mean and std of all of them."""
    if sum_across_ranks is None:
        return ((advantages - advantages.mean()) / (advantages.std() + ADVANTAGE_STD_EPSILON)).astype(np.float32)
    a = np.asarray(advantages, dtype=np.float64)
    n, total, squares = sum_across_ranks(np.array([a.size, a.sum(), np.square(a).sum()]))
    mean = total / n
    std = np.sqrt(max(squares / n - mean * mean, 0.0))
    return ((a - mean) / (std + ADVANTAGE_STD_EPSILON)).astype(np.float32)


class PPOTrainer(RecurrentCriticValues, Trainer):
    """PPO for one brain: ``policy`` acts, the critic estimates values, one Adam updates both."""

    def __init__(self, brain_name: str, behavior_spec: BehaviorSpec, hyperparams: PPOHyperparams,
                 seed: int, device: str = "cpu", use_numpy_update: bool = True):
        super().__init__(brain_name, behavior_spec, hyperparams, device)
        self.policy = Policy(behavior_spec, hyperparams, seed, device)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed + 2)
            self.critic = self._make_critic().to(self.device)
        trainable = [
            p for p in chain(self.policy.actor.parameters(), self.critic.parameters()) if p.requires_grad
        ]
        self.optimizer = Adam(trainable, lr=hyperparams.learning_rate)  # adam.py says why not torch.optim
        # curiosity / rnd: their own networks and optimizers (reward_providers.py)
        self.providers = make_providers(behavior_spec, hyperparams.reward_signals,
                                        hyperparams.reward_signal_networks, seed + 4)
        self._needs_next_obs = any(p.needs_next_obs for p in self.providers.values())
        self._needs_done = any(p.needs_done for p in self.providers.values())  # gail with use_actions
        self._episode_intrinsic: dict[Any, dict[str, float]] = {}  # episode -> reward sums so far
        # LSTM: experiences train in sequences of this length; the critic's memory at the end of an
        # episode's last trajectory is where its next trajectory starts
        self.sequence_length = hyperparams.sequence_length if hyperparams.memory_size else 1
        self._critic_memory: dict[Any, np.ndarray] = {}  # episode -> float32 [memory_size]
        self.shuffle_generator = torch.Generator()
        self.shuffle_generator.manual_seed(seed + 3)
        self.buffer = UpdateBuffer()
        self.step = 0
        # minibatch steps in numpy for vector-observation networks on the CPU (numpy_update.py);
        # MLAGENTS_LIKE_NUMPY_UPDATE=0 (``use_numpy_update`` False) keeps autograd
        self.numpy_update = use_numpy_update
        # value estimates of vector-observation critics in numpy: no per-trajectory torch op overhead
        self._numpy_critic = NumpyCritic(self.critic) if (
            isinstance(self.critic, Critic) and numpy_net.supports(self.critic, recurrent=True)
            and self.device.type == "cpu") else None
        self._numpy_ppo: numpy_update.NumpyPPO | None = None  # built at the first numpy update
        self._rows: int | None = None  # ``update``'s rows
        # data-parallel ranks (trainer/distributed.py ``Ranks.wire``): sums a float64 vector over
        # the ranks, for the advantages' mean and std over all ranks' buffers; None alone
        self.sum_across_ranks = None
        # behavioral_cloning (trainer/behavioral_cloning.py), set by behavior.make_trainer: one round
        # of cloning after each PPO update
        self.behavioral_cloning = None

    def _make_critic(self) -> torch.nn.Module:
        """PPO's critic (a POCA trainer builds its centralised one instead)."""
        h = self.hyperparams
        return Critic(self.behavior_spec.observation_specs, list(h.reward_signals), h,
                      shared_body=self.policy.actor.network_body if h.shared_critic else None)

    # ------------------------------------------------------------------ experience
    def _tensors(self, arrays: list[np.ndarray]) -> list[torch.Tensor]:
        return [torch.as_tensor(np.asarray(a, dtype=np.float32), device=self.device) for a in arrays]

    def _value_estimates(self, traj: Trajectory) -> tuple[dict[str, np.ndarray], dict[str, float]]:
        """Current-critic values for obs [T] and next_obs, in one batch: (values [T] per signal, V(next))."""
        both = [np.concatenate([o, n[None]], axis=0) for o, n in zip(traj.obs, traj.next_obs)]
        if self._numpy_critic is not None:
            estimates = self._numpy_critic(both)
            return ({name: v[:-1] for name, v in estimates.items()},
                    {name: float(v[-1]) for name, v in estimates.items()})
        with torch.inference_mode():
            estimates = self.critic(self._tensors(both))
        values = {name: v[:-1].cpu().numpy() for name, v in estimates.items()}
        next_values = {name: float(v[-1]) for name, v in estimates.items()}
        return values, next_values

    def process_trajectory(self, traj: Trajectory) -> dict[str, float]:
        """Normalise, estimate values, compute GAE per reward signal, and buffer the experiences."""
        length = len(traj)
        if self.hyperparams.normalize:
            # in torch, not numpy: the same float32 sums as ML-Agents (the interop test checks
            # the statistics bit for bit); the numpy actor/critic re-read only the normalisers
            obs_tensors = self._tensors(traj.obs)
            self.policy.actor.update_normalization(obs_tensors)
            self.critic.update_normalization(obs_tensors)
        if self.hyperparams.memory_size:
            values, next_values, critic_memories = self._value_estimates_by_sequence(traj)
        else:
            values, next_values = self._value_estimates(traj)
        terminal = traj.done and not traj.interrupted
        fields: dict[str, np.ndarray] = {_obs_key(i): np.asarray(o, np.float32) for i, o in enumerate(traj.obs)}
        experience = self._provider_experience(traj, fields)
        advantages = []
        stats: dict[str, float] = {}
        for name, (gamma, strength) in self.hyperparams.reward_signals.items():
            provider = self.providers.get(name)
            rewards, bootstrap = self._signal_rewards(name, strength, traj, experience, terminal, next_values[name],
                                                      stats)
            advantage, returns = gae(rewards, values[name], bootstrap, gamma, self.hyperparams.lambd)
            advantages.append(advantage)
            fields[f"values:{name}"] = values[name]
            fields[f"returns:{name}"] = returns
            label = name.capitalize() if provider is None else provider.stat_name
            stats[f"Policy/{label} Value Estimate"] = float(np.mean(values[name]))
        if traj.done:
            self._episode_intrinsic.pop(traj.episode, None)
        fields["advantages"] = (advantages[0] if len(advantages) == 1  # the mean of one row is that row
                                else np.mean(np.stack(advantages), axis=0)).astype(np.float32)
        self._add_action_fields(traj, fields)
        if self.hyperparams.memory_size:
            fields = self._in_whole_sequences(traj, fields, critic_memories)
        self.buffer.append(fields)
        self.step += length
        return stats

    def _add_action_fields(self, traj: Trajectory, fields: dict[str, np.ndarray]) -> None:
        """The actions, their log-probabilities and the action masks of a trajectory's steps."""
        length = len(traj)
        fields["continuous_actions"] = np.asarray(traj.continuous_actions, np.float32).reshape(length, -1)
        fields["discrete_actions"] = np.asarray(traj.discrete_actions, np.int64).reshape(length, -1)
        fields["log_probs"] = np.asarray(traj.log_probs, np.float32).reshape(length, -1)
        mask_width = sum(self.behavior_spec.action_spec.discrete_branches)
        fields["action_masks"] = (
            np.zeros((length, mask_width), dtype=bool) if traj.action_masks is None
            else np.asarray(traj.action_masks, dtype=bool)
        )

    def _provider_experience(self, traj: Trajectory, fields: dict[str, np.ndarray]) -> Experience | None:
        """What curiosity / rnd / gail read of a trajectory (None without them); adds the next
        observations and the done flags to ``fields`` when one of them needs them."""
        if not self.providers:
            return None
        next_obs = None
        if self._needs_next_obs:  # what each step led to: the following step's obs, then next_obs
            next_obs = [np.concatenate([o[1:], n[None]], axis=0).astype(np.float32)
                        for o, n in zip(traj.obs, traj.next_obs)]
            fields.update({_next_obs_key(i): o for i, o in enumerate(next_obs)})
        done = None
        if self._needs_done:  # gail: 1 on the step that ended the episode
            done = np.zeros(len(traj), np.float32)
            done[-1] = float(traj.done)
            fields["done"] = done
        return Experience(traj.obs, next_obs, traj.continuous_actions, traj.discrete_actions, done=done)

    def _signal_rewards(self, name: str, strength: float, traj: Trajectory, experience: Experience | None,
                        terminal: bool, next_value: float, stats: dict[str, float]) -> tuple[np.ndarray, float]:
        """(rewards float32 [T] of reward signal ``name`` times its strength, the value its returns
        bootstrap from: 0 after a true terminal, except for a signal that ignores it). Intrinsic
        signals also sum their rewards per episode into ``stats`` when the episode ends."""
        provider = self.providers.get(name)
        if provider is None:
            return np.asarray(traj.rewards, dtype=np.float32) * np.float32(strength), 0.0 if terminal else next_value
        rewards = provider.evaluate(experience) * np.float32(strength)
        sums = self._episode_intrinsic.setdefault(traj.episode, {})
        sums[name] = sums.get(name, 0.0) + float(np.sum(rewards))
        if traj.done:
            stats[f"Policy/{provider.stat_name} Reward"] = sums[name]
        return rewards, next_value if provider.ignore_done or not terminal else 0.0

    def forget_episodes(self) -> None:
        """After a RESET or a simulator restart the unfinished episodes never continue: drop what
        was kept for them (critic memories, intrinsic reward sums)."""
        self._critic_memory.clear()
        self._episode_intrinsic.clear()

    # ------------------------------------------------------------------ update
    def ready_to_update(self) -> bool:
        return len(self.buffer) > self.hyperparams.buffer_size

    def current_schedule(self) -> tuple[float, float, float]:
        """(learning rate, beta, epsilon) decayed to the current step."""
        h = self.hyperparams
        return (
            decay(h.learning_rate_schedule, h.learning_rate, LEARNING_RATE_FLOOR, self.step, h.max_steps),
            decay(h.beta_schedule, h.beta, BETA_FLOOR, self.step, h.max_steps),
            decay(h.epsilon_schedule, h.epsilon, EPSILON_FLOOR, self.step, h.max_steps),
        )

    def _buffer_tensors(self) -> dict[str, Any]:
        data = self.buffer.concatenated()
        data["advantages"] = normalize_advantages(data["advantages"], self.sum_across_ranks)
        tensors = {key: torch.as_tensor(value, device=self.device) for key, value in data.items()}
        tensors["allowed"] = (~tensors.pop("action_masks")).float()
        return tensors

    def _minibatch_loss(self, batch: dict[str, torch.Tensor], beta: float, epsilon: float
                        ) -> tuple[torch.Tensor, dict[str, float]]:
        n_obs = len(self.behavior_spec.observation_specs)
        obs = [batch[_obs_key(i)] for i in range(n_obs)]
        allowed = batch["allowed"] if self.behavior_spec.action_spec.discrete_branches else None
        mask = None
        if self.hyperparams.memory_size:  # rows are whole sequences; each starts from its stored memories
            step = self.sequence_length
            mask = batch["masks"]
            log_probs, entropy = self.policy.evaluate(
                obs, allowed, batch["continuous_actions"], batch["discrete_actions"],
                batch["memory"][::step].unsqueeze(0), step)
            values, _ = self.critic.forward_memory(obs, batch["critic_memory"][::step].unsqueeze(0), step)
        else:
            log_probs, entropy = self.policy.evaluate(
                obs, allowed, batch["continuous_actions"], batch["discrete_actions"]
            )
            values = self.critic(obs)
        names = list(values)
        policy_term = policy_loss(batch["advantages"], log_probs, batch["log_probs"], epsilon, mask)
        # The reference's trust region is anchored at the *returns*, not at the old value estimates:
        # in mlagents 1.1.0 RewardSignalUtil.value_estimates_key(name) is the returns key, so
        # _process_trajectory's value estimates are overwritten by the returns and the update reads
        # the returns as "old values". max((R-V)^2, clip(V-R, +-eps)^2) is then (R-V)^2: the critic
        # is not held to +-epsilon per update. We reproduce that (measured: anchoring at the real
        # old values learned ball3d measurably slower than mlagents-learn on the same stub).
        returns = {n: batch[f"returns:{n}"] for n in names}
        value_term = value_loss(values, returns, returns, epsilon, mask)
        loss = ppo_loss(policy_term, value_term, entropy, beta, mask)
        return loss, {
            "Losses/Policy Loss": abs(policy_term.item()),
            "Losses/Value Loss": value_term.item(),
            "Policy/Entropy": masked_mean(entropy, mask).item(),
        }

    def update(self, rows: int | None = None) -> dict[str, float]:
        """num_epoch passes of shuffled minibatches over ALL buffered experiences; then clear the buffer.

        ``rows``: data-parallel ranks (trainer/distributed.py) must all take the same number of
        minibatch steps: each epoch then shuffles the whole buffer but steps only the minibatches
        that ``rows`` experiences (the smallest buffer of all ranks) fill."""
        self._rows = rows
        learning_rate, beta, epsilon = self.current_schedule()
        for group in self.optimizer.param_groups:
            group["lr"] = learning_rate
        collected: dict[str, list[float]] = {}
        if self.numpy_update and numpy_update.supports(self):
            self._update_numpy(learning_rate, beta, epsilon, collected)
        else:
            self._update_torch(beta, epsilon, collected)
        result = self._finish_update(collected, learning_rate, beta, epsilon)
        if self.behavioral_cloning is not None:
            result.update(self.behavioral_cloning.update(self.step))
        return result

    def _update_torch(self, beta: float, epsilon: float, collected: dict[str, list[float]]) -> None:
        """Autograd through the torch modules (recurrent, visual or shared-body networks, or
        MLAGENTS_LIKE_NUMPY_UPDATE=0), stepped by the same Adam."""
        data = self._buffer_tensors()
        for order in self._minibatch_indices():
            index = order.to(self.device)
            batch = {k: v[index] for k, v in data.items()}
            loss, stats = self._minibatch_loss(batch, beta, epsilon)
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            stats.update(self._update_providers(batch))
            for key, value in stats.items():
                collected.setdefault(key, []).append(value)

    def _update_providers(self, batch: dict[str, Any]) -> dict[str, float]:
        """One step of every curiosity / rnd learner on a PPO minibatch (numpy or torch columns)."""
        if not self.providers:
            return {}
        n_obs = len(self.behavior_spec.observation_specs)
        experience = Experience(
            [batch[_obs_key(i)] for i in range(n_obs)],
            [batch[_next_obs_key(i)] for i in range(n_obs)] if self._needs_next_obs else None,
            batch["continuous_actions"], batch["discrete_actions"], batch.get("masks"), batch.get("done"))
        stats: dict[str, float] = {}
        for provider in self.providers.values():
            stats.update(provider.update(experience))
        return stats

    def _minibatch_indices(self):
        """num_epoch shuffles of the buffer (the seeded shuffle generator), cut into full minibatches.

        With memory the shuffle moves whole sequences and batch_size is rounded down to a multiple
        of sequence_length (at least one sequence), as in the reference."""
        length, step = len(self.buffer), self.sequence_length
        rows = min(length, self._rows or length)
        batch_size = max(self.hyperparams.batch_size - self.hyperparams.batch_size % step, step)
        within = torch.arange(step)
        for _ in range(self.hyperparams.num_epoch):
            order = torch.randperm(length // step, generator=self.shuffle_generator)
            if step > 1:
                order = (order[:, None] * step + within).reshape(-1)
            for start in range(0, (rows // batch_size) * batch_size, batch_size):
                yield order[start:start + batch_size]

    def _update_numpy(self, learning_rate: float, beta: float, epsilon: float,
                      collected: dict[str, list[float]]) -> None:
        """The same minibatches (same shuffles) as the torch path, stepped by NumpyPPO."""
        data = self.buffer.concatenated()
        data["advantages"] = normalize_advantages(data["advantages"], self.sum_across_ranks)
        masks = data.pop("action_masks")
        if self.behavior_spec.action_spec.discrete_branches:
            data["allowed"] = (~masks).astype(np.float32)
        n_obs = len(self.behavior_spec.observation_specs)
        obs = [data.pop(_obs_key(i)) for i in range(n_obs)]
        provider_columns = {}  # what only curiosity / rnd read: not indexed per minibatch without them
        if self.providers:
            provider_columns = {_obs_key(i): o for i, o in enumerate(obs)}
            provider_columns.update({k: data.pop(k) for k in [*(_next_obs_key(i) for i in range(n_obs)), "done"]
                                     if k in data})
        if self._numpy_ppo is None:
            self._numpy_ppo = numpy_update.NumpyPPO(self.policy.numpy_actor, self._numpy_critic, self.optimizer)
        stepper = self._numpy_ppo
        actor_in, critic_in = stepper.prepare(obs)
        orders = [order.numpy() for order in self._minibatch_indices()]
        results = stepper.run(data, actor_in, critic_in, orders, learning_rate, beta, epsilon)
        if self.providers:  # curiosity / rnd: networks of their own, on the same minibatches
            columns = {**data, **provider_columns}
            for stats, index in zip(results, orders):
                batch = {k: v[index] for k, v in columns.items()}
                stats.update(self._update_providers(batch))
        for stats in results:
            for key, value in stats.items():
                collected.setdefault(key, []).append(value)

    def _finish_update(self, collected: dict[str, list[float]], learning_rate: float, beta: float,
                       epsilon: float) -> dict[str, float]:
        self.buffer.clear()
        result = {key: float(np.mean(values)) for key, values in collected.items()}
        result.update({"Policy/Learning Rate": learning_rate, "Policy/Epsilon": epsilon, "Policy/Beta": beta})
        return result

    # ------------------------------------------------------------------ persistence
    def optimizers(self) -> list[Adam]:
        """Every optimiser of this brain: PPO's, each curiosity / rnd / gail learner's, then
        behavioral cloning's."""
        bc = [] if self.behavioral_cloning is None else [self.behavioral_cloning.optimizer]
        return [self.optimizer, *(p.optimizer for p in self.providers.values()), *bc]

    def normalizers(self) -> list:
        """Every observation normaliser of the actor, the critic and the curiosity / rnd networks
        (a shared body's once), in a fixed order."""
        from trainer.common.normalizer import Normalizer

        modules = [self.policy.actor, self.critic]
        modules += [module for p in self.providers.values() for module in p.modules()]
        seen, found = set(), []
        for module in modules:
            for m in module.modules():
                if isinstance(m, Normalizer) and id(m) not in seen:
                    seen.add(id(m))
                    found.append(m)
        return found

    def state_dict(self) -> dict[str, Any]:
        """checkpoint.pt content: ML-Agents' keys plus ``RNG`` (generator states as uint8 tensors).

        Tensors are live references; save (or copy) before the next update.
        """
        state = {
            "Policy": self.policy.actor.state_dict(),
            "global_step": {"step": torch.tensor(self.step, dtype=torch.int64)},
            "Optimizer:value_optimizer": self.optimizer.state_dict(),
            "Optimizer:critic": self.critic.state_dict(),
            "RNG": {
                "policy_sampling": self.policy.generator.get_state(),
                "policy_noise": torch.from_numpy(noise_state(self.policy.sampler.noise)),
                "minibatch_shuffle": self.shuffle_generator.get_state(),
            },
        }
        for provider in self.providers.values():
            state.update(provider.state_dict())
        if self.behavioral_cloning is not None:
            state.update(self.behavioral_cloning.state_dict())
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.policy.actor.load_state_dict(state["Policy"])
        critic_state, own = state["Optimizer:critic"], self.critic.state_dict()
        changed = set(own) ^ set(critic_state)
        if changed and all(key.startswith("value_heads.") for key in changed):
            # reward signals were added or removed since the checkpoint: keep everything else
            signals = sorted({key.split(".")[1] for key in changed})
            self.critic.load_state_dict({k: v for k, v in critic_state.items() if k in own}, strict=False)
            logger.warning("The reward signals differ from the checkpoint's (%s): value heads of new signals "
                           "and the optimizer's moments start fresh.", ", ".join(signals))
        else:
            self.critic.load_state_dict(critic_state)
            self.optimizer.load_state_dict(state["Optimizer:value_optimizer"])
        self.step = int(state["global_step"]["step"])
        load_providers(self.providers, state)
        if self.behavioral_cloning is not None:
            if "Optimizer:BC" in state:
                self.behavioral_cloning.load_state_dict(state)
            else:
                logger.warning("The checkpoint has no behavioral cloning state: its optimizer starts fresh.")
        rng = state.get("RNG")
        if rng is not None:
            self.policy.generator.set_state(rng["policy_sampling"])
            if "policy_noise" in rng:  # the numpy acting noise (numpy_policy.py); older checkpoints: none
                set_noise_state(self.policy.sampler.noise, rng["policy_noise"].numpy())
            self.shuffle_generator.set_state(rng["minibatch_shuffle"])

    def restart_counters(self) -> None:
        """--initialize-from: the weights stay, the step count starts over."""
        self.step = 0

    def export_onnx(self, path: str) -> None:
        from trainer.artifacts.onnx_export import export_policy

        export_policy(self.policy, path)
