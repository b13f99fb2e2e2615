"""Read a trainer YAML (modern, mid-era or legacy 0.x) into a checked ``RunOptions``; write it back.

``load_run_options(path)`` reads any file ``mlagents-like-learn`` accepts, including the
``configuration.yaml`` it writes (round trip). Every problem is one ``ConfigError``.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from typing import Any, Collection, Mapping

import yaml

from trainer.artifacts.atomic import atomic_write
from trainer.config.env_params import structure_environment_parameters
from trainer.config.legacy import convert_if_legacy, is_legacy_flat
from trainer.config.settings import (
    CheckpointSettings,
    EngineSettings,
    EnvSettings,
    RunOptions,
    TorchSettings,
)
from trainer.config.strict import check_known_keys, require_mapping, structure, to_bool
from trainer.config.trainer_schema import merged_behavior_blocks, structure_trainer_settings
from trainer.errors import ConfigError

logger = logging.getLogger("mlagents_like")

TOP_LEVEL_KEYS = (
    "behaviors",
    "default_settings",
    "env_settings",
    "engine_settings",
    "checkpoint_settings",
    "torch_settings",
    "environment_parameters",
    "debug",
)
CONFIGURATION_FILE_NAME = "configuration.yaml"
# refused before parsing: the largest real ML-Agents config is a few KiB, and parsing 50 MB of YAML
# took 71 s and 566 MB (docs/reliability.md)
MAX_CONFIG_BYTES = 1 << 20


class _StrictSafeLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping (PyYAML silently keeps the last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                mark = key_node.start_mark
                raise ConfigError(
                    f"{mark.name}:{mark.line + 1}:{mark.column + 1}: the key '{key}' is given twice in one mapping."
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def read_yaml_file(path: str) -> Any:
    """Parse ``path`` as YAML. Missing file, bad encoding and syntax errors (with line and
    column) become ConfigError."""
    if not os.path.isfile(path):
        what = "is a directory" if os.path.isdir(path) else "could not be found"
        raise ConfigError(f"Config file {what}: {os.path.abspath(path)}. Pass the path of a YAML file.")
    size = os.path.getsize(path)
    if size > MAX_CONFIG_BYTES:
        raise ConfigError(
            f"Config file {path} is {size / 2**20:.1f} MiB; a trainer configuration is at most "
            f"{MAX_CONFIG_BYTES // 2**20} MiB (real ones are a few KiB). Pass the right file."
        )
    try:
        with open(path, encoding="utf-8") as stream:
            text = stream.read()
    except UnicodeDecodeError:
        raise ConfigError(f"Config file {path} is not UTF-8 text. Save it as UTF-8.") from None
    except OSError as error:
        raise ConfigError(f"Config file {path} could not be read: {error.strerror}.") from None
    try:
        loader = _StrictSafeLoader(text)
        loader.name = path
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else path
        problem = error.problem or error.context or "malformed YAML"
        raise ConfigError(f"{where}: YAML syntax error: {problem}.") from None
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: YAML error: {error}.") from None


def load_config_dict(path: str) -> dict:
    """The top-level mapping of ``path``, converted to the modern layout if it is legacy."""
    return _load_config(path)[0]


def _load_config(path: str) -> tuple[dict, bool]:
    """(the modern-layout mapping of ``path``, whether it was an ML-Agents 0.x flat file)."""
    raw = read_yaml_file(path)
    if raw is None:
        raise ConfigError(f"Config file {path} is empty. It needs at least a 'behaviors:' section.")
    if not isinstance(raw, Mapping):
        raise ConfigError(
            f"Config file {path} must hold a mapping at the top level (behaviors:, ...), "
            f"not a {type(raw).__name__}."
        )
    return convert_if_legacy(dict(raw), path), is_legacy_flat(raw)


def _structure_section(cls: type, raw: Mapping, key: str) -> Any:
    return structure(cls, raw.get(key), key)


def run_options_from_dict(raw: Mapping, config_path: str | None = None) -> RunOptions:
    """A modern-layout dict -> RunOptions, with every schema and range check of docs/configuration.md, "YAML"."""
    raw = require_mapping(raw, "the configuration")
    check_known_keys(raw, TOP_LEVEL_KEYS, "")
    default_raw = raw.get("default_settings")
    default_settings = None
    if default_raw is not None:
        default_raw = require_mapping(default_raw, "default_settings")
        default_settings = structure_trainer_settings(default_raw, "default_settings")
    behaviors_raw = require_mapping(raw.get("behaviors"), "behaviors")
    behaviors = {
        name: structure_trainer_settings(block, f"behaviors.{name}", has_defaults=default_raw is not None)
        for name, block in merged_behavior_blocks(default_raw, behaviors_raw).items()
    }
    # With default_settings any behavior name is covered, so a curriculum may name unlisted ones.
    known_behaviors: Collection[str] | None = list(behaviors) if behaviors and default_settings is None else None
    return RunOptions(
        behaviors=behaviors,
        default_settings=default_settings,
        env_settings=_structure_section(EnvSettings, raw, "env_settings"),
        engine_settings=_structure_section(EngineSettings, raw, "engine_settings"),
        checkpoint_settings=_structure_section(CheckpointSettings, raw, "checkpoint_settings"),
        torch_settings=_structure_section(TorchSettings, raw, "torch_settings"),
        environment_parameters=structure_environment_parameters(
            raw.get("environment_parameters"), "environment_parameters", known_behaviors
        ),
        debug=to_bool(raw.get("debug", False), "debug"),
        config_path=config_path,
    )


def load_yaml_run_options(path: str) -> RunOptions:
    """Read and structure ``path``; errors are prefixed with the file name. No cross-checks. A 0.x
    file's step counts keep their meaning (``RunOptions.legacy_env_steps``)."""
    raw, legacy = _load_config(path)
    try:
        options = run_options_from_dict(raw, config_path=path)
    except ConfigError as error:
        raise ConfigError(f"{path}: {error}") from None
    return dataclasses.replace(options, legacy_env_steps=True) if legacy else options


def load_run_options(path: str) -> RunOptions:
    """``path`` -> RunOptions exactly as ``mlagents-like-learn path`` (no flags) would resolve it,
    seed left as written. Reads configuration.yaml back too."""
    options = load_yaml_run_options(path)
    options = dataclasses.replace(
        options, checkpoint_settings=prioritize_resume_init(options.checkpoint_settings, frozenset())
    )
    check_run_options(options)
    return options


def prioritize_resume_init(ckpt: CheckpointSettings, cli_given: Collection[str]) -> CheckpointSettings:
    """resume and initialize_from together: a flag given on the CLI wins; otherwise resume wins."""
    if not (ckpt.resume and ckpt.initialize_from is not None):
        return ckpt
    if "initialize_from" in cli_given and "resume" not in cli_given:
        logger.warning(
            "Both resume and initialize_from=%s are set; --initialize-from was given, so resume is ignored.",
            ckpt.initialize_from,
        )
        return dataclasses.replace(ckpt, resume=False)
    logger.warning(
        "Both resume and initialize_from=%s are set; the run is resumed and initialize_from is ignored.",
        ckpt.initialize_from,
    )
    return dataclasses.replace(ckpt, initialize_from=None)


def _check(condition: bool, flag: str, key: str, rule: str, value: Any) -> None:
    if not condition:
        raise ConfigError(f"{flag} ({key}) must be {rule}, got {value}.")


def check_run_options(options: RunOptions) -> None:
    """Checks on the final options (YAML plus flags): env, ports, engine, run id."""
    env = options.env_settings
    _check(env.num_envs >= 1, "--num-envs", "env_settings.num_envs", ">= 1", env.num_envs)
    if env.num_envs > 1 and env.env_path is None:
        raise ConfigError(
            f"--num-envs {env.num_envs} (env_settings.num_envs) needs --env: the Editor is a single "
            f"environment on port 5004. Give --env PATH or --env stub:TASK, or use --num-envs 1."
        )
    _check(env.num_areas >= 1, "--num-areas", "env_settings.num_areas", ">= 1", env.num_areas)
    last_port = env.base_port + env.num_envs - 1
    if not (1 <= env.base_port and last_port <= 65535):
        raise ConfigError(
            f"--base-port (env_settings.base_port) {env.base_port} with {env.num_envs} env(s) needs ports "
            f"{env.base_port}..{last_port}; they must lie in 1..65535."
        )
    _check(env.timeout_wait > 0, "--timeout-wait", "env_settings.timeout_wait", "> 0", env.timeout_wait)
    _check(-1 <= env.seed <= 2**31 - 1 - env.num_envs, "--seed", "env_settings.seed",
           "-1 (random) or a non-negative int32", env.seed)
    _check(env.max_lifetime_restarts >= -1, "--max-lifetime-restarts", "env_settings.max_lifetime_restarts",
           ">= -1", env.max_lifetime_restarts)
    _check(env.restarts_rate_limit_n >= -1, "--restarts-rate-limit-n", "env_settings.restarts_rate_limit_n",
           ">= -1", env.restarts_rate_limit_n)
    _check(env.restarts_rate_limit_period_s >= 0, "--restarts-rate-limit-period-s",
           "env_settings.restarts_rate_limit_period_s", ">= 0", env.restarts_rate_limit_period_s)
    _check(bool(env.bind.strip()), "--bind", "env_settings.bind", "a host address", repr(env.bind))
    if env.env_path is not None and env.env_path.startswith("stub:") and not env.env_path[5:]:
        raise ConfigError("--env stub:TASK needs a task name after 'stub:', e.g. --env stub:basic.")
    if options.max_steps_override is not None and options.max_steps_override < 1:
        raise ConfigError(f"--max-steps must be at least 1, got {options.max_steps_override}.")
    if options.check and options.capture_spec is not None:
        raise ConfigError("--check and --capture-spec do different things: give one of them.")
    engine = options.engine_settings
    _check(engine.width >= 1, "--width", "engine_settings.width", ">= 1", engine.width)
    _check(engine.height >= 1, "--height", "engine_settings.height", ">= 1", engine.height)
    _check(engine.time_scale > 0, "--time-scale", "engine_settings.time_scale", "> 0", engine.time_scale)
    run_id = options.checkpoint_settings.run_id
    _check(bool(run_id.strip()), "--run-id", "checkpoint_settings.run_id", "a non-empty name", repr(run_id))
    check_folder_name(run_id, "--run-id", "checkpoint_settings.run_id")
    init = options.checkpoint_settings.initialize_from
    if init is not None:
        check_folder_name(init, "--initialize-from", "checkpoint_settings.initialize_from")


def check_folder_name(name: str, flag: str, key: str) -> None:
    """A run id names one folder inside --results-dir: no separators, not '.' or '..', no NUL."""
    separators = {"/", os.sep} | ({os.altsep} if os.altsep else set())
    if name in (".", "..") or "\0" in name or any(sep in name for sep in separators):
        raise ConfigError(
            f"{flag} ({key}) must be a plain folder name inside --results-dir (no '/', '..' or '.'), "
            f"got {name!r}. To write elsewhere, use --results-dir."
        )


def write_run_options(options: RunOptions, output_dir: str | None = None) -> str:
    """Write ``configuration.yaml`` (as_dict, key order kept) into ``output_dir`` (default
    results/<run-id>), creating it. Returns the file path."""
    output_dir = output_dir or options.checkpoint_settings.write_path
    os.makedirs(output_dir, exist_ok=True)
    path = os.path.join(output_dir, CONFIGURATION_FILE_NAME)
    atomic_write(path, lambda stream: yaml.safe_dump(options.as_dict(), stream, sort_keys=False), binary=False)
    return path
