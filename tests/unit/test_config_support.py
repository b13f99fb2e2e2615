"""Features of the Release-22 schema that this trainer does not implement are refused, by key."""
from __future__ import annotations

import textwrap

import pytest

from protos.types import DimensionProperty, ObservationSpec, ObservationType
from trainer.config import load_run_options
from trainer.config.support import check_supported, goal_conditioning_note, unsupported
from trainer.errors import ConfigError


def options(tmp_path, text: str):
    path = tmp_path / "c.yaml"
    path.write_text(textwrap.dedent(text))
    return load_run_options(str(path))


def test_plain_ppo_config_is_supported(tmp_path):
    opts = options(tmp_path, """
        behaviors:
          Basic:
            trainer_type: ppo
            hyperparameters: {shared_critic: true}
            network_settings: {normalize: true, goal_conditioning_type: none, memory: {memory_size: 8}}
            reward_signals: {extrinsic: {gamma: 0.9}, curiosity: {strength: 0.02}, rnd: {}}
    """)
    assert unsupported(opts.behaviors["Basic"]) == []
    check_supported(opts)  # no error


def test_imitation_self_play_memory_and_intrinsic_signals_are_all_supported_with_ppo(tmp_path):
    opts = options(tmp_path, """
        behaviors:
          Striker:
            trainer_type: ppo
            hyperparameters: {shared_critic: true}
            network_settings: {memory: {memory_size: 64, sequence_length: 16}}
            reward_signals:
              extrinsic: {}
              rnd: {}
              gail: {demo_path: a.demo}
            behavioral_cloning: {demo_path: a.demo}
            self_play: {save_steps: 100}
          Goalie:
            trainer_type: ppo
    """)
    assert unsupported(opts.behaviors["Striker"]) == []  # gail, behavioral_cloning, self_play: all trained
    assert unsupported(opts.behaviors["Goalie"]) == []
    check_supported(opts)  # no error


def test_sac_is_supported_with_memory_and_intrinsic_signals(tmp_path):
    opts = options(tmp_path, """
        behaviors:
          Plain: {trainer_type: sac, network_settings: {normalize: true}}
          Fancy:
            trainer_type: sac
            network_settings: {memory: {memory_size: 8, sequence_length: 4}}
            reward_signals: {extrinsic: {}, curiosity: {}, rnd: {}}
    """)
    assert unsupported(opts.behaviors["Plain"]) == []
    assert unsupported(opts.behaviors["Fancy"]) == []
    check_supported(opts)


def test_poca_with_memory_is_supported_and_default_settings_are_checked_too(tmp_path):
    opts = options(tmp_path, """
        default_settings:
          trainer_type: poca
          network_settings: {memory: {memory_size: 16, sequence_length: 4}}
        behaviors: {}
    """)
    check_supported(opts)  # POCA trains with memory (docs/poca.md)
    # the loader knows only the reference's reward signals; one it let through would be refused
    signals = opts.default_settings.reward_signals
    signals["foo"] = signals["extrinsic"]
    with pytest.raises(ConfigError, match=r"'default_settings\.reward_signals\.foo'"):
        check_supported(opts)


def test_goal_signals_warn_only_with_hyper_conditioning(tmp_path):
    opts = options(tmp_path, """
        behaviors:
          Hyper: {trainer_type: ppo}
          Plain: {trainer_type: ppo, network_settings: {goal_conditioning_type: none}}
    """)
    vector = ObservationSpec((4,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "obs")
    goal = ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.GOAL_SIGNAL, "goal")
    note = goal_conditioning_note([vector, goal], opts.behaviors["Hyper"])
    assert note is not None and "goal" in note and "goal_conditioning_type: none" in note
    assert goal_conditioning_note([vector, goal], opts.behaviors["Plain"]) is None
    assert goal_conditioning_note([vector], opts.behaviors["Hyper"]) is None
