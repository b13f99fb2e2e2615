"""Every bad config gives one ConfigError naming the key path (and the closest valid key)."""
from __future__ import annotations

import textwrap

import pytest

from trainer.config import load_run_options
from trainer.errors import ConfigError, UserError


def error_for(tmp_path, text: str) -> str:
    path = tmp_path / "bad.yaml"
    path.write_text(textwrap.dedent(text))
    with pytest.raises(ConfigError) as info:
        load_run_options(str(path))
    assert isinstance(info.value, UserError) and info.value.exit_code == 2
    return str(info.value)


def ppo(block: str) -> str:
    return "behaviors:\n  3DBall:\n    trainer_type: ppo\n" + textwrap.indent(textwrap.dedent(block), "    ")


def test_unknown_hyperparameter_names_path_and_suggestion(tmp_path):
    message = error_for(tmp_path, ppo("hyperparameters: {lamda: 0.9}"))
    assert "behaviors.3DBall.hyperparameters.lamda" in message
    assert "Did you mean 'lambd'?" in message
    assert "bad.yaml" in message


@pytest.mark.parametrize("text, path, suggestion", [
    ("behavior:\n  A: {}\n", "behavior", "behaviors"),
    ("env_settings: {num_env: 2}\n", "env_settings.num_env", "num_envs"),
    ("engine_settings: {timescale: 2}\n", "engine_settings.timescale", "time_scale"),
    ("checkpoint_settings: {runid: x}\n", "checkpoint_settings.runid", "run_id"),
    (ppo("network_settings: {hiden_units: 3}"), "behaviors.3DBall.network_settings.hiden_units", "hidden_units"),
    (ppo("reward_signals: {extrinsic: {gama: 0.9}}"), "behaviors.3DBall.reward_signals.extrinsic.gama", "gamma"),
    (ppo("reward_signals: {curiousity: {}}"), "behaviors.3DBall.reward_signals.curiousity", "curiosity"),
    (ppo("max_step: 10"), "behaviors.3DBall.max_step", "max_steps"),
    ("environment_parameters:\n  g: {sampler_type: uniform, sampler_parameters: {min: 1}}\n",
     "environment_parameters.g.sampler_parameters.min", "min_value"),
])
def test_unknown_keys_everywhere(tmp_path, text, path, suggestion):
    message = error_for(tmp_path, text)
    assert f"'{path}'" in message
    assert f"Did you mean '{suggestion}'?" in message


@pytest.mark.parametrize("block, path, expected, given", [
    ("hyperparameters: {batch_size: big}", "hyperparameters.batch_size", "integer", "the string 'big'"),
    ("hyperparameters: {batch_size: 32.5}", "hyperparameters.batch_size", "integer", "32.5"),
    ("hyperparameters: {learning_rate: fast}", "hyperparameters.learning_rate", "number", "'fast'"),
    ("network_settings: {normalize: 'yes'}", "network_settings.normalize", "true or false", "'yes'"),
    ("network_settings: {normalize: 1}", "network_settings.normalize", "true or false", "1"),
    ("hyperparameters: {num_epoch: true}", "hyperparameters.num_epoch", "integer", "boolean true"),
    ("hyperparameters: [1, 2]", "hyperparameters", "mapping", "[1, 2]"),
])
def test_wrong_types(tmp_path, block, path, expected, given):
    message = error_for(tmp_path, ppo(block))
    assert f"behaviors.3DBall.{path}" in message
    assert expected in message and given in message


@pytest.mark.parametrize("block, path, fragment", [
    ("hyperparameters: {batch_size: 2048, buffer_size: 1024}", "hyperparameters.batch_size", "buffer_size"),
    ("hyperparameters: {lambd: 1.5}", "hyperparameters.lambd", "[0, 1]"),
    ("hyperparameters: {epsilon: 0}", "hyperparameters.epsilon", "> 0"),
    ("reward_signals: {extrinsic: {gamma: -0.1}}", "reward_signals.extrinsic.gamma", "[0, 1]"),
    ("network_settings: {hidden_units: 0}", "network_settings.hidden_units", "> 0"),
    ("network_settings: {num_layers: 0}", "network_settings.num_layers", ">= 1"),
    ("network_settings: {memory: {memory_size: 33}}", "network_settings.memory.memory_size", "even"),
    ("network_settings: {memory: {memory_size: 0}}", "network_settings.memory.memory_size", "> 0"),
    ("hyperparameters: {batch_size: 32, buffer_size: 64}\nnetwork_settings: {memory: {sequence_length: 64}}",
     "network_settings.memory.sequence_length", "batch_size"),
    ("hyperparameters: {learning_rate_schedule: exponential}", "hyperparameters.learning_rate_schedule",
     "linear, constant"),
    ("network_settings: {vis_encode_type: nature}", "network_settings.vis_encode_type", "nature_cnn"),
    ("reward_signals: {gail: {}}", "reward_signals.gail.demo_path", "required"),
    ("behavioral_cloning: {steps: 3}", "behavioral_cloning.demo_path", "required"),
])
def test_impossible_values(tmp_path, block, path, fragment):
    message = error_for(tmp_path, ppo(block))
    assert f"behaviors.3DBall.{path}" in message
    assert fragment in message


def test_poca_is_accepted_with_its_own_hyperparameters(tmp_path):
    from trainer.config.settings import POCASettings

    path = tmp_path / "poca.yaml"
    path.write_text("behaviors:\n  A: {trainer_type: poca, hyperparameters: {lambd: 0.9}}\n")
    settings = load_run_options(str(path)).behaviors["A"]
    assert settings.trainer_type == "poca" and settings.hyperparameters == POCASettings(lambd=0.9)
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: poca, hyperparameters: {shared_critic: true}}\n")
    assert "Unknown key 'behaviors.A.hyperparameters.shared_critic'" in message


def test_sac_keys_are_checked(tmp_path):
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: sac, hyperparameters: {beta: 0.1}}\n")
    assert "Unknown key 'behaviors.A.hyperparameters.beta'" in message
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: sac, hyperparameters: {taw: 0.1}}\n")
    assert "Did you mean 'tau'?" in message
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: sac, hyperparameters: {tau: 1.5}}\n")
    assert "behaviors.A.hyperparameters.tau" in message and "(0, 1]" in message
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: sac, hyperparameters: {save_replay_buffer: 3}}\n")
    assert "behaviors.A.hyperparameters.save_replay_buffer" in message and "true or false" in message
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: sac, hyperparameters: {steps_per_update: 0}}\n")
    assert "behaviors.A.hyperparameters.steps_per_update" in message
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: sac, hyperparameters: {batch_size: 64, "
                                  "buffer_size: 32}}\n")
    assert "must not exceed" in message


def test_unknown_trainer_type_suggests(tmp_path):
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: ppoo}\n")
    assert "unknown trainer type 'ppoo'" in message and "Did you mean 'ppo'?" in message


def test_hyperparameters_need_trainer_type(tmp_path):
    message = error_for(tmp_path, "behaviors:\n  A: {hyperparameters: {batch_size: 8}}\n")
    assert "behaviors.A" in message and "trainer_type" in message


def test_malformed_yaml_gives_file_line_and_column(tmp_path):
    message = error_for(tmp_path, "behaviors:\n  A:\n    trainer_type: ppo\n   bad: [1, 2\n")
    assert "bad.yaml:" in message and "YAML syntax error" in message
    location = message.split("bad.yaml:")[1].split(":")
    assert location[0].isdigit() and location[1].isdigit()


def test_duplicate_key_is_an_error(tmp_path):
    message = error_for(tmp_path, "behaviors:\n  A: {trainer_type: ppo}\n  A: {trainer_type: ppo}\n")
    assert "bad.yaml:3:3" in message and "'A' is given twice" in message


def test_missing_file_empty_file_and_non_mapping(tmp_path):
    with pytest.raises(ConfigError, match="could not be found"):
        load_run_options(str(tmp_path / "nope.yaml"))
    assert "empty" in error_for(tmp_path, "")
    assert "mapping at the top level" in error_for(tmp_path, "- a\n- b\n")


def test_env_settings_cross_checks(tmp_path):
    assert "needs --env" in error_for(tmp_path, "env_settings: {num_envs: 2}\n")
    assert "env_settings.num_areas" in error_for(tmp_path, "env_settings: {num_areas: 0}\n")
    assert "65535" in error_for(tmp_path, "env_settings: {base_port: 70000}\n")


@pytest.mark.parametrize("params, fragment", [
    ("p: {sampler_type: uniform, sampler_parameters: {min_value: 2, max_value: 1}}", "greater than max_value"),
    ("p: {sampler_type: multirangeuniform, sampler_parameters: {intervals: [[3, 1]]}}", "intervals[0]"),
    ("p: {sampler_type: unifrom, sampler_parameters: {}}", "Did you mean 'uniform'?"),
    ("p: {curriculum: [{name: L0, value: 1}, {name: L1, value: 2}]}", "needs completion_criteria"),
    ("p: {curriculum: [{name: L0, value: 1, completion_criteria: {behavior: A, measure: progress, "
     "threshold: 1.5}}, {name: L1, value: 2}]}", "[0, 1]"),
    ("p: {curriculum: [{name: L0, value: 1, completion_criteria: {behavior: Ghost}}, {name: L1, value: 2}]}",
     "'Ghost'"),
    ("p: {curriculum: [{Lesson0: {value: 1, completion_criteria: {behavior: A}}}, {name: L1}]}",
     "curriculum[1].value"),
])
def test_environment_parameter_errors(tmp_path, params, fragment):
    message = error_for(tmp_path, f"behaviors:\n  A: {{trainer_type: ppo}}\nenvironment_parameters:\n  {params}\n")
    assert "environment_parameters.p" in message
    assert fragment in message
