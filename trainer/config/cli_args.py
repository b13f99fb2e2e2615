"""``mlagents-like-learn`` command line: the flags of ``mlagents-learn`` plus ours (docs/configuration.md,
"Command line"); each flag takes its dest, default and type from the settings field it sets.

A flag overrides the YAML only if it was actually given on the command line; the given flags are
tracked by the parser's actions (``namespace._given_flags``), not by comparing with defaults.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import random
import typing
from typing import Any, Sequence

from trainer.config.loader import check_run_options, load_yaml_run_options, prioritize_resume_init
from trainer.config.settings import (
    CheckpointSettings,
    EngineSettings,
    EnvSettings,
    NetworkSettings,
    RunOptions,
    TorchSettings,
)
from trainer.config.trainer_schema import apply_deterministic

logger = logging.getLogger("mlagents_like")

GIVEN_FLAGS_ATTR = "_given_flags"
SECTIONS: dict[str, type] = {
    "checkpoint_settings": CheckpointSettings,
    "env_settings": EnvSettings,
    "engine_settings": EngineSettings,
    "torch_settings": TorchSettings,
}


def _mark_given(namespace: argparse.Namespace, dest: str) -> None:
    given = getattr(namespace, GIVEN_FLAGS_ATTR, None)
    if given is None:
        given = set()
        setattr(namespace, GIVEN_FLAGS_ATTR, given)
    given.add(dest)


class _Store(argparse.Action):
    """Store the value and remember that the flag was given."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        setattr(namespace, self.dest, values)
        _mark_given(namespace, self.dest)


class _StoreTrue(_Store):
    def __init__(self, option_strings, dest, default=False, required=False, help=None) -> None:
        super().__init__(option_strings, dest, nargs=0, const=True, default=default, required=required, help=help)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        super().__call__(parser, namespace, True, option_string)


class _Removed(argparse.Action):
    """A removed flag that only logs a warning."""

    def __init__(self, option_strings, dest, default=False, help=None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        logger.warning("The command line argument %s was removed.", option_string)


class _ShippedFiles(argparse.Action):
    """``--list-configs``, ``--copy-configs DIR``, ``--write-slurm-template DIR``: print or copy
    files the package ships (trainer/shipped: what a pip user has instead of the checkout's
    configs/ and docker/slurm/), then exit as ``--help`` does, without training."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        from pathlib import Path

        from trainer import shipped

        try:
            if self.dest == "list_configs":
                lines = [str(path) for path in shipped.config_paths()]
            elif self.dest == "copy_configs":
                lines = [f"wrote {path}" for path in shipped.copy_configs(values)]
            else:
                lines = [f"wrote {path}" for path in shipped.write_slurm_template(values)]
                lines.append(shipped.slurm_usage(Path(values)))
        except OSError as err:
            parser.exit(2, f"{parser.prog}: error: {option_string}: {err}\n")
        print("\n".join(lines))
        parser.exit(0)


def _value_type(section: type, name: str) -> type | None:
    """int or float for a numeric field (None allowed), else None: argparse keeps the string."""
    hint = typing.get_type_hints(section)[name]
    candidates = [arg for arg in typing.get_args(hint) if arg is not type(None)] or [hint]
    return candidates[0] if candidates[0] in (int, float) else None


def _setting_flag(group: Any, section: type, name: str, help: str, flag: str | None = None, **extra: Any) -> None:
    """``--flag`` for the field ``section.name``: its dest is the field's name, its default the field's
    default and its type the field's type (a bool field is a switch), so no default is written twice."""
    default = {f.name: f.default for f in dataclasses.fields(section)}[name]
    flag = flag or "--" + name.replace("_", "-")
    if isinstance(default, bool):
        group.add_argument(flag, dest=name, default=default, action=_StoreTrue, help=help, **extra)
        return
    value_type = _value_type(section, name)
    if value_type is not None:
        extra["type"] = value_type
    group.add_argument(flag, dest=name, default=default, action=_Store, help=help, **extra)


def _add_general_flags(parser: argparse.ArgumentParser) -> None:
    env, ckpt = EnvSettings, CheckpointSettings
    parser.add_argument("trainer_config_path", nargs="?", default=None, help="ML-Agents trainer YAML (optional)")
    _setting_flag(parser, env, "env_path", "Unity executable to train, or stub:TASK for the built-in stub simulator; "
                  "without it, wait for the Unity Editor on port 5004", flag="--env", metavar="ENV_PATH")
    _setting_flag(parser, ckpt, "load_model", argparse.SUPPRESS, flag="--load")
    _setting_flag(parser, ckpt, "resume", "resume training from results/<run-id>")
    _setting_flag(parser, NetworkSettings, "deterministic", "act with the mean / argmax instead of sampling")
    _setting_flag(parser, ckpt, "force", "overwrite an existing results/<run-id>")
    _setting_flag(parser, ckpt, "run_id", "name of the run (results sub-folder)")
    _setting_flag(parser, ckpt, "initialize_from", "initialize each behavior from "
                  "results/<RUN_ID>/<behavior>/checkpoint.pt", metavar="RUN_ID")
    _setting_flag(parser, env, "seed", "random seed; -1 picks one in [0, 10000)")
    _setting_flag(parser, ckpt, "train_model", argparse.SUPPRESS, flag="--train")
    _setting_flag(parser, ckpt, "inference", "run the policy without training")
    _setting_flag(parser, env, "base_port", "port of worker 0; worker i uses base+i")
    _setting_flag(parser, env, "num_envs", "number of simulator processes")
    _setting_flag(parser, env, "num_areas", "training areas per simulator")
    _setting_flag(parser, RunOptions, "debug", "debug logging with timestamps")
    _setting_flag(parser, env, "env_args", "everything after this flag is passed to the simulator",
                  nargs=argparse.REMAINDER)
    _setting_flag(parser, env, "max_lifetime_restarts", "simulator crash restarts allowed over the run (-1: unlimited)")
    _setting_flag(parser, env, "restarts_rate_limit_n",
                  "restarts allowed per --restarts-rate-limit-period-s (-1: no rate limit)")
    _setting_flag(parser, env, "restarts_rate_limit_period_s", "period of the restart rate limit, seconds")
    parser.add_argument("--torch", action=_Removed, help="(removed) does nothing")
    parser.add_argument("--tensorflow", action=_Removed, help="(removed) does nothing")
    _setting_flag(parser, ckpt, "results_dir", "base folder of all runs")
    _setting_flag(parser, ckpt, "record_video", "--env stub:TASK: a background process films checkpoints' ONNX "
                  "(as a 4 %% CPU budget allows; the final one always) to <Behavior>-<step>.mp4 beside "
                  "them and into TensorBoard (Images)")
    _setting_flag(parser, env, "timeout_wait", "seconds to wait for each simulator message")
    _setting_flag(parser, env, "bind", "address the gRPC server binds (use 0.0.0.0 or [::] for all interfaces)")
    _setting_flag(parser, RunOptions, "batch_per_rank", "data-parallel ranks: buffer_size and batch_size are each "
                  "rank's, not all ranks' together (the default; docs/cluster.md)")
    shipped = parser.add_argument_group(title="Files the package ships (without a checkout of the repository)")
    shipped.add_argument("--list-configs", nargs=0, default=False, action=_ShippedFiles, help="print the paths of the example configs, then exit")
    shipped.add_argument("--copy-configs", metavar="DIR", action=_ShippedFiles,
                         help="copy the example configs into DIR, then exit")
    shipped.add_argument("--write-slurm-template", metavar="DIR", action=_ShippedFiles,
                         help="write the Slurm job template (train.sbatch, sweep.sh, sweep.py) into DIR, then exit")
    mirror = parser.add_argument_group(title="Behavior specs (docs/mirror.md)")
    _setting_flag(mirror, RunOptions, "capture_spec", "connect to --env, record its behavior specs to FILE after "
                  "the first steps and exit without training", metavar="FILE")
    _setting_flag(mirror, RunOptions, "check", "check the trainer YAML against --spec FILE (or --env "
                  "stub:mirror=FILE) and exit: 0 if it fits, 2 with one line per problem")
    _setting_flag(mirror, RunOptions, "max_steps_override", "a short run: every behavior stops at N steps and writes "
                  "a summary at least every N/10 steps (for CI on the mirror)", flag="--max-steps", metavar="N")
    _setting_flag(mirror, RunOptions, "spec_path", "a behaviors.json (from --capture-spec or a run's run_logs) "
                  "for --check", flag="--spec", metavar="FILE")


def _add_engine_and_torch_flags(parser: argparse.ArgumentParser) -> None:
    engine = parser.add_argument_group(title="Engine Configuration")
    for name, help in (("width", "window width, pixels"), ("height", "window height, pixels"),
                       ("quality_level", "QualitySettings level"), ("time_scale", "Time.timeScale"),
                       ("target_frame_rate", "Application.targetFrameRate"),
                       ("capture_frame_rate", "Time.captureFramerate"),
                       ("no_graphics", "run simulators with -nographics -batchmode"),
                       ("no_graphics_monitor", "like --no-graphics except for worker 0")):
        _setting_flag(engine, EngineSettings, name, help)
    torch_group = parser.add_argument_group(title="Torch Configuration")
    _setting_flag(torch_group, TorchSettings, "device", "torch device, e.g. cpu, cuda, cuda:0", flag="--torch-device")


def build_parser() -> argparse.ArgumentParser:
    """The ``mlagents-like-learn`` parser. Dests and defaults equal mlagents-learn's."""
    parser = argparse.ArgumentParser(
        prog="mlagents-like-learn",
        description="Train Unity ML-Agents behaviors with PPO (mlagents-learn compatible).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    _add_general_flags(parser)
    _add_engine_and_torch_flags(parser)
    return parser


def given_flags(namespace: argparse.Namespace) -> frozenset[str]:
    """Dests of the flags given on the command line."""
    return frozenset(getattr(namespace, GIVEN_FLAGS_ATTR, None) or ())


def apply_cli_overrides(options: RunOptions, values: dict[str, Any], given: frozenset[str]) -> RunOptions:
    """Route each given flag into its settings section (by field name) and return new options."""
    changes: dict[str, Any] = {}
    for section, cls in SECTIONS.items():
        names = {f.name for f in dataclasses.fields(cls)}
        updates = {dest: values[dest] for dest in given if dest in names}
        if updates:
            changes[section] = dataclasses.replace(getattr(options, section), **updates)
    if "debug" in given:
        changes["debug"] = True
    if "deterministic" in given:
        changes["behaviors"] = {name: apply_deterministic(ts, True) for name, ts in options.behaviors.items()}
        if options.default_settings is not None:
            changes["default_settings"] = apply_deterministic(options.default_settings, True)
        changes["cli_deterministic"] = True
    return dataclasses.replace(options, **changes)


def parse_run_options(argv: Sequence[str]) -> RunOptions:
    """argv (without the program name) -> final, checked RunOptions with the run seed resolved.

    Raises ConfigError for bad YAML or values; argparse's own errors exit with code 2.
    """
    namespace = build_parser().parse_args(list(argv))
    values = vars(namespace)
    given = set(given_flags(namespace))
    if "load_model" in given:
        logger.warning("--load is deprecated; use --resume.")
        values["resume"] = True
        given.add("resume")
    if "train_model" in given:
        logger.warning("--train is deprecated and does nothing; training is the default (see --inference).")
    config_path = values["trainer_config_path"]
    if config_path is not None:
        options = load_yaml_run_options(config_path)
    else:
        logger.warning("No trainer configuration file given: every behavior uses the default settings.")
        options = RunOptions()
    options = apply_cli_overrides(options, values, frozenset(given))
    checkpoint = prioritize_resume_init(options.checkpoint_settings, given)
    env = options.env_settings
    if env.seed == -1:
        env = dataclasses.replace(env, seed=random.randrange(10000))
        logger.debug("run seed set to %d", env.seed)
    options = dataclasses.replace(options, checkpoint_settings=checkpoint, env_settings=env,
                                  check=values["check"], spec_path=values["spec_path"],
                                  capture_spec=values["capture_spec"],
                                  max_steps_override=values["max_steps_override"],
                                  batch_per_rank=values["batch_per_rank"])
    check_run_options(options)
    return options
