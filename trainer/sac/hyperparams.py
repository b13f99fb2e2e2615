"""The settings the SAC room needs, as one frozen dataclass (defaults: ML-Agents' SAC defaults).

The network fields have the names and meaning of ``PPOHyperparams``' (trainer/ppo/hyperparams.py),
so the networks of trainer/common/networks.py build from either.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from trainer.ppo.hyperparams import SignalNetwork


@dataclass(frozen=True)
class SACHyperparams:
    batch_size: int = 128  # experiences per gradient step, sampled uniformly from the replay buffer
    buffer_size: int = 50_000  # replay buffer capacity; the oldest experiences are overwritten
    learning_rate: float = 3.0e-4  # Adam learning rate of the policy, value and entropy optimisers
    learning_rate_schedule: str = "constant"  # or "linear" (decays to 1e-10 over max_steps)
    buffer_init_steps: int = 0  # agent steps collected before the first gradient step
    tau: float = 0.005  # target value network: target = tau * value + (1 - tau) * target per step
    steps_per_update: float = 1.0  # agent steps per gradient step
    save_replay_buffer: bool = False  # write the replay buffer beside every checkpoint
    init_entcoef: float = 1.0  # initial entropy coefficient (alpha) of every action branch
    reward_signal_steps_per_update: float = 1.0  # agent steps per reward-signal update
    max_steps: int = 500_000  # agent steps; the decay horizon of a linear schedule
    normalize: bool = False
    hidden_units: int = 128
    num_layers: int = 2
    vis_encode_type: str = "simple"
    deterministic: bool = False
    # network_settings.memory: an LSTM in every network (networks.py); 0 = none
    memory_size: int = 0
    sequence_length: int = 64  # with memory: experiences per sampled sequence
    # reward signal name -> (gamma, strength)
    reward_signals: dict[str, tuple[float, float]] = field(default_factory=lambda: {"extrinsic": (0.99, 1.0)})
    # curiosity / rnd (/ any provider of trainer/common/reward_providers.py) -> its own network
    reward_signal_networks: dict[str, SignalNetwork] = field(default_factory=dict)
