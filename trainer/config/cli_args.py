"""``mlagents-like-learn`` command line: the flags of ``mlagents-learn`` (docs/configuration.md §5) plus ``--bind``.

A flag overrides the YAML only if it was actually given on the command line; the given flags are
tracked by the parser's actions (``namespace._given_flags``), not by comparing with defaults.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import random
from typing import Any, Sequence

from trainer.config.loader import check_run_options, load_yaml_run_options, prioritize_resume_init
from trainer.config.settings import (
    CheckpointSettings,
    EngineSettings,
    EnvSettings,
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


def _add_general_flags(parser: argparse.ArgumentParser) -> None:
    add = parser.add_argument
    add("trainer_config_path", nargs="?", default=None, help="ML-Agents trainer YAML (optional)")
    add("--env", dest="env_path", default=None, action=_Store, metavar="ENV_PATH",
        help="Unity executable to train, or stub:TASK for the built-in stub simulator; "
        "without it, wait for the Unity Editor on port 5004")
    add("--load", dest="load_model", action=_StoreTrue, help=argparse.SUPPRESS)
    add("--resume", action=_StoreTrue, help="resume training from results/<run-id>")
    add("--deterministic", action=_StoreTrue, help="act with the mean / argmax instead of sampling")
    add("--force", action=_StoreTrue, help="overwrite an existing results/<run-id>")
    add("--run-id", default="ppo", action=_Store, help="name of the run (results sub-folder)")
    add("--initialize-from", metavar="RUN_ID", default=None, action=_Store,
        help="initialize each behavior from results/<RUN_ID>/<behavior>/checkpoint.pt")
    add("--seed", type=int, default=-1, action=_Store, help="random seed; -1 picks one in [0, 10000)")
    add("--train", dest="train_model", action=_StoreTrue, help=argparse.SUPPRESS)
    add("--inference", action=_StoreTrue, help="run the policy without training")
    add("--base-port", type=int, default=5005, action=_Store, help="port of worker 0; worker i uses base+i")
    add("--num-envs", type=int, default=1, action=_Store, help="number of simulator processes")
    add("--num-areas", type=int, default=1, action=_Store, help="training areas per simulator")
    add("--debug", action=_StoreTrue, help="debug logging with timestamps")
    add("--env-args", default=None, nargs=argparse.REMAINDER, action=_Store,
        help="everything after this flag is passed to the simulator")
    add("--max-lifetime-restarts", type=int, default=10, action=_Store,
        help="simulator crash restarts allowed over the run (-1: unlimited)")
    add("--restarts-rate-limit-n", type=int, default=1, action=_Store,
        help="restarts allowed per --restarts-rate-limit-period-s (-1: no rate limit)")
    add("--restarts-rate-limit-period-s", type=int, default=60, action=_Store,
        help="period of the restart rate limit, seconds")
    add("--torch", action=_Removed, help="(removed) does nothing")
    add("--tensorflow", action=_Removed, help="(removed) does nothing")
    add("--results-dir", default="results", action=_Store, help="base folder of all runs")
    add("--timeout-wait", type=int, default=60, action=_Store, help="seconds to wait for each simulator message")
    add("--bind", default="127.0.0.1", action=_Store,
        help="address the gRPC server binds (use 0.0.0.0 or [::] for all interfaces)")
    shipped = parser.add_argument_group(title="Files the package ships (without a checkout of the repository)")
    shipped.add_argument("--list-configs", nargs=0, action=_ShippedFiles, help="print the paths of the example configs, then exit")
    shipped.add_argument("--copy-configs", metavar="DIR", action=_ShippedFiles,
                         help="copy the example configs into DIR, then exit")
    shipped.add_argument("--write-slurm-template", metavar="DIR", action=_ShippedFiles,
                         help="write the Slurm job template (train.sbatch, sweep.sh, sweep.py) into DIR, then exit")
    mirror = parser.add_argument_group(title="Behavior specs (docs/mirror.md)")
    mirror.add_argument("--capture-spec", metavar="FILE", default=None, action=_Store,
                        help="connect to --env, record its behavior specs to FILE after the first steps "
                             "and exit without training")
    mirror.add_argument("--check", action=_StoreTrue,
                        help="check the trainer YAML against --spec FILE (or --env stub:mirror=FILE) and "
                             "exit: 0 if it fits, 2 with one line per problem")
    mirror.add_argument("--max-steps", dest="max_steps_override", type=int, metavar="N", default=None,
                        action=_Store, help="a short run: every behavior stops at N steps and writes a summary "
                                            "at least every N/10 steps (for CI on the mirror)")
    mirror.add_argument("--spec", dest="spec_path", metavar="FILE", default=None, action=_Store,
                        help="a behaviors.json (from --capture-spec or a run's run_logs) for --check")


def _add_engine_and_torch_flags(parser: argparse.ArgumentParser) -> None:
    engine = parser.add_argument_group(title="Engine Configuration")
    engine.add_argument("--width", type=int, default=84, action=_Store, help="window width, pixels")
    engine.add_argument("--height", type=int, default=84, action=_Store, help="window height, pixels")
    engine.add_argument("--quality-level", type=int, default=5, action=_Store, help="QualitySettings level")
    engine.add_argument("--time-scale", type=float, default=20.0, action=_Store, help="Time.timeScale")
    engine.add_argument("--target-frame-rate", type=int, default=-1, action=_Store,
                        help="Application.targetFrameRate")
    engine.add_argument("--capture-frame-rate", type=int, default=60, action=_Store, help="Time.captureFramerate")
    engine.add_argument("--no-graphics", action=_StoreTrue, help="run simulators with -nographics -batchmode")
    engine.add_argument("--no-graphics-monitor", action=_StoreTrue,
                        help="like --no-graphics except for worker 0")
    torch_group = parser.add_argument_group(title="Torch Configuration")
    torch_group.add_argument("--torch-device", dest="device", default=None, action=_Store,
                             help="torch device, e.g. cpu, cuda, cuda:0")


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
                                  max_steps_override=values["max_steps_override"])
    check_run_options(options)
    return options
