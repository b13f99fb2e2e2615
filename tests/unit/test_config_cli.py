"""mlagents-learn flags: names, defaults, routing, and overriding the YAML only when given."""
from __future__ import annotations

import textwrap

import pytest

from trainer.config import build_parser, parse_run_options
from trainer.errors import ConfigError

SPEC_DEFAULTS = {  # docs/configuration.md, "Command line", dest -> default
    "env_path": None, "resume": False, "load_model": False, "train_model": False, "deterministic": False,
    "force": False, "run_id": "ppo", "initialize_from": None, "seed": -1, "inference": False,
    "base_port": 5005, "num_envs": 1, "num_areas": 1, "debug": False, "env_args": None,
    "max_lifetime_restarts": 10, "restarts_rate_limit_n": 1, "restarts_rate_limit_period_s": 60,
    "results_dir": "results", "timeout_wait": 60, "width": 84, "height": 84, "quality_level": 5,
    "time_scale": 20, "target_frame_rate": -1, "capture_frame_rate": 60, "no_graphics": False,
    "no_graphics_monitor": False, "device": None, "bind": "127.0.0.1", "trainer_config_path": None,
}


def config(tmp_path, text: str) -> str:
    path = tmp_path / "c.yaml"
    path.write_text(textwrap.dedent(text))
    return str(path)


def test_parser_dests_and_defaults():
    parser = build_parser()
    assert parser.prog == "mlagents-like-learn"
    for dest, default in SPEC_DEFAULTS.items():
        assert parser.get_default(dest) == default, dest


def test_hidden_flags_are_not_in_help():
    text = build_parser().format_help()
    assert "--load" not in text and "--train " not in text
    assert "--bind" in text and "--torch-device" in text


def test_flags_route_into_sections(tmp_path):
    options = parse_run_options([
        "--env", "stub:basic", "--num-envs", "3", "--num-areas", "2", "--base-port", "6000", "--seed", "12",
        "--timeout-wait", "5", "--max-lifetime-restarts", "-1", "--restarts-rate-limit-n", "4",
        "--restarts-rate-limit-period-s", "30", "--bind", "0.0.0.0", "--run-id", "r1", "--results-dir",
        str(tmp_path), "--force", "--inference", "--width", "100", "--height", "50", "--quality-level", "1",
        "--time-scale", "2.5", "--target-frame-rate", "30", "--capture-frame-rate", "0", "--no-graphics",
        "--no-graphics-monitor", "--torch-device", "cpu", "--debug", "--env-args", "--foo", "1",
    ])
    env = options.env_settings
    assert (env.env_path, env.num_envs, env.num_areas, env.base_port, env.seed) == ("stub:basic", 3, 2, 6000, 12)
    assert (env.timeout_wait, env.max_lifetime_restarts, env.restarts_rate_limit_n) == (5, -1, 4)
    assert (env.restarts_rate_limit_period_s, env.bind, env.env_args) == (30, "0.0.0.0", ["--foo", "1"])
    ck = options.checkpoint_settings
    assert (ck.run_id, ck.results_dir, ck.force, ck.inference) == ("r1", str(tmp_path), True, True)
    eng = options.engine_settings
    assert (eng.width, eng.height, eng.quality_level, eng.time_scale) == (100, 50, 1, 2.5)
    assert (eng.target_frame_rate, eng.capture_frame_rate, eng.no_graphics, eng.no_graphics_monitor) == (
        30, 0, True, True)
    assert options.torch_settings.device == "cpu" and options.debug is True


def test_flags_override_yaml_only_when_given(tmp_path):
    path = config(tmp_path, """
        behaviors: {A: {trainer_type: ppo}}
        env_settings: {base_port: 7000, seed: 3, timeout_wait: 9}
        engine_settings: {time_scale: 1.0}
        checkpoint_settings: {run_id: from_yaml}
    """)
    untouched = parse_run_options([path])
    assert (untouched.env_settings.base_port, untouched.env_settings.timeout_wait) == (7000, 9)
    assert untouched.engine_settings.time_scale == 1.0
    assert untouched.checkpoint_settings.run_id == "from_yaml"
    # Given flags win, even when they repeat the default value.
    overridden = parse_run_options([path, "--base-port", "5005", "--run-id", "cli"])
    assert overridden.env_settings.base_port == 5005
    assert overridden.checkpoint_settings.run_id == "cli"
    assert overridden.env_settings.timeout_wait == 9 and overridden.env_settings.seed == 3


def test_seed_resolved_once_into_env_settings():
    seeds = {parse_run_options([]).env_settings.seed for _ in range(20)}
    assert all(0 <= seed < 10000 for seed in seeds)
    assert len(seeds) > 1
    assert parse_run_options(["--seed", "0"]).env_settings.seed == 0


def test_deterministic_applies_to_every_behavior(tmp_path):
    path = config(tmp_path, """
        default_settings: {trainer_type: ppo}
        behaviors: {A: {trainer_type: ppo}, B: {trainer_type: ppo}}
    """)
    options = parse_run_options([path, "--deterministic"])
    assert all(ts.network_settings.deterministic for ts in options.behaviors.values())
    assert options.behavior_settings("Unlisted").network_settings.deterministic
    assert parse_run_options(["--deterministic"]).behavior_settings("X").network_settings.deterministic
    assert not parse_run_options([path]).behaviors["A"].network_settings.deterministic


def test_load_is_ored_into_resume():
    assert parse_run_options(["--load"]).checkpoint_settings.resume is True
    assert parse_run_options([]).checkpoint_settings.resume is False


def test_resume_wins_over_initialize_from(tmp_path):
    options = parse_run_options(["--resume", "--initialize-from", "old"])
    assert options.checkpoint_settings.resume and options.checkpoint_settings.initialize_from is None
    yaml_init = config(tmp_path, "checkpoint_settings: {initialize_from: old}\n")
    options = parse_run_options([yaml_init, "--resume"])
    assert options.checkpoint_settings.resume and options.checkpoint_settings.initialize_from is None
    yaml_resume = config(tmp_path, "checkpoint_settings: {resume: true}\n")
    options = parse_run_options([yaml_resume, "--initialize-from", "old"])
    assert not options.checkpoint_settings.resume and options.checkpoint_settings.initialize_from == "old"


def test_removed_flags_only_warn(caplog):
    with caplog.at_level("WARNING", logger="mlagents_like"):
        parse_run_options(["--torch", "--tensorflow"])
    assert "--torch was removed" in caplog.text and "--tensorflow was removed" in caplog.text


@pytest.mark.parametrize("argv, fragment", [
    (["--num-envs", "2"], "needs --env"),
    (["--num-areas", "0"], "--num-areas"),
    (["--num-envs", "0"], "--num-envs"),
    (["--base-port", "0"], "1..65535"),
    (["--env", "stub:x", "--num-envs", "4", "--base-port", "65533"], "65536"),
    (["--env", "stub:"], "task name"),
    (["--timeout-wait", "0"], "--timeout-wait"),
    (["--time-scale", "0"], "--time-scale"),
])
def test_cli_value_errors(argv, fragment):
    with pytest.raises(ConfigError) as info:
        parse_run_options(argv)
    assert fragment in str(info.value)


def test_argparse_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as info:
        parse_run_options(["--num-envs", "many"])
    assert info.value.code == 2
    with pytest.raises(SystemExit) as info:
        parse_run_options(["--no-such-flag"])
    assert info.value.code == 2
