"""What of the Release-22 schema this trainer can train with, checked before anything starts.

The loader accepts every key ML-Agents accepts (so a config is never "unknown" here just because
a feature is missing), and the resolved configuration.yaml keeps them all. A feature that would
change what is trained, but that the PPO room does not implement, must not be dropped quietly:
``check_supported`` refuses it with one message per run, before the results folder or a
simulator exists, naming each key and what to do.
"""
from __future__ import annotations

from trainer.config.settings import RunOptions, TrainerSettings
from trainer.errors import ConfigError

# reward signals the trainers compute (trainer/ppo/trainer.py and trainer/sac/trainer.py check
# the same list: both take every provider of trainer/common/reward_providers.py)
SUPPORTED_REWARD_SIGNALS = ("extrinsic", "curiosity", "rnd", "gail")


def unsupported(ts: TrainerSettings) -> list[tuple[str, str]]:
    """(key path inside a behavior block, what to do) for each unsupported feature ``ts`` uses."""
    found = []
    for name in ts.reward_signals:
        if name not in SUPPORTED_REWARD_SIGNALS:
            found.append((f"reward_signals.{name}",
                          f"remove it; supported reward signals: {', '.join(SUPPORTED_REWARD_SIGNALS)}"))
    return found


def check_supported(options: RunOptions) -> None:
    """ConfigError listing every unsupported feature of every behavior block (default_settings
    included: it applies to behaviors the YAML does not name)."""
    blocks = {f"behaviors.{name}": ts for name, ts in options.behaviors.items()}
    if options.default_settings is not None:
        blocks = {"default_settings": options.default_settings, **blocks}
    problems = [f"'{prefix}.{key}': {advice}" for prefix, ts in blocks.items() for key, advice in unsupported(ts)]
    if problems:
        raise ConfigError(
            "this configuration uses features mlagents-like-learn does not support yet, so it "
            "would not train what it says:\n  " + "\n  ".join(problems)
        )


def demo_paths(settings: TrainerSettings) -> list[tuple[str, str]]:
    """(YAML key, demo_path) of a behavior's TrainerSettings: GAIL's and behavioral_cloning's."""
    found = []
    gail = settings.reward_signals.get("gail")
    if gail is not None:
        found.append(("reward_signals.gail.demo_path", gail.demo_path))
    if settings.behavioral_cloning is not None:
        found.append(("behavioral_cloning.demo_path", settings.behavioral_cloning.demo_path))
    return found


def check_demo_paths(options: RunOptions) -> None:
    """ConfigError unless every demo_path of the run names a .demo file or a folder holding one
    (trainer/demonstrations.py reads them once the behavior connects)."""
    blocks = {f"behaviors.{name}": ts for name, ts in options.behaviors.items()}
    if options.default_settings is not None:
        blocks = {"default_settings": options.default_settings, **blocks}
    problems = []
    for prefix, ts in blocks.items():
        for key, path in demo_paths(ts):
            from protos.demo_file import DemoFileError, demo_files  # protobuf: only a run with demonstrations

            try:
                demo_files(path)
            except DemoFileError as error:
                problems.append(f"'{prefix}.{key}': {error}")
    if problems:
        raise ConfigError("\n  ".join(["a demonstration cannot be read:", *problems]))


def goal_conditioning_note(observation_specs, ts: TrainerSettings) -> str | None:
    """A warning when a behavior sends goal-signal observations that ML-Agents would feed to its
    hyper-network (goal_conditioning_type: hyper, the default); they are plain inputs here."""
    from protos.types import ObservationType  # numpy: the checks above run before the simulators launch

    goals = [o.name for o in observation_specs if o.observation_type == ObservationType.GOAL_SIGNAL]
    if not goals or ts.network_settings.goal_conditioning_type != "hyper":
        return None
    return (f"goal-signal observation(s) {', '.join(goals)} are concatenated with the other inputs, "
            "as with goal_conditioning_type: none; the hyper-network conditioning is not implemented. "
            "Set goal_conditioning_type: none to silence this.")
