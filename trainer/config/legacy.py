"""Convert old trainer files to the modern layout on load (docs/configuration.md, "Legacy formats").

* ML-Agents 0.x flat format: top-level behavior names plus ``default``, each a flat dict with
  ``trainer: ppo``, ``lambd``, ``num_layers``, ``hidden_units``, ``normalize``, ``use_recurrent``, ...
  ``default`` becomes ``default_settings`` (0.x used it for every unlisted brain) and each behavior
  becomes a full block from ``default`` updated by its own keys. A flat ``gamma`` is the extrinsic
  reward's gamma. ``max_steps`` and ``summary_freq`` keep their 0.x meaning: the 0.x trainers
  advanced their step counter once per environment step, whatever the number of agents, so these
  counts are environment steps of one simulator. They become agent steps at the behavior's first
  contact, times the number of its agents in one simulator (``RunOptions.behavior_settings``);
  ``log_agent_steps`` then shows the numbers and the modern block with the converted values.
* Mid-era (0.17-0.18): ``behaviors:`` plus top-level ``curriculum:`` / ``parameter_randomization:``,
  which become ``environment_parameters``.

A WARNING shows the modern YAML; the result then goes through the normal strict path.
"""
from __future__ import annotations

import logging
from typing import Any, Mapping

import yaml

from trainer.config.settings import settings_as_dict
from trainer.errors import ConfigError

logger = logging.getLogger("mlagents_like")

PPO_KEYS = (
    "batch_size", "buffer_size", "learning_rate", "beta", "epsilon", "lambd", "num_epoch",
    "shared_critic", "learning_rate_schedule", "beta_schedule", "epsilon_schedule",
)
SAC_KEYS = (
    "batch_size", "buffer_size", "learning_rate", "learning_rate_schedule", "buffer_init_steps", "tau",
    "steps_per_update", "save_replay_buffer", "init_entcoef", "reward_signal_steps_per_update",
)
NETWORK_KEYS = ("normalize", "hidden_units", "num_layers", "vis_encode_type", "goal_conditioning_type")
TRAINER_KEYS = (
    "checkpoint_interval", "init_path", "keep_checkpoints", "even_checkpoints", "max_steps",
    "time_horizon", "summary_freq", "threaded", "self_play", "behavioral_cloning",
)
#: Keys consumed by the conversion itself (not copied as they are).
CONVERTED_KEYS = ("trainer", "use_recurrent", "sequence_length", "memory_size", "gamma", "reward_signals")
LEGACY_MARKERS = frozenset(PPO_KEYS + SAC_KEYS + NETWORK_KEYS + CONVERTED_KEYS + ("max_steps", "time_horizon"))
MODERN_ONLY_KEYS = frozenset(
    ("behaviors", "default_settings", "env_settings", "engine_settings", "checkpoint_settings",
     "torch_settings", "environment_parameters", "debug")
)
OLD_SAMPLER_TYPES = {"multirange_uniform": "multirangeuniform"}


def is_legacy_flat(raw: Mapping) -> bool:
    """A 0.x file: no modern top-level key, and ``default`` or a block with flat trainer keys."""
    if MODERN_ONLY_KEYS & set(raw):
        return False
    return "default" in raw or any(
        isinstance(block, Mapping) and LEGACY_MARKERS & set(block) for block in raw.values()
    )


def convert_legacy_behavior(config: Mapping, name: str) -> tuple[dict, list[str]]:
    """One flat 0.x block -> (modern TrainerSettings dict, keys that were dropped)."""
    if config.get("trainer") is None:
        raise ConfigError(
            f"Legacy (0.x) config section '{name}' has no 'trainer:' key. Add 'trainer: ppo' to it or to 'default'."
        )
    new: dict[str, Any] = {"trainer_type": config["trainer"]}
    trainer_keys = SAC_KEYS if config["trainer"] == "sac" else PPO_KEYS  # the trainer's own class
    hyperparameters = {key: config[key] for key in trainer_keys if key in config}
    if hyperparameters:
        new["hyperparameters"] = hyperparameters
    network = {key: config[key] for key in NETWORK_KEYS if key in config}
    if config.get("use_recurrent", False):
        network["memory"] = {
            "sequence_length": config.get("sequence_length", 64),
            "memory_size": config.get("memory_size", 128),
        }
    if network:
        new["network_settings"] = network
    if "reward_signals" in config:
        new["reward_signals"] = config["reward_signals"]
    elif "gamma" in config:
        new["reward_signals"] = {"extrinsic": {"gamma": config["gamma"], "strength": 1.0}}
    for key in TRAINER_KEYS:
        if key in config:
            new[key] = config[key]
    used = set(trainer_keys + NETWORK_KEYS + TRAINER_KEYS + CONVERTED_KEYS)
    dropped = [str(key) for key in config if key not in used]
    return new, dropped


def convert_legacy_flat(raw: Mapping) -> tuple[dict, dict[str, list[str]]]:
    """A whole 0.x trainer file -> (modern dict, dropped keys per section)."""
    default = dict(raw.get("default") or {})
    modern: dict[str, Any] = {}
    dropped: dict[str, list[str]] = {}
    default_settings = None
    if default:
        default_settings, dropped["default"] = convert_legacy_behavior({"trainer": "ppo", **default}, "default")
        modern["default_settings"] = default_settings
    behaviors = {}
    for name, block in raw.items():
        if name == "default":
            continue
        if block is not None and not isinstance(block, Mapping):
            raise ConfigError(f"Legacy (0.x) config section '{name}' must be a mapping of settings.")
        behaviors[str(name)], dropped[str(name)] = convert_legacy_behavior({**default, **(block or {})}, str(name))
        memory_in_default = (default_settings or {}).get("network_settings", {}).get("memory")
        if memory_in_default and "memory" not in behaviors[str(name)].get("network_settings", {}):
            behaviors[str(name)].setdefault("network_settings", {})["memory"] = None
    modern["behaviors"] = behaviors
    return modern, {key: keys for key, keys in dropped.items() if keys}


def convert_parameter_randomization(old: Mapping) -> dict:
    """``{resampling-interval, p: {sampler-type, ...}}`` -> environment_parameters samplers."""
    params = {}
    for name, block in old.items():
        if name == "resampling-interval":
            continue
        if not isinstance(block, Mapping) or "sampler-type" not in block:
            raise ConfigError(f"'parameter_randomization.{name}' needs a 'sampler-type'.")
        rest = {key: val for key, val in block.items() if key != "sampler-type"}
        kind = OLD_SAMPLER_TYPES.get(block["sampler-type"], block["sampler-type"])
        params[str(name)] = {"sampler_type": kind, "sampler_parameters": rest}
    return params


def convert_curriculum(old: Mapping, params: dict) -> dict:
    """``{behavior: {measure, thresholds, min_lesson_length, signal_smoothing, parameters}}`` ->
    one curriculum per parameter, lessons named Lesson0, Lesson1, ... (with ``name``)."""
    for behavior, block in old.items():
        path = f"curriculum.{behavior}"
        if not isinstance(block, Mapping) or "thresholds" not in block or "parameters" not in block:
            raise ConfigError(f"'{path}' needs 'measure', 'thresholds' and 'parameters'.")
        thresholds = list(block["thresholds"])
        for param, values in block["parameters"].items():
            if param in params:
                logger.warning("Parameter '%s' has both a sampler and a curriculum; the curriculum is ignored.", param)
                continue
            if not isinstance(values, list) or len(values) != len(thresholds) + 1:
                raise ConfigError(
                    f"'{path}.parameters.{param}' must list {len(thresholds) + 1} values (one more than thresholds)."
                )
            lessons = []
            for i, value in enumerate(values):
                lesson: dict[str, Any] = {"name": f"Lesson{i}", "value": value}
                if i < len(thresholds):
                    lesson["completion_criteria"] = {
                        "behavior": str(behavior),
                        "measure": block.get("measure", "reward"),
                        "min_lesson_length": block.get("min_lesson_length", 1),
                        "signal_smoothing": block.get("signal_smoothing", False),
                        "threshold": thresholds[i],
                    }
                lessons.append(lesson)
            params[str(param)] = {"curriculum": lessons}
    return params


def _convert_mid_era(raw: dict) -> dict:
    modern = {key: val for key, val in raw.items() if key not in ("curriculum", "parameter_randomization")}
    params = dict(modern.get("environment_parameters") or {})
    params.update(convert_parameter_randomization(raw.get("parameter_randomization") or {}))
    params = convert_curriculum(raw.get("curriculum") or {}, params)
    modern["environment_parameters"] = params
    return modern


def env_step_note(modern: Mapping) -> str:
    """What the warning says about a 0.x file's step counts, with each behavior's numbers."""
    default = modern.get("default_settings") or {}

    def count(block: Mapping, key: str, fallback: str) -> str:
        value = block.get(key, default.get(key))
        try:  # 0.x files write counts like 5.0e6
            return f"{int(float(value))}" if float(value) == int(float(value)) else str(value)
        except (TypeError, ValueError):
            return fallback if value is None else str(value)

    counts = [f"{name}: max_steps {count(block, 'max_steps', 'the default 500000')}, "
              f"summary_freq {count(block, 'summary_freq', 'the default 50000')}"
              for name, block in modern["behaviors"].items()]
    return ("Step counts keep their 0.x meaning, environment steps of one simulator whatever the number "
            "of agents (" + "; ".join(counts) + "): at a behavior's first contact they are multiplied by "
            "its agents in one simulator and become agent steps (e.g. max_steps 2000 with 14 agents: 28000). "
            "The YAML below still shows the 0.x counts; the converted values are logged at first contact.")


def log_agent_steps(brain: str, agents: int, written: Any, converted: Any) -> None:
    """At ``brain``'s first contact: its 0.x step counts (``written``, TrainerSettings as in the
    file) as agent steps with ``agents`` agents in one simulator, and the modern block with the
    values the run uses (``converted``)."""
    logger.warning(
        "%s: %d agents in one simulator, so the 0.x max_steps %d and summary_freq %d (environment steps) "
        "are %d and %d agent steps. The modern equivalent of this behavior, with these values:\n%s",
        brain, agents, written.max_steps, written.summary_freq, written.max_steps * agents,
        written.summary_freq * agents,
        yaml.safe_dump({"behaviors": {brain: settings_as_dict(converted)}}, sort_keys=False),
    )


def convert_if_legacy(raw: dict, path: str) -> dict:
    """``raw`` unchanged if modern; else converted, with a WARNING showing the modern YAML."""
    if is_legacy_flat(raw):
        modern, dropped = convert_legacy_flat(raw)
        what = "the ML-Agents 0.x trainer format"
    elif "behaviors" in raw and ({"curriculum", "parameter_randomization"} & set(raw)):
        modern, dropped = _convert_mid_era(raw), {}
        what = "the ML-Agents 0.17-0.18 format (curriculum/parameter_randomization)"
    else:
        return raw
    notes = "".join(f" Dropped from '{section}': {', '.join(keys)}." for section, keys in dropped.items())
    if what == "the ML-Agents 0.x trainer format":
        notes += " " + env_step_note(modern)
    logger.warning(
        "%s is in %s; it was converted on load.%s The modern equivalent (save it to silence this warning):\n%s",
        path, what, notes, yaml.safe_dump(modern, sort_keys=False),
    )
    return modern
