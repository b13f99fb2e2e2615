"""Academy step semantics, proto building and CLI behaviour, in-process (no gRPC)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from protos.communicator_objects import agent_action_pb2
from tests.stub.conftest import REPO
from unity_stub_env.academy import Academy, ActionCountError
from unity_stub_env.agents import build_brain_parameters
from unity_stub_env.cli import main
from unity_stub_env.communicator import communication_versions_compatible
from unity_stub_env.tasks import make_task


def _discrete(*choices):
    return [agent_action_pb2.AgentActionProto(discrete_actions=[c]) for c in choices]


def _position(info) -> int:
    return int(np.argmax(info.observations[0].float_data.data))


def test_rewards_between_decisions_are_summed_and_actions_follow_position():
    academy = Academy(make_task("basic", num_areas=2, seed=0), decision_period=2)
    first = academy.collect_infos()
    assert [info.id for info in first] == [0, 1]
    academy.apply_actions(_discrete(2, 1))  # agent 0 right twice, agent 1 left twice
    academy.advance()
    infos = academy.collect_infos()
    assert [_position(info) for info in infos] == [12, 8]
    assert [info.reward for info in infos] == pytest.approx([-0.02, -0.02])
    assert [info.id for info in infos] == [0, 1]


def test_agent_finishing_mid_period_sends_terminal_then_new_first_info():
    academy = Academy(make_task("basic", num_areas=1, seed=0), decision_period=4)
    academy.collect_infos()
    academy.apply_actions(_discrete(1))  # left: 9, 8, 7 (small goal on step 3), then reset
    academy.advance()
    terminal, fresh = academy.collect_infos()
    assert (terminal.done, terminal.max_step_reached, terminal.id, _position(terminal)) == (True, False, 0, 7)
    assert terminal.reward == pytest.approx(3 * -0.01 + 0.1)
    # the new episode took step 4 with the zero action (stay): one step cost, still at 10
    assert (fresh.done, fresh.id, _position(fresh)) == (False, 1, 10)
    assert fresh.reward == pytest.approx(-0.01)
    stats = academy.take_stats()
    assert ("Basic/Large Goal Reached", 0.0) in [(key, value) for key, value, _ in stats]
    assert academy.take_stats() == []


def test_ball3d_reward_is_set_not_summed_and_reset_gives_new_ids():
    academy = Academy(make_task("ball3d", num_areas=1, seed=0))
    assert academy.decision_period == 5
    ids = [info.id for info in academy.collect_infos()]
    assert ids == list(range(12))
    academy.apply_actions([agent_action_pb2.AgentActionProto(continuous_actions=[0.0, 0.0])] * 12)
    academy.advance()
    infos = academy.collect_infos()
    assert np.allclose([info.reward for info in infos], 0.1)  # 5 steps, SetReward(0.1) each
    academy.environment_reset()
    assert [info.id for info in academy.collect_infos()] == list(range(12, 24))


def test_wrong_number_of_actions_is_a_clear_error():
    academy = Academy(make_task("basic", num_areas=2, seed=0))
    academy.collect_infos()
    with pytest.raises(ActionCountError, match="1 actions .* 2 agents"):
        academy.apply_actions(_discrete(2))
    academy.apply_actions([])  # no actions: everyone stays
    academy.advance()
    assert [_position(info) for info in academy.collect_infos()] == [10, 10]


def test_brain_parameters_fill_action_spec_and_legacy_fields():
    ball = build_brain_parameters("3DBall?team=0", make_task("ball3d").action_spec)
    assert (ball.brain_name, ball.action_spec.num_continuous_actions) == ("3DBall?team=0", 2)
    assert (ball.vector_action_space_type_deprecated, list(ball.vector_action_size_deprecated)) == (1, [2])
    basic = build_brain_parameters("Basic?team=0", make_task("basic").action_spec)
    assert list(basic.action_spec.discrete_branch_sizes) == [3] and basic.action_spec.num_discrete_actions == 1
    assert (basic.vector_action_space_type_deprecated, list(basic.vector_action_size_deprecated)) == (0, [3])


@pytest.mark.parametrize("unity,trainer,ok", [
    ("1.5.0", "1.5.0", True), ("1.5.0", "1.0.0", True), ("1.5.0", "2.0.0", False),
    ("0.15.0", "0.15.1", True), ("0.15.0", "0.16.0", False), ("1.5.0", "1.5.0-preview", False),
    ("1.5.0", "", False),
])
def test_communication_version_check(unity, trainer, ok):
    assert communication_versions_compatible(unity, trainer) is ok


def test_cli_list_and_usage_errors(capsys):
    assert main(["--list"]) == 0
    out = capsys.readouterr().out
    assert "behavior 'Basic'" in out and "discrete_branches=[3]" in out
    assert "behavior '3DBall'" in out and "continuous=2" in out and "[8]" in out
    assert main(["--task", "basic", "-nographics", "-batchmode"]) == 2
    assert "--mlagents-port" in capsys.readouterr().err
    assert main(["--task", "nope", "--mlagents-port", "5005"]) == 2
    assert "ball3d, basic" in capsys.readouterr().err
    assert main(["--task", "basic,nope", "--mlagents-port", "5005"]) == 2  # one bad name of several
    assert "nope" in capsys.readouterr().err
    assert main(["--task", "basic", "--task", "basic", "--mlagents-port", "5005"]) == 2
    assert "each --task may appear once" in capsys.readouterr().err
    assert main(["--task", "basic", "--mlagents-port", "5005", "--spin-wait-ms", "-1"]) == 2
    assert "--spin-wait-ms must be 0 or more, got -1" in capsys.readouterr().err


def test_written_launcher_keeps_the_spin_wait(tmp_path, capsys):
    assert main(["--task", "ball3d", "--spin-wait-ms", "1.5", "--write-launcher", str(tmp_path)]) == 0
    script = (tmp_path / "StubBall3D.x86_64").read_text()
    assert "--task ball3d --spin-wait-ms 1.5 \"$@\"" in script


def test_no_trainer_exits_1_naming_the_address_and_logs_to_the_log_file(tmp_path):
    import socket
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    log = tmp_path / "Player-0.log"
    done = subprocess.run(
        [sys.executable, "-m", "unity_stub_env.cli", "--task", "basic", "--mlagents-port", str(port),
         "--connect-timeout", "0.5", "-logfile", str(log), "-screen-width", "84"],
        cwd=REPO, capture_output=True, text=True, timeout=30,
    )
    assert done.returncode == 1
    assert f"localhost:{port}" in done.stderr
    text = log.read_text()
    assert f"localhost:{port}" in text and "Ignoring unknown flags: -screen-width 84" in text


def test_write_launcher_makes_a_unity_build_like_executable(tmp_path, capsys):
    import os

    assert main(["--task", "basic,ball3d", "--write-launcher", str(tmp_path)]) == 0
    exe = tmp_path / "StubBasicBall3D.x86_64"
    assert os.access(exe, os.X_OK)
    text = exe.read_text()
    assert text.startswith("#!/bin/sh\nexec ") and "-m unity_stub_env.cli --task basic,ball3d" in text
    assert text.rstrip().endswith('"$@"')  # passes on the flags the launching tool adds
    assert f"--env {tmp_path / 'StubBasicBall3D'}" in capsys.readouterr().out


def test_written_launcher_puts_its_own_checkout_first_on_pythonpath(tmp_path, capsys):
    """Launching tools (mlagents-learn, UnityEnvironment) drop PYTHONPATH: the player must still run
    the unity_stub_env it was written from, not whichever one the venv has installed."""
    import os

    assert main(["--task", "dodge", "--write-launcher", str(tmp_path)]) == 0
    capsys.readouterr()
    exe = tmp_path / "StubDodge.x86_64"
    assert f"exec env PYTHONPATH={REPO}\"${{PYTHONPATH:+:$PYTHONPATH}}\" " in exe.read_text()
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
    done = subprocess.run([str(exe), "--list"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "dodge: behavior 'Dodge'" in done.stdout
