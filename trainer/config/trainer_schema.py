"""Raw ``behaviors.<name>`` / ``default_settings`` blocks -> checked ``TrainerSettings`` (docs/configuration.md,
"Per behavior" and the sections after it)."""
from __future__ import annotations

import dataclasses
import logging
from typing import Any, Mapping

from trainer.config.settings import (
    HYPERPARAMETER_CLASSES,
    REWARD_SIGNAL_CLASSES,
    TRAINABLE_TRAINER_TYPES,
    TRAINER_TYPES,
    BehavioralCloningSettings,
    NetworkSettings,
    OnPolicySettings,
    PPOSettings,
    SACSettings,
    SelfPlaySettings,
    TrainerSettings,
)
from trainer.config.strict import (
    check_known_keys,
    deep_merge,
    join_path,
    require_mapping,
    structure,
    suggestion,
    to_int,
    to_str,
)
from trainer.errors import ConfigError

logger = logging.getLogger("mlagents_like")


def check_trainer_type(value: Any, path: str) -> str:
    """Every trainer type of TRAINABLE_TRAINER_TYPES trains; a known one not listed there is
    refused; anything else is unknown."""
    trainer_type = to_str(value, path)
    if trainer_type in TRAINABLE_TRAINER_TYPES:
        return trainer_type
    if trainer_type in TRAINER_TYPES:
        raise ConfigError(
            f"'{path}' is '{trainer_type}': mlagents-like trains {', '.join(TRAINABLE_TRAINER_TYPES)} "
            f"only for now. Set 'trainer_type: ppo'."
        )
    raise ConfigError(
        f"'{path}': unknown trainer type '{trainer_type}'.{suggestion(trainer_type, TRAINER_TYPES)} "
        f"Known trainer types: {', '.join(TRAINER_TYPES)}."
    )


def structure_hyperparameters(raw: Any, path: str, trainer_type: str = "ppo") -> OnPolicySettings | SACSettings:
    """The hyperparameters class of ``trainer_type``; for PPO with the schedule-copy rule:
    beta/epsilon schedules follow learning_rate_schedule when only it is given."""
    raw = dict(require_mapping(raw, path))
    if trainer_type != "ppo":
        return structure(HYPERPARAMETER_CLASSES[trainer_type], raw, path)
    if "learning_rate_schedule" in raw:
        raw.setdefault("beta_schedule", raw["learning_rate_schedule"])
        raw.setdefault("epsilon_schedule", raw["learning_rate_schedule"])
    return structure(PPOSettings, raw, path)


def structure_reward_signals(raw: Any, path: str) -> dict:
    raw = require_mapping(raw, path)
    signals = {}
    for name, block in raw.items():
        check_known_keys({name: None}, REWARD_SIGNAL_CLASSES, path)
        block_path = join_path(path, name)
        block = require_mapping(block, block_path)
        settings = structure(REWARD_SIGNAL_CLASSES[name], block, block_path)
        encoding_size = getattr(settings, "encoding_size", None)
        if encoding_size is not None:
            logger.warning("'%s.encoding_size' is deprecated; use network_settings.hidden_units.", block_path)
            if "network_settings" not in block:
                network = dataclasses.replace(settings.network_settings, hidden_units=encoding_size)
                settings = dataclasses.replace(settings, network_settings=network)
        signals[name] = settings
    return signals


def _max_steps(value: Any, path: str) -> int:
    """Accepts float spellings such as ``5.0e5`` or ``"5.0e6"`` (int(float()))."""
    if isinstance(value, str):
        try:
            return int(float(value))
        except ValueError:
            pass
    if isinstance(value, float):
        return int(value)
    return to_int(value, path)


def structure_trainer_settings(raw: Any, path: str, has_defaults: bool = False) -> TrainerSettings:
    """One merged behavior block (default_settings already laid under it) -> TrainerSettings.

    has_defaults: a default_settings block was merged in, which always carries a trainer_type.
    """
    raw = dict(require_mapping(raw, path))
    if "framework" in raw:
        logger.warning("'%s.framework' is deprecated and ignored.", path)
        raw.pop("framework")
    if "hyperparameters" in raw and "trainer_type" not in raw and not has_defaults:
        raise ConfigError(
            f"'{path}' gives hyperparameters but no trainer_type. Add 'trainer_type: ppo' to it."
        )
    trainer_type = check_trainer_type(raw.get("trainer_type", "ppo"), join_path(path, "trainer_type"))
    raw.setdefault("hyperparameters", {})  # the defaults of the trainer type, not PPO's
    hooks = {
        "trainer_type": check_trainer_type,
        "hyperparameters": lambda v, p: structure_hyperparameters(v, p, trainer_type),
        "reward_signals": structure_reward_signals,
        "max_steps": _max_steps,
        "self_play": lambda v, p: None if v is None else structure(SelfPlaySettings, v, p),
        "behavioral_cloning": lambda v, p: None if v is None else structure(BehavioralCloningSettings, v, p),
    }
    settings = structure(TrainerSettings, raw, path, hooks)
    check_trainer_settings(settings, path)
    return settings


def _require(condition: bool, path: str, rule: str, value: Any) -> None:
    if not condition:
        raise ConfigError(f"'{path}' must be {rule}, got {value}.")


def check_network_settings(network: NetworkSettings, path: str) -> None:
    _require(network.hidden_units > 0, f"{path}.hidden_units", "> 0", network.hidden_units)
    _require(network.num_layers >= 1, f"{path}.num_layers", ">= 1", network.num_layers)
    memory = network.memory
    if memory is not None:
        size = memory.memory_size
        _require(size > 0 and size % 2 == 0, f"{path}.memory.memory_size", "> 0 and even", size)
        _require(memory.sequence_length >= 1, f"{path}.memory.sequence_length", ">= 1", memory.sequence_length)


def check_hyperparameters(hp: OnPolicySettings | SACSettings, path: str) -> None:
    _require(hp.batch_size >= 1, f"{path}.batch_size", ">= 1", hp.batch_size)
    if isinstance(hp, SACSettings):
        check_sac_hyperparameters(hp, path)
        return
    if hp.batch_size > hp.buffer_size:
        raise ConfigError(
            f"'{path}.batch_size' ({hp.batch_size}) must not exceed '{path}.buffer_size' ({hp.buffer_size})."
        )
    _require(hp.learning_rate > 0, f"{path}.learning_rate", "> 0", hp.learning_rate)
    _require(hp.beta >= 0, f"{path}.beta", ">= 0", hp.beta)
    _require(hp.epsilon > 0, f"{path}.epsilon", "> 0", hp.epsilon)
    _require(0.0 <= hp.lambd <= 1.0, f"{path}.lambd", "in [0, 1]", hp.lambd)
    _require(hp.num_epoch >= 1, f"{path}.num_epoch", ">= 1", hp.num_epoch)


def check_sac_hyperparameters(hp: SACSettings, path: str) -> None:
    if hp.batch_size > hp.buffer_size:
        raise ConfigError(
            f"'{path}.batch_size' ({hp.batch_size}) must not exceed '{path}.buffer_size' ({hp.buffer_size})."
        )
    _require(hp.learning_rate > 0, f"{path}.learning_rate", "> 0", hp.learning_rate)
    _require(hp.buffer_init_steps >= 0, f"{path}.buffer_init_steps", ">= 0", hp.buffer_init_steps)
    _require(0.0 < hp.tau <= 1.0, f"{path}.tau", "in (0, 1]", hp.tau)
    _require(hp.steps_per_update > 0, f"{path}.steps_per_update", "> 0", hp.steps_per_update)
    _require(hp.reward_signal_steps_per_update > 0, f"{path}.reward_signal_steps_per_update", "> 0",
             hp.reward_signal_steps_per_update)
    _require(hp.init_entcoef > 0, f"{path}.init_entcoef", "> 0", hp.init_entcoef)


def check_trainer_settings(ts: TrainerSettings, path: str) -> None:
    """Cross-field and range checks; the first violation raises with its key path."""
    check_hyperparameters(ts.hyperparameters, f"{path}.hyperparameters")
    check_network_settings(ts.network_settings, f"{path}.network_settings")
    memory = ts.network_settings.memory
    if memory is not None and memory.sequence_length > ts.hyperparameters.batch_size:
        raise ConfigError(
            f"'{path}.network_settings.memory.sequence_length' ({memory.sequence_length}) must not exceed "
            f"'{path}.hyperparameters.batch_size' ({ts.hyperparameters.batch_size})."
        )
    for name, signal in ts.reward_signals.items():
        signal_path = f"{path}.reward_signals.{name}"
        _require(0.0 <= signal.gamma <= 1.0, f"{signal_path}.gamma", "in [0, 1]", signal.gamma)
        check_network_settings(signal.network_settings, f"{signal_path}.network_settings")
    for key in ("time_horizon", "summary_freq", "checkpoint_interval"):
        _require(getattr(ts, key) >= 1, f"{path}.{key}", ">= 1", getattr(ts, key))
    _require(ts.max_steps >= 0, f"{path}.max_steps", ">= 0", ts.max_steps)
    _require(ts.keep_checkpoints >= 0, f"{path}.keep_checkpoints", ">= 0", ts.keep_checkpoints)
    if ts.even_checkpoints and ts.keep_checkpoints == 0:
        raise ConfigError(f"'{path}.even_checkpoints' needs keep_checkpoints >= 1.")


def apply_deterministic(ts: TrainerSettings, deterministic: bool) -> TrainerSettings:
    network = dataclasses.replace(ts.network_settings, deterministic=deterministic)
    return dataclasses.replace(ts, network_settings=network)


def merged_behavior_blocks(default_raw: Mapping | None, behaviors_raw: Mapping) -> dict[str, dict]:
    """Each behavior block with default_settings deep-merged under it (raw dicts)."""
    return {
        str(name): deep_merge(default_raw or {}, require_mapping(block, f"behaviors.{name}"))
        for name, block in behaviors_raw.items()
    }
