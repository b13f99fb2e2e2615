"""Typed, frozen run configuration in the ML-Agents Release-22 schema (docs/configuration.md, "Command
line" and "YAML").

Field order is the order ``configuration.yaml`` is written in, which follows the reference.
Every default is the reference default. Building these from YAML (with all the checks) is
``trainer.config.loader``'s job; constructing them directly skips the checks.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from dataclasses import dataclass, field
from typing import Any, ClassVar

from trainer.config.env_params import EnvironmentParameterSettings, environment_parameters_as_dict
from trainer.errors import ConfigError

logger = logging.getLogger("mlagents_like")

SCHEDULES = ("linear", "constant")
ENCODER_TYPES = ("simple", "nature_cnn", "resnet", "match3", "fully_connected")
# the smallest camera height and width each vis_encode_type takes (ML-Agents' limits)
ENCODER_MIN_SIZE = {"simple": 20, "nature_cnn": 36, "resnet": 15, "match3": 5, "fully_connected": 1}
CONDITIONING_TYPES = ("hyper", "none")
TRAINER_TYPES = ("ppo", "sac", "poca")
TRAINABLE_TRAINER_TYPES = ("ppo", "sac", "poca")
DEFAULT_CHECKPOINT_NAME = "checkpoint.pt"


@dataclass(frozen=True)
class OnPolicySettings:
    """The hyperparameters PPO and MA-POCA share (``trainer_type: poca`` takes exactly these; as in
    ML-Agents, its beta/epsilon schedules do not follow learning_rate_schedule: docs/poca.md)."""

    batch_size: int = 1024
    buffer_size: int = 10240
    learning_rate: float = 3.0e-4
    beta: float = 5.0e-3
    epsilon: float = 0.2
    lambd: float = 0.95
    num_epoch: int = 3
    learning_rate_schedule: str = field(default="linear", metadata={"choices": SCHEDULES})
    beta_schedule: str = field(default="linear", metadata={"choices": SCHEDULES})
    epsilon_schedule: str = field(default="linear", metadata={"choices": SCHEDULES})


@dataclass(frozen=True)
class PPOSettings(OnPolicySettings):
    """``trainer_type: ppo``: the on-policy hyperparameters plus ``shared_critic``."""

    shared_critic: bool = False


@dataclass(frozen=True)
class SACSettings:
    """``trainer_type: sac`` hyperparameters (docs/configuration.md, "SAC"). ``steps_per_update`` and
    ``reward_signal_steps_per_update`` are agent steps per gradient step (floats allowed);
    ``reward_signal_steps_per_update`` None means: the same as ``steps_per_update``."""

    batch_size: int = 128
    buffer_size: int = 50000
    learning_rate: float = 3.0e-4
    learning_rate_schedule: str = field(default="constant", metadata={"choices": SCHEDULES})
    buffer_init_steps: int = 0
    tau: float = 0.005
    steps_per_update: float = 1.0
    save_replay_buffer: bool = False
    init_entcoef: float = 1.0
    reward_signal_steps_per_update: float | None = None

    def __post_init__(self) -> None:
        if self.reward_signal_steps_per_update is None:
            object.__setattr__(self, "reward_signal_steps_per_update", float(self.steps_per_update))


@dataclass(frozen=True)
class POCASettings(OnPolicySettings):
    """``trainer_type: poca``: the on-policy hyperparameters, without ``shared_critic``."""


#: trainer_type -> its hyperparameters class
HYPERPARAMETER_CLASSES: dict[str, type] = {"ppo": PPOSettings, "sac": SACSettings, "poca": POCASettings}


@dataclass(frozen=True)
class MemorySettings:
    """LSTM memory. memory_size holds h then c, each memory_size / 2 wide."""

    sequence_length: int = 64
    memory_size: int = 128


@dataclass(frozen=True)
class NetworkSettings:
    normalize: bool = False
    hidden_units: int = 128
    num_layers: int = 2
    vis_encode_type: str = field(default="simple", metadata={"choices": ENCODER_TYPES})
    memory: MemorySettings | None = None
    goal_conditioning_type: str = field(default="hyper", metadata={"choices": CONDITIONING_TYPES})
    deterministic: bool = False


@dataclass(frozen=True)
class RewardSignalSettings:
    """The ``extrinsic`` signal; the base of the others."""

    gamma: float = 0.99
    strength: float = 1.0
    network_settings: NetworkSettings = field(default_factory=NetworkSettings)


@dataclass(frozen=True)
class CuriositySettings(RewardSignalSettings):
    learning_rate: float = 3e-4
    encoding_size: int | None = None


@dataclass(frozen=True)
class RNDSettings(RewardSignalSettings):
    learning_rate: float = 1e-4
    encoding_size: int | None = None


@dataclass(frozen=True)
class GAILSettings(RewardSignalSettings):
    learning_rate: float = 3e-4
    encoding_size: int | None = None
    use_actions: bool = False
    use_vail: bool = False
    demo_path: str | None = None
    required_keys: ClassVar[tuple[str, ...]] = ("demo_path",)


REWARD_SIGNAL_CLASSES: dict[str, type] = {
    "extrinsic": RewardSignalSettings,
    "curiosity": CuriositySettings,
    "gail": GAILSettings,
    "rnd": RNDSettings,
}


@dataclass(frozen=True)
class BehavioralCloningSettings:
    demo_path: str
    steps: int = 0
    strength: float = 1.0
    samples_per_update: int = 0
    num_epoch: int | None = None
    batch_size: int | None = None
    required_keys: ClassVar[tuple[str, ...]] = ("demo_path",)


@dataclass(frozen=True)
class SelfPlaySettings:
    save_steps: int = 20000
    team_change: int | None = None  # None -> 5 * save_steps
    swap_steps: int = 2000
    window: int = 10
    play_against_latest_model_ratio: float = 0.5
    initial_elo: float = 1200.0

    def __post_init__(self) -> None:
        if self.team_change is None:
            object.__setattr__(self, "team_change", 5 * self.save_steps)


def _default_reward_signals() -> dict[str, RewardSignalSettings]:
    return {"extrinsic": RewardSignalSettings()}


@dataclass(frozen=True)
class TrainerSettings:
    trainer_type: str = "ppo"
    hyperparameters: OnPolicySettings | SACSettings = field(default_factory=PPOSettings)
    checkpoint_interval: int = 500000
    network_settings: NetworkSettings = field(default_factory=NetworkSettings)
    reward_signals: dict[str, RewardSignalSettings] = field(default_factory=_default_reward_signals)
    init_path: str | None = None
    keep_checkpoints: int = 5
    even_checkpoints: bool = False
    max_steps: int = 500000
    time_horizon: int = 64
    summary_freq: int = 50000
    threaded: bool = False
    self_play: SelfPlaySettings | None = None
    behavioral_cloning: BehavioralCloningSettings | None = None

    def __post_init__(self) -> None:
        if self.even_checkpoints and self.keep_checkpoints > 0:
            object.__setattr__(self, "checkpoint_interval", int(self.max_steps / self.keep_checkpoints))


@dataclass(frozen=True)
class EnvSettings:
    env_path: str | None = None
    env_args: list[str] | None = None
    base_port: int = 5005
    num_envs: int = 1
    num_areas: int = 1
    timeout_wait: int = 60
    seed: int = -1
    max_lifetime_restarts: int = 10
    restarts_rate_limit_n: int = 1
    restarts_rate_limit_period_s: int = 60
    bind: str = "127.0.0.1"


@dataclass(frozen=True)
class EngineSettings:
    width: int = 84
    height: int = 84
    quality_level: int = 5
    time_scale: float = 20.0
    target_frame_rate: int = -1
    capture_frame_rate: int = 60
    no_graphics: bool = False
    no_graphics_monitor: bool = False


@dataclass(frozen=True)
class CheckpointSettings:
    run_id: str = "ppo"
    initialize_from: str | None = None
    load_model: bool = False
    resume: bool = False
    force: bool = False
    train_model: bool = False
    inference: bool = False
    results_dir: str = "results"
    record_video: bool = False  # --record-video: clips of checkpoints in a CPU budget (trainer/artifacts/clips.py)

    @property
    def write_path(self) -> str:
        """results/<run-id>"""
        return os.path.join(self.results_dir, self.run_id)

    @property
    def maybe_init_path(self) -> str | None:
        """results/<initialize_from>, or None."""
        return None if self.initialize_from is None else os.path.join(self.results_dir, self.initialize_from)


@dataclass(frozen=True)
class TorchSettings:
    device: str | None = None


def _as_agent_steps(settings: TrainerSettings, agents: int) -> TrainerSettings:
    """A 0.x behavior's max_steps and summary_freq (environment steps of one simulator) as agent
    steps: × its ``agents`` in one simulator (docs/configuration.md)."""
    return dataclasses.replace(settings, max_steps=settings.max_steps * agents,
                               summary_freq=settings.summary_freq * agents)


@dataclass(frozen=True)
class RunOptions:
    """Everything one run needs. ``behaviors`` already has default_settings merged in."""

    behaviors: dict[str, TrainerSettings] = field(default_factory=dict)
    default_settings: TrainerSettings | None = None
    env_settings: EnvSettings = field(default_factory=EnvSettings)
    engine_settings: EngineSettings = field(default_factory=EngineSettings)
    checkpoint_settings: CheckpointSettings = field(default_factory=CheckpointSettings)
    torch_settings: TorchSettings = field(default_factory=TorchSettings)
    environment_parameters: dict[str, EnvironmentParameterSettings] = field(default_factory=dict)
    debug: bool = False
    config_path: str | None = None
    #: --deterministic given on the CLI: also applies to behaviors that get plain defaults.
    cli_deterministic: bool = False
    #: what to do instead of training (command line only, not in configuration.yaml; docs/mirror.md):
    #: --check the YAML against --spec FILE, or --capture-spec FILE (record the behaviors and exit)
    check: bool = False
    spec_path: str | None = None
    capture_spec: str | None = None
    #: --max-steps N: every behavior stops at N steps and summarizes at least every N / 10 (a short
    #: CI run of a project's YAML, docs/mirror.md); configuration.yaml keeps the YAML's values
    max_steps_override: int | None = None
    #: the file was an ML-Agents 0.x one: its max_steps and summary_freq count environment steps of
    #: one simulator, and become agent steps once the behavior's agents are counted (docs/configuration.md)
    legacy_env_steps: bool = False
    #: the behaviors of such a file whose counts are already agent steps in ``behaviors``
    #: (``with_agent_steps``, at their first contact), so configuration.yaml carries the counts the run uses
    agent_step_behaviors: frozenset[str] = frozenset()
    #: --batch-per-rank: with K data-parallel ranks, buffer_size and batch_size count ONE rank's
    #: experiences (K times the YAML's per update) instead of all ranks' (docs/cluster.md)
    batch_per_rank: bool = False

    def behavior_settings(self, brain_name: str, agents: int | None = None) -> TrainerSettings:
        """The settings for ``brain_name`` (no ``?team=``), with init_path resolved for
        --initialize-from. With ``legacy_env_steps``, ``agents`` (the behavior's agents in one
        simulator, known at first contact) turns max_steps and summary_freq into agent steps.
        Raises ConfigError for an unconfigured behavior when a config file was given and it has
        no default_settings."""
        settings = self.behaviors.get(brain_name, self.default_settings)
        if settings is None:
            if self.config_path is not None:
                configured = ", ".join(self.behaviors) or "none"
                raise ConfigError(
                    f"The behavior '{brain_name}' is not in {self.config_path}. Add a "
                    f"'behaviors.{brain_name}' section or a 'default_settings' section. "
                    f"Configured behaviors: {configured}."
                )
            logger.warning(
                "Behavior '%s' is not configured (no config file); using default settings.", brain_name
            )
            settings = TrainerSettings()
            if self.cli_deterministic:
                network = dataclasses.replace(settings.network_settings, deterministic=True)
                settings = dataclasses.replace(settings, network_settings=network)
        if self.legacy_env_steps and agents is not None and brain_name not in self.agent_step_behaviors:
            settings = _as_agent_steps(settings, agents)
        if self.max_steps_override is not None:
            settings = dataclasses.replace(settings, max_steps=self.max_steps_override,
                                           summary_freq=min(settings.summary_freq,
                                                            max(self.max_steps_override // 10, 1)))
        init_dir = self.checkpoint_settings.maybe_init_path
        if init_dir is not None:
            if settings.init_path is None:
                init_path = os.path.join(init_dir, brain_name, DEFAULT_CHECKPOINT_NAME)
            elif not os.path.dirname(settings.init_path):
                init_path = os.path.join(init_dir, brain_name, settings.init_path)
            else:
                init_path = settings.init_path
            settings = dataclasses.replace(settings, init_path=init_path)
        return settings

    def with_agent_steps(self, brain_name: str, agents: int) -> RunOptions:
        """A 0.x file's options with ``brain_name``'s max_steps and summary_freq as agent steps
        (× ``agents``, its agents in one simulator) in ``behaviors``; unchanged for a modern file or
        a behavior already converted. configuration.yaml, a modern file, then shows the counts the
        run uses (docs/configuration.md, "Steps in a 0.x file are environment steps")."""
        if not self.legacy_env_steps or brain_name in self.agent_step_behaviors:
            return self
        settings = self.behaviors.get(brain_name, self.default_settings)
        if settings is None:
            return self
        return dataclasses.replace(self, behaviors={**self.behaviors, brain_name: _as_agent_steps(settings, agents)},
                                   agent_step_behaviors=self.agent_step_behaviors | {brain_name})

    def as_dict(self) -> dict[str, Any]:
        """Plain dict in the YAML layout and the reference's key order, for configuration.yaml."""
        return {
            "default_settings": None if self.default_settings is None else settings_as_dict(self.default_settings),
            "behaviors": {name: settings_as_dict(ts) for name, ts in self.behaviors.items()},
            "env_settings": settings_as_dict(self.env_settings),
            "engine_settings": settings_as_dict(self.engine_settings),
            "environment_parameters": environment_parameters_as_dict(self.environment_parameters) or None,
            "checkpoint_settings": settings_as_dict(self.checkpoint_settings),
            "torch_settings": settings_as_dict(self.torch_settings),
            "debug": self.debug,
        }


def settings_as_dict(obj: Any) -> Any:
    """Recursively turn settings dataclasses into plain dicts/lists (field order kept)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: settings_as_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {key: settings_as_dict(val) for key, val in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [settings_as_dict(item) for item in obj]
    return obj
