"""Defaults from the spec's tables, default_settings deep merge, behavior lookup, round trip."""
from __future__ import annotations

import os
import textwrap

import pytest
import yaml

from trainer.config import (
    EngineSettings,
    EnvSettings,
    CheckpointSettings,
    RunOptions,
    TrainerSettings,
    load_run_options,
    run_options_from_dict,
    write_run_options,
)
from trainer.errors import ConfigError

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load_text(tmp_path, text: str) -> RunOptions:
    path = tmp_path / "config.yaml"
    path.write_text(textwrap.dedent(text))
    return load_run_options(str(path))


def test_trainer_defaults_equal_spec_tables():
    ts = TrainerSettings()
    hp = ts.hyperparameters
    assert (hp.batch_size, hp.buffer_size, hp.learning_rate, hp.beta, hp.epsilon, hp.lambd, hp.num_epoch) == (
        1024, 10240, 3.0e-4, 5.0e-3, 0.2, 0.95, 3)
    assert hp.shared_critic is False
    assert (hp.learning_rate_schedule, hp.beta_schedule, hp.epsilon_schedule) == ("linear", "linear", "linear")
    net = ts.network_settings
    assert (net.normalize, net.hidden_units, net.num_layers, net.vis_encode_type) == (False, 128, 2, "simple")
    assert (net.memory, net.goal_conditioning_type, net.deterministic) == (None, "hyper", False)
    assert list(ts.reward_signals) == ["extrinsic"]
    assert (ts.reward_signals["extrinsic"].gamma, ts.reward_signals["extrinsic"].strength) == (0.99, 1.0)
    assert (ts.keep_checkpoints, ts.even_checkpoints, ts.checkpoint_interval, ts.max_steps) == (5, False, 500000, 500000)
    assert (ts.time_horizon, ts.summary_freq, ts.threaded, ts.init_path) == (64, 50000, False, None)
    assert ts.self_play is None and ts.behavioral_cloning is None


def test_sac_defaults_equal_spec_table_and_round_trip(tmp_path):
    options = load_text(tmp_path, """
        behaviors:
          A: {trainer_type: sac}
          B: {trainer_type: sac, hyperparameters: {steps_per_update: 10, learning_rate_schedule: linear}}
          C: {trainer_type: sac, hyperparameters: {steps_per_update: 10, reward_signal_steps_per_update: 2.5}}
    """)
    hp = options.behaviors["A"].hyperparameters
    assert (hp.batch_size, hp.buffer_size, hp.learning_rate, hp.learning_rate_schedule) == (128, 50000, 3.0e-4, "constant")
    assert (hp.buffer_init_steps, hp.tau, hp.steps_per_update, hp.save_replay_buffer) == (0, 0.005, 1.0, False)
    assert (hp.init_entcoef, hp.reward_signal_steps_per_update) == (1.0, 1.0)
    b = options.behaviors["B"].hyperparameters
    assert (b.steps_per_update, b.reward_signal_steps_per_update, b.learning_rate_schedule) == (10.0, 10.0, "linear")
    assert options.behaviors["C"].hyperparameters.reward_signal_steps_per_update == 2.5
    path = write_run_options(options, str(tmp_path / "out"))
    assert load_run_options(path).behaviors == options.behaviors


def test_env_engine_checkpoint_defaults_equal_cli_table():
    env = EnvSettings()
    assert (env.env_path, env.env_args, env.base_port, env.num_envs, env.num_areas) == (None, None, 5005, 1, 1)
    assert (env.timeout_wait, env.seed, env.max_lifetime_restarts) == (60, -1, 10)
    assert (env.restarts_rate_limit_n, env.restarts_rate_limit_period_s, env.bind) == (1, 60, "127.0.0.1")
    eng = EngineSettings()
    assert (eng.width, eng.height, eng.quality_level, eng.time_scale) == (84, 84, 5, 20.0)
    assert (eng.target_frame_rate, eng.capture_frame_rate, eng.no_graphics, eng.no_graphics_monitor) == (
        -1, 60, False, False)
    ck = CheckpointSettings()
    assert (ck.run_id, ck.initialize_from, ck.load_model, ck.resume, ck.force) == ("ppo", None, False, False, False)
    assert (ck.train_model, ck.inference, ck.results_dir) == (False, False, "results")


def test_sub_block_defaults_and_derived_values(tmp_path):
    options = load_text(tmp_path, """
        behaviors:
          A:
            trainer_type: ppo
            max_steps: 5.0e5
            keep_checkpoints: 4
            even_checkpoints: true
            network_settings: {memory: {}}
            self_play: {save_steps: 300}
            behavioral_cloning: {demo_path: demos/a.demo}
            reward_signals:
              curiosity: {}
              rnd: {}
              gail: {demo_path: demos/a.demo}
    """)
    ts = options.behaviors["A"]
    assert ts.max_steps == 500000                      # "5.0e5" is a string to PyYAML
    assert ts.checkpoint_interval == 500000 // 4       # even_checkpoints
    assert (ts.network_settings.memory.sequence_length, ts.network_settings.memory.memory_size) == (64, 128)
    assert ts.self_play.team_change == 1500            # 5 x save_steps
    assert (ts.self_play.swap_steps, ts.self_play.window, ts.self_play.initial_elo) == (2000, 10, 1200.0)
    bc = ts.behavioral_cloning
    assert (bc.steps, bc.strength, bc.samples_per_update, bc.num_epoch, bc.batch_size) == (0, 1.0, 0, None, None)
    assert ts.reward_signals["curiosity"].learning_rate == 3e-4
    assert ts.reward_signals["rnd"].learning_rate == 1e-4
    gail = ts.reward_signals["gail"]
    assert (gail.use_actions, gail.use_vail, gail.gamma, gail.strength) == (False, False, 0.99, 1.0)


def test_schedule_copy_rule(tmp_path):
    options = load_text(tmp_path, """
        behaviors:
          A: {trainer_type: ppo, hyperparameters: {learning_rate_schedule: constant}}
          B: {trainer_type: ppo, hyperparameters: {learning_rate_schedule: constant, beta_schedule: linear}}
    """)
    a, b = options.behaviors["A"].hyperparameters, options.behaviors["B"].hyperparameters
    assert (a.beta_schedule, a.epsilon_schedule) == ("constant", "constant")
    assert (b.beta_schedule, b.epsilon_schedule) == ("linear", "constant")


def test_default_settings_deep_merged_under_behaviors(tmp_path):
    options = load_text(tmp_path, """
        default_settings:
          trainer_type: ppo
          hyperparameters: {batch_size: 64, buffer_size: 640, beta: 0.01}
          network_settings: {hidden_units: 32}
          max_steps: 1000
        behaviors:
          Walker:
            hyperparameters: {batch_size: 128}
            network_settings: {num_layers: 3}
    """)
    walker = options.behaviors["Walker"]
    assert walker.hyperparameters.batch_size == 128      # behavior wins
    assert walker.hyperparameters.buffer_size == 640     # from default_settings, same nested block
    assert walker.hyperparameters.beta == 0.01
    assert walker.network_settings.hidden_units == 32
    assert walker.network_settings.num_layers == 3
    assert walker.max_steps == 1000
    other = options.behavior_settings("Crawler")         # unlisted: default_settings
    assert other.hyperparameters.batch_size == 64 and other.network_settings.num_layers == 2


def test_unlisted_behavior_with_config_file_is_an_error(tmp_path):
    options = load_text(tmp_path, "behaviors:\n  Basic: {trainer_type: ppo}\n")
    with pytest.raises(ConfigError) as info:
        options.behavior_settings("Dodge")
    assert "Dodge" in str(info.value) and "Basic" in str(info.value)


def test_unlisted_behavior_without_config_file_gets_defaults_with_warning(caplog):
    with caplog.at_level("WARNING", logger="mlagents_like"):
        settings = RunOptions().behavior_settings("Dodge")
    assert settings == TrainerSettings()
    assert "Dodge" in caplog.text


def test_initialize_from_sets_init_paths(tmp_path):
    options = load_text(tmp_path, """
        behaviors:
          A: {trainer_type: ppo}
          B: {trainer_type: ppo, init_path: B-100.pt}
          C: {trainer_type: ppo, init_path: /abs/c.pt}
        checkpoint_settings: {initialize_from: old, results_dir: out}
    """)
    assert options.behavior_settings("A").init_path == os.path.join("out", "old", "A", "checkpoint.pt")
    assert options.behavior_settings("B").init_path == os.path.join("out", "old", "B", "B-100.pt")
    assert options.behavior_settings("C").init_path == "/abs/c.pt"


def test_configuration_yaml_round_trip(tmp_path):
    options = load_text(tmp_path, """
        default_settings: {trainer_type: ppo, summary_freq: 100}
        behaviors:
          A:
            trainer_type: ppo
            network_settings: {memory: {sequence_length: 16, memory_size: 32}}
        environment_parameters:
          gravity: 9.81
          scale: {sampler_type: uniform, sampler_parameters: {min_value: 0.5, max_value: 3.0, seed: 43}}
          wall:
            curriculum:
              - name: Low
                value: {sampler_type: multirangeuniform, sampler_parameters: {intervals: [[1, 2], [5, 6]]}}
                completion_criteria: {behavior: A, threshold: 0.5, measure: progress}
              - {name: High, value: 4}
        env_settings: {seed: 7, env_path: "stub:basic", num_envs: 2}
        checkpoint_settings: {run_id: rt}
    """)
    path = write_run_options(options, str(tmp_path / "out"))
    with open(path) as stream:
        written = yaml.safe_load(stream)
    assert list(written) == ["default_settings", "behaviors", "env_settings", "engine_settings",
                             "environment_parameters", "checkpoint_settings", "torch_settings", "debug"]
    assert written["environment_parameters"]["gravity"] == {"curriculum": [{
        "value": {"sampler_type": "constant", "sampler_parameters": {"seed": -1, "value": 9.81}},
        "name": "gravity", "completion_criteria": None}]}
    reloaded = load_run_options(path)
    assert reloaded.behaviors == options.behaviors
    assert reloaded.default_settings == options.default_settings
    assert reloaded.environment_parameters == options.environment_parameters
    assert (reloaded.env_settings, reloaded.engine_settings) == (options.env_settings, options.engine_settings)
    assert reloaded.checkpoint_settings == options.checkpoint_settings
    assert reloaded.as_dict() == options.as_dict()


@pytest.mark.parametrize("name, behavior", [("basic", "Basic"), ("ball3d", "3DBall"), ("basic_sac", "Basic"),
                                            ("ball3d_sac", "3DBall"), ("dodge", "Dodge"), ("dodge_legacy", "Dodge"),
                                            ("creature_walk", "Creature"), ("creature_clock", "Creature")])
def test_shipped_configs_load(name, behavior):
    options = load_run_options(os.path.join(REPO, "configs", f"{name}.yaml"))
    assert behavior in options.behaviors


def test_basic_and_ball3d_values():
    basic = load_run_options(os.path.join(REPO, "configs", "basic.yaml")).behaviors["Basic"]
    hp = basic.hyperparameters
    assert (hp.batch_size, hp.buffer_size, hp.beta, hp.lambd, hp.num_epoch) == (32, 256, 5e-3, 0.95, 3)
    assert (basic.network_settings.hidden_units, basic.network_settings.num_layers) == (20, 1)
    assert (basic.reward_signals["extrinsic"].gamma, basic.max_steps, basic.time_horizon) == (0.9, 20000, 3)
    assert (basic.summary_freq, basic.checkpoint_interval, basic.keep_checkpoints) == (2000, 2000, 5)
    ball = load_run_options(os.path.join(REPO, "configs", "ball3d.yaml")).behaviors["3DBall"]
    hp = ball.hyperparameters
    assert (hp.batch_size, hp.buffer_size, hp.beta, hp.lambd) == (64, 12000, 1e-3, 0.99)
    assert (ball.network_settings.normalize, ball.max_steps, ball.time_horizon, ball.summary_freq) == (
        True, 500000, 1000, 12000)


def test_run_options_from_dict_without_file_has_no_config_path():
    options = run_options_from_dict({"behaviors": {"A": {"trainer_type": "ppo"}}})
    assert options.config_path is None
    assert options.behaviors["A"] == TrainerSettings()


def test_dodge_configs_carry_the_dodge_thesis_values_and_agree(caplog):
    """configs/dodge.yaml and the 0.x flat configs/dodge_legacy.yaml: the dodge thesis' hyperparameters
    (gamma 0.995, lambd 0.93, batch 2048, buffer 20480, 5 epochs, horizon 1000, beta 1e-2,
    epsilon 0.3, normalize, 3 x 512, 5e6 steps); the legacy one loads with its warning."""
    modern = load_run_options(os.path.join(REPO, "configs", "dodge.yaml")).behaviors["Dodge"]
    with caplog.at_level("WARNING", logger="mlagents_like"):
        legacy = load_run_options(os.path.join(REPO, "configs", "dodge_legacy.yaml")).behaviors["Dodge"]
    assert "0.x" in caplog.text
    for dodge in (modern, legacy):
        hp, net = dodge.hyperparameters, dodge.network_settings
        assert (hp.batch_size, hp.buffer_size, hp.num_epoch, hp.beta, hp.epsilon, hp.lambd, hp.learning_rate) == (
            2048, 20480, 5, 1e-2, 0.3, 0.93, 3e-4)
        assert (net.normalize, net.num_layers, net.hidden_units, net.memory) == (True, 3, 512, None)
        assert dodge.reward_signals["extrinsic"].gamma == 0.995
        assert (dodge.max_steps, dodge.time_horizon) == (5_000_000, 1000)
    assert modern.hyperparameters == legacy.hyperparameters and modern.network_settings == legacy.network_settings


def test_mimic_config_carries_the_seed_values_restated_for_its_rate():
    """configs/mimic.yaml: the mimic thesis' final hyperparameters (lr 1e-4 linear, beta 5e-4, epsilon
    0.2, lambd 0.95, 2 epochs, normalize, 2 x 1024, checkpoints every 200k, summaries every 25k); its
    per-decision values at 250 Hz (gamma 0.99, horizon 1250 = 5 s, 5e7 steps, buffer 20000 = 80 s and
    batch 1000 = 4 s of experience, so the same gradient steps per simulated second) restated for the
    50 decisions per second it runs at, and the motion parameter (0, stand)."""
    options = load_run_options(os.path.join(REPO, "configs", "mimic.yaml"))
    mimic = options.behaviors["Mimic"]
    hp, net = mimic.hyperparameters, mimic.network_settings
    assert (hp.learning_rate, hp.beta, hp.epsilon, hp.lambd, hp.num_epoch) == (1e-4, 5e-4, 0.2, 0.95, 2)
    assert hp.learning_rate_schedule == "linear"
    assert (net.normalize, net.num_layers, net.hidden_units) == (True, 2, 1024)
    rate = options.environment_parameters["decision_hz"].curriculum[0].value.value
    assert rate == 50
    # the same discount per simulated second and the same horizon and budget in simulated seconds
    assert mimic.reward_signals["extrinsic"].gamma == pytest.approx(0.99 ** (250 / rate), abs=5e-4)
    assert mimic.reward_signals["extrinsic"].strength == 1.0
    assert (mimic.time_horizon / rate, mimic.max_steps / rate) == (1250 / 250, 50_000_000 / 250)
    assert (hp.buffer_size / rate, hp.batch_size / rate) == (20000 / 250, 1000 / 250)
    assert (mimic.summary_freq, mimic.checkpoint_interval, mimic.keep_checkpoints) == (25000, 200000, 5)
    assert set(options.environment_parameters) == {"motion", "decision_hz"}
