"""The settings the PPO room needs, as one frozen dataclass.

The run loop maps the typed ML-Agents configuration (``trainer/config``) onto this, so the PPO code
never depends on how YAML is parsed. Defaults are ML-Agents' PPO defaults.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class SignalNetwork:
    """An intrinsic reward signal's own learner (its ``learning_rate`` and ``network_settings``)."""

    learning_rate: float = 3.0e-4
    hidden_units: int = 128
    num_layers: int = 2
    normalize: bool = False
    vis_encode_type: str = "simple"
    use_actions: bool = False  # gail: the discriminator also sees the actions and done flags
    use_vail: bool = False  # gail: variational bottleneck


@dataclass(frozen=True)
class PPOHyperparams:
    batch_size: int = 1024  # experiences per minibatch
    buffer_size: int = 10240  # an update runs once the buffer holds MORE than this many experiences
    learning_rate: float = 3.0e-4  # initial Adam learning rate
    beta: float = 5.0e-3  # initial entropy-bonus coefficient
    epsilon: float = 0.2  # initial PPO clip range (policy ratio and value trust region)
    lambd: float = 0.95  # GAE lambda
    num_epoch: int = 3  # passes over the buffer per update
    shared_critic: bool = False  # value heads on the actor's body instead of a separate critic
    learning_rate_schedule: str = "linear"  # "linear" decays to 1e-10 over max_steps, "constant" keeps it
    beta_schedule: str = "linear"  # floor 1e-5
    epsilon_schedule: str = "linear"  # floor 0.1
    max_steps: int = 500_000  # agent-steps; the decay horizon
    normalize: bool = False  # running normalisation of vector observations
    hidden_units: int = 128
    num_layers: int = 2
    vis_encode_type: str = "simple"  # simple | nature_cnn | resnet | match3 | fully_connected
    deterministic: bool = False  # act with the mean / argmax instead of sampling
    # network_settings.memory: an LSTM (hidden memory_size / 2) after the hidden layers; 0 = none
    memory_size: int = 0
    sequence_length: int = 64  # with memory: experiences per training sequence
    # reward signal name (e.g. "extrinsic") -> (gamma, strength)
    reward_signals: dict[str, tuple[float, float]] = field(
        default_factory=lambda: {"extrinsic": (0.99, 1.0)}
    )
    # curiosity / rnd -> the network that computes that signal's reward (reward_providers.py)
    reward_signal_networks: dict[str, SignalNetwork] = field(default_factory=dict)
