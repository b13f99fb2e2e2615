"""Legacy 0.x flat trainer files and mid-era curriculum/parameter_randomization keys."""
from __future__ import annotations

import textwrap

import pytest
import yaml

from trainer.config import load_run_options, write_run_options
from trainer.errors import ConfigError

SEED_000 = """
default:
  trainer: ppo
  batch_size: 1024
  beta: 5.0e-3
  buffer_size: 10240
  epsilon: 0.2
  hidden_units: 128
  lambd: 0.95
  learning_rate: 3.0e-4
  max_steps: 5.0e5
  memory_size: 256
  normalize: false
  num_epoch: 3
  num_layers: 2
  time_horizon: 64
  sequence_length: 64
  summary_freq: 1000
  use_recurrent: false
  summary_path: old_summaries
Dodge:
  gamma: 0.995
  lambd: 0.93
  batch_size: 2048
  buffer_size: 20480
  num_epoch: 5
  time_horizon: 1000
  max_steps: 5.0e6
  beta: 1.0e-2
  epsilon: 0.3
  normalize: true
  num_layers: 3
  hidden_units: 512
"""


def load_text(tmp_path, text: str):
    path = tmp_path / "legacy.yaml"
    path.write_text(textwrap.dedent(text))
    return load_run_options(str(path))


def test_seed_000_converts_to_expected_modern_values(tmp_path, caplog):
    with caplog.at_level("WARNING", logger="mlagents_like"):
        options = load_text(tmp_path, SEED_000)
    dodge = options.behaviors["Dodge"]
    hp = dodge.hyperparameters
    assert dodge.trainer_type == "ppo"
    assert (hp.batch_size, hp.buffer_size, hp.num_epoch, hp.beta, hp.epsilon, hp.lambd) == (
        2048, 20480, 5, 0.01, 0.3, 0.93)
    assert hp.learning_rate == 3.0e-4
    assert (dodge.network_settings.normalize, dodge.network_settings.num_layers) == (True, 3)
    assert dodge.network_settings.hidden_units == 512
    assert dodge.network_settings.memory is None                       # use_recurrent: false
    assert dodge.reward_signals["extrinsic"].gamma == 0.995             # flat gamma = extrinsic gamma
    assert (dodge.max_steps, dodge.time_horizon, dodge.summary_freq) == (5000000, 1000, 1000)
    # default became default_settings (0.x applied it to every unlisted brain)
    assert options.behavior_settings("Other").hyperparameters.batch_size == 1024
    # the warning carries the modern YAML, and names the dropped key
    assert "0.x" in caplog.text and "summary_path" in caplog.text
    modern_text = caplog.text.split("warning):\n", 1)[1]
    modern = yaml.safe_load(modern_text)
    assert modern["behaviors"]["Dodge"]["hyperparameters"]["lambd"] == 0.93
    assert modern["behaviors"]["Dodge"]["reward_signals"] == {"extrinsic": {"gamma": 0.995, "strength": 1.0}}


def test_use_recurrent_becomes_memory(tmp_path):
    options = load_text(tmp_path, """
        default: {trainer: ppo, use_recurrent: true, sequence_length: 32, memory_size: 64, batch_size: 64}
        A: {}
        B: {use_recurrent: false}
    """)
    memory = options.behaviors["A"].network_settings.memory
    assert (memory.sequence_length, memory.memory_size) == (32, 64)
    assert options.behaviors["B"].network_settings.memory is None


def test_legacy_without_trainer_is_an_error(tmp_path):
    with pytest.raises(ConfigError, match="'A' has no 'trainer:'"):
        load_text(tmp_path, "A: {batch_size: 32}\n")


def test_legacy_values_go_through_strict_checks(tmp_path):
    with pytest.raises(ConfigError, match="behaviors.A.hyperparameters.lambd"):
        load_text(tmp_path, "A: {trainer: ppo, lambd: 2.0}\n")
    assert load_text(tmp_path, "A: {trainer: poca}\n").behaviors["A"].trainer_type == "poca"


def test_legacy_sac_keys_go_to_sac_hyperparameters(tmp_path):
    options = load_text(tmp_path, "A: {trainer: sac, tau: 0.01, steps_per_update: 10, buffer_size: 1000, lambd: 0.9}\n")
    hp = options.behaviors["A"].hyperparameters
    assert (hp.tau, hp.steps_per_update, hp.buffer_size, hp.reward_signal_steps_per_update) == (0.01, 10.0, 1000, 10.0)


def test_mid_era_curriculum_and_parameter_randomization(tmp_path):
    options = load_text(tmp_path, """
        behaviors:
          Wall: {trainer_type: ppo}
        parameter_randomization:
          resampling-interval: 5000
          mass: {sampler-type: uniform, min_value: 0.5, max_value: 10}
          scale: {sampler-type: multirange_uniform, intervals: [[7, 10], [15, 20]]}
        curriculum:
          Wall:
            measure: progress
            thresholds: [0.1, 0.3]
            min_lesson_length: 100
            signal_smoothing: true
            parameters:
              wall_height: [1.5, 2.0, 2.5]
    """)
    params = options.environment_parameters
    assert params["mass"].curriculum[0].value.min_value == 0.5
    assert params["scale"].curriculum[0].value.intervals == ((7.0, 10.0), (15.0, 20.0))
    lessons = params["wall_height"].curriculum
    assert [lesson.name for lesson in lessons] == ["Lesson0", "Lesson1", "Lesson2"]
    assert [lesson.value.value for lesson in lessons] == [1.5, 2.0, 2.5]
    first = lessons[0].completion_criteria
    assert (first.behavior, first.measure, first.threshold, first.min_lesson_length) == ("Wall", "progress", 0.1, 100)
    assert lessons[1].completion_criteria.threshold == 0.3 and lessons[2].completion_criteria is None


def test_modern_file_with_typo_is_not_taken_for_legacy(tmp_path):
    with pytest.raises(ConfigError, match="Did you mean 'behaviors'"):
        load_text(tmp_path, "behavior:\n  A: {trainer_type: ppo}\n")


def test_0x_step_counts_become_agent_steps_at_first_contact_and_1x_ones_stay(tmp_path, caplog):
    with caplog.at_level("WARNING", logger="mlagents_like"):
        options = load_text(tmp_path, SEED_000)
    assert options.legacy_env_steps
    assert "Dodge: max_steps 5000000, summary_freq 1000" in caplog.text  # the load-time note, with numbers
    before = options.behavior_settings("Dodge")
    after = options.behavior_settings("Dodge", agents=14)
    assert (before.max_steps, before.summary_freq) == (5000000, 1000)
    assert (after.max_steps, after.summary_freq) == (70000000, 14000)  # the dodge thesis' 5e6 on 14 agents (docs/stub-tasks.md)
    modern = tmp_path / "modern.yaml"
    modern.write_text("behaviors:\n  Dodge:\n    trainer_type: ppo\n    max_steps: 2000\n    summary_freq: 500\n")
    options = load_run_options(str(modern))
    assert not options.legacy_env_steps
    settings = options.behavior_settings("Dodge", agents=14)
    assert (settings.max_steps, settings.summary_freq) == (2000, 500)


def test_a_0x_behavior_converted_at_first_contact_is_written_with_agent_steps_once(tmp_path):
    options = load_text(tmp_path, SEED_000)
    converted = options.with_agent_steps("Dodge", 14)
    dodge = converted.as_dict()["behaviors"]["Dodge"]
    assert (dodge["max_steps"], dodge["summary_freq"]) == (70000000, 14000)  # 5e6 and 1000 x 14
    assert options.as_dict()["behaviors"]["Dodge"]["max_steps"] == 5000000  # the loaded options are kept
    # a converted behavior is not multiplied again, by a later contact or by behavior_settings
    assert converted.with_agent_steps("Dodge", 14) is converted
    assert converted.behavior_settings("Dodge", agents=14).max_steps == 70000000
    # written and read back, configuration.yaml is a modern file with the same counts
    path = write_run_options(converted, str(tmp_path / "out"))
    again = load_run_options(path)
    assert not again.legacy_env_steps
    assert (again.behaviors["Dodge"].max_steps, again.behaviors["Dodge"].summary_freq) == (70000000, 14000)
    modern = tmp_path / "modern.yaml"
    modern.write_text("behaviors:\n  Dodge:\n    trainer_type: ppo\n    max_steps: 2000\n")
    plain = load_run_options(str(modern))
    assert plain.with_agent_steps("Dodge", 14) is plain  # a 1.x file is unaffected
