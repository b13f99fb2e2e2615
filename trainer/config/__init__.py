"""Run configuration: the ML-Agents Release-22 YAML schema, legacy conversion and the CLI.

Only typed, frozen settings and their loading and validation live here; the run's changing state
(the curriculum's current lessons: ``trainer.curriculum``) does not.
"""
from __future__ import annotations

from trainer.config.env_params import (
    CompletionCriteria,
    ConstantSampler,
    EnvironmentParameterSettings,
    GaussianSampler,
    HmmSampler,
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
    OnPolicySettings,
    POCASettings,
    PPOSettings,
    RewardSignalSettings,
    RNDSettings,
    RunOptions,
    SACSettings,
    SelfPlaySettings,
    TorchSettings,
    TrainerSettings,
)
from trainer.config.loader import load_run_options, run_options_from_dict, write_run_options
from trainer.config.cli_args import build_parser, parse_run_options

__all__ = [
    "BehavioralCloningSettings", "CheckpointSettings", "CompletionCriteria", "ConstantSampler",
    "CuriositySettings", "EngineSettings", "EnvSettings",
    "EnvironmentParameterSettings", "GAILSettings", "GaussianSampler", "Lesson", "MemorySettings",
    "HmmSampler", "MultiRangeUniformSampler", "NetworkSettings", "OnPolicySettings", "POCASettings", "PPOSettings", "RNDSettings", "RewardSignalSettings",
    "RunOptions", "SACSettings", "Sampler", "SelfPlaySettings", "TorchSettings", "TrainerSettings", "UniformSampler",
    "assign_seeds", "build_parser", "load_run_options", "parse_run_options", "run_options_from_dict",
    "write_run_options",
]
