"""Run configuration: the ML-Agents Release-22 YAML schema, legacy conversion and the CLI.

Import order matters: env_params pulls in param_manager at its end.
"""
from __future__ import annotations

from trainer.config.env_params import (  # noqa: F401  (first: see module docstring)
    CompletionCriteria,
    ConstantSampler,
    EnvironmentParameterManager,
    EnvironmentParameterSettings,
    GaussianSampler,
    Lesson,
    MultiRangeUniformSampler,
    Sampler,
    UniformSampler,
    assign_seeds,
)
from trainer.config.settings import (
    BehavioralCloningSettings,
    CheckpointSettings,
    CuriositySettings,
    EngineSettings,
    EnvSettings,
    GAILSettings,
    MemorySettings,
    NetworkSettings,
    PPOSettings,
    RewardSignalSettings,
    RNDSettings,
    RunOptions,
    SelfPlaySettings,
    TorchSettings,
    TrainerSettings,
)
from trainer.config.loader import load_run_options, run_options_from_dict, write_run_options
from trainer.config.cli_args import build_parser, parse_run_options

__all__ = [
    "BehavioralCloningSettings", "CheckpointSettings", "CompletionCriteria", "ConstantSampler",
    "CuriositySettings", "EngineSettings", "EnvSettings", "EnvironmentParameterManager",
    "EnvironmentParameterSettings", "GAILSettings", "GaussianSampler", "Lesson", "MemorySettings",
    "MultiRangeUniformSampler", "NetworkSettings", "PPOSettings", "RNDSettings", "RewardSignalSettings",
    "RunOptions", "Sampler", "SelfPlaySettings", "TorchSettings", "TrainerSettings", "UniformSampler",
    "assign_seeds", "build_parser", "load_run_options", "parse_run_options", "run_options_from_dict",
    "write_run_options",
]
