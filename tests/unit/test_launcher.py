"""Simulator launching: executable lookup, argv order (docs/protocol.md, "Launching an executable"), restart
limits (docs/protocol.md, "Timeouts and liveness"), processes."""
from __future__ import annotations

import os
import sys
import time

import pytest

from trainer.envs.launcher import (
    RestartPolicy,
    SimulatorProcess,
    build_launch_command,
    resolve_env_path,
)
from trainer.errors import ConfigError, EnvironmentNotFoundError


def _make_file(path, executable=True):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"#!/bin/sh\n")
    os.chmod(path, 0o755 if executable else 0o644)
    return str(path)


# --- resolve_env_path --------------------------------------------------------------------------

def test_stub_passes_through():
    assert resolve_env_path("stub:ball3d") == "stub:ball3d"


def test_empty_or_unknown_stub_task_is_an_error():
    with pytest.raises(EnvironmentNotFoundError, match="names no stub task; use --env stub:TASK"):
        resolve_env_path("stub:")
    with pytest.raises(EnvironmentNotFoundError, match="unknown stub task 'balls'.*ball3d, basic"):
        resolve_env_path("stub:balls")
    with pytest.raises(EnvironmentNotFoundError, match="unknown stub task 'nope'"):
        resolve_env_path("stub:basic,nope")
    assert resolve_env_path("stub:basic,ball3d") == "stub:basic,ball3d"  # several behaviors in one stub


def test_the_trainers_stub_task_list_is_the_stubs():
    from unity_stub_env.task_names import TASK_NAMES
    from unity_stub_env.tasks import TASKS

    assert sorted(TASK_NAMES) == sorted(TASKS)


def test_checking_a_stub_task_name_does_not_import_mujoco():
    """The trainer checks --env stub:TASK before launching; MuJoCo's import (~0.3 s) belongs
    to the stub process, not to the trainer's start-up."""
    import subprocess

    probe = ("import sys; from trainer.envs.launcher import resolve_env_path; "
             "resolve_env_path('stub:ball3d'); import unity_stub_env; "
             "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mujoco', 'unity_stub_env')))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    # render.gl only sets MUJOCO_GL's headless default (it must run before MuJoCo is imported)
    assert loaded.strip() == ("['unity_stub_env', 'unity_stub_env.launcher', 'unity_stub_env.render', "
                              "'unity_stub_env.render.gl', 'unity_stub_env.task_names']")


@pytest.mark.parametrize("given", ["Game", "Game.x86_64", "Game.exe", "Game.app", "Game.x86"])
def test_linux_prefers_x86_64_whatever_suffix_was_given(tmp_path, given):
    expected = _make_file(tmp_path / "Game.x86_64")
    _make_file(tmp_path / "Game.x86")
    assert resolve_env_path(str(tmp_path / given), platform="linux") == expected


def test_linux_falls_back_to_x86_then_bare_file(tmp_path):
    x86 = _make_file(tmp_path / "a" / "Game.x86")
    assert resolve_env_path(str(tmp_path / "a" / "Game"), platform="linux") == x86
    bare = _make_file(tmp_path / "b" / "Game")
    assert resolve_env_path(str(tmp_path / "b" / "Game"), platform="linux") == bare


def test_relative_path_becomes_absolute(tmp_path, monkeypatch):
    expected = _make_file(tmp_path / "Game.x86_64")
    monkeypatch.chdir(tmp_path)
    assert resolve_env_path("Game", platform="linux") == expected


def test_linux_directory_with_one_player(tmp_path):
    player = _make_file(tmp_path / "build" / "3DBall.x86_64")
    (tmp_path / "build" / "3DBall_Data").mkdir()
    assert resolve_env_path(str(tmp_path / "build"), platform="linux") == player


def test_not_executable_file_is_skipped_with_chmod_hint(tmp_path):
    _make_file(tmp_path / "Game.x86_64", executable=False)
    with pytest.raises(EnvironmentNotFoundError, match="chmod"):
        resolve_env_path(str(tmp_path / "Game"), platform="linux")


def test_not_found_names_every_candidate_and_the_alternatives(tmp_path):
    base = str(tmp_path / "Missing")
    with pytest.raises(EnvironmentNotFoundError) as info:
        resolve_env_path(base + ".x86_64", platform="linux")
    message = str(info.value)
    for candidate in (base + ".x86_64", base + ".x86", base):
        assert candidate + "," in message or candidate + "." in message
    assert "--env" in message and "stub:TASK" in message and "Editor" in message


def test_macos_app_bundle(tmp_path):
    binary = _make_file(tmp_path / "Game.app" / "Contents" / "MacOS" / "Game")
    assert resolve_env_path(str(tmp_path / "Game.app"), platform="darwin") == binary
    other = _make_file(tmp_path / "Other.app" / "Contents" / "MacOS" / "Renamed")
    assert resolve_env_path(str(tmp_path / "Other"), platform="darwin") == other


def test_windows_exe_and_folder_skipping_crash_handler(tmp_path):
    exe = _make_file(tmp_path / "Game.exe")
    assert resolve_env_path(str(tmp_path / "Game"), platform="win32") == exe
    _make_file(tmp_path / "Build" / "UnityCrashHandler64.exe")
    player = _make_file(tmp_path / "Build" / "Walker.exe")
    assert resolve_env_path(str(tmp_path / "Build"), platform="win32") == player


# --- build_launch_command ----------------------------------------------------------------------

def test_minimal_command():
    assert build_launch_command("/b/Game.x86_64", 0, 5005) == ["/b/Game.x86_64", "--mlagents-port", "5005"]


def test_no_graphics_log_folder_and_env_args(tmp_path):
    logs = str(tmp_path / "results" / "run" / "run_logs")
    command = build_launch_command(
        "/b/Game.x86_64", 2, 5005, no_graphics=True, log_folder=logs, env_args=["--foo", "1"], seed=3
    )
    assert command == [
        "/b/Game.x86_64", "-nographics", "-batchmode", "--mlagents-port", "5007",
        "-logFile", f"{tmp_path}/results/run/run_logs/Player-2.log", "--foo", "1",
    ]


def test_relative_log_folder_is_made_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    command = build_launch_command("/b/G", 0, 6000, log_folder="results/r/run_logs")
    assert command == ["/b/G", "--mlagents-port", "6000", "-logFile", f"{tmp_path}/results/r/run_logs/Player-0.log"]


@pytest.mark.parametrize(
    "worker_id, expected_prefix",
    [(0, ["/b/G", "--mlagents-port", "5005"]), (1, ["/b/G", "-nographics", "-batchmode", "--mlagents-port", "5006"])],
)
def test_no_graphics_monitor_keeps_graphics_on_worker_zero_only(worker_id, expected_prefix):
    assert build_launch_command("/b/G", worker_id, 5005, no_graphics_monitor=True) == expected_prefix


@pytest.mark.parametrize("flag", ["-logfile", "-LOGFILE", "-logFile"])
def test_user_logfile_is_not_duplicated(flag):
    command = build_launch_command("/b/G", 0, 5005, log_folder="/r/logs", env_args=[flag, "-"])
    assert command == ["/b/G", "--mlagents-port", "5005", flag, "-"]


def test_stub_command_uses_python_module_and_same_arguments():
    command = build_launch_command(
        "stub:ball3d", 1, 5005, no_graphics=True, log_folder="/r/logs", env_args=["-screen-width", "64"]
    )
    assert command == [
        sys.executable, "-m", "unity_stub_env.cli", "--task", "ball3d",
        "-nographics", "-batchmode", "--mlagents-port", "5006", "-logFile", "/r/logs/Player-1.log",
        "-screen-width", "64",
    ]


def test_stub_is_told_to_poll_and_a_unity_build_never_is():
    stub = build_launch_command("stub:basic", 0, 5005, stub_spin_wait=0.0015)
    assert stub[:7] == [sys.executable, "-m", "unity_stub_env.cli", "--task", "basic", "--spin-wait-ms", "1.5"]
    assert "--spin-wait-ms" not in build_launch_command("stub:basic", 0, 5005, stub_spin_wait=0.0)
    assert "--spin-wait-ms" not in build_launch_command("/b/G", 0, 5005, stub_spin_wait=0.0015)


def test_stub_is_told_the_transport_and_a_unity_build_never_is():
    stub = build_launch_command("stub:basic", 0, 5005, stub_transport="grpcio")
    assert stub[:7] == [sys.executable, "-m", "unity_stub_env.cli", "--task", "basic", "--transport", "grpcio"]
    assert "--transport" not in build_launch_command("stub:basic", 0, 5005, stub_transport="http2")
    assert "--transport" not in build_launch_command("/b/G", 0, 5005, stub_transport="grpcio")


@pytest.mark.parametrize("cpus, expected", [(1, 0.0), (2, 0.0), (3, 0.001)])
def test_pool_polls_only_with_a_cpu_for_the_trainer_and_each_simulator(monkeypatch, cpus, expected):
    from trainer.envs.pool import EnvPool, PoolSettings
    from trainer.envs import cpus as cpu_helpers

    monkeypatch.setattr(cpu_helpers, "usable_cpus", lambda: cpus)
    settings = PoolSettings(env_path="stub:basic", env_args=(), base_port=5005, num_envs=2, num_areas=1,
                            seed=0, timeout_wait=5, bind="127.0.0.1", no_graphics=True,
                            no_graphics_monitor=False, log_folder=None)
    pool = EnvPool(settings, initial_side_channel=lambda: b"")
    assert [w.spin_wait for w in pool.workers] == [expected, expected]


def test_num_areas_must_be_positive():
    with pytest.raises(ConfigError, match="num-areas"):
        build_launch_command("/b/G", 0, 5005, num_areas=0)


# --- RestartPolicy -----------------------------------------------------------------------------

@pytest.mark.parametrize(
    "policy_args, times, expected",
    [
        # defaults: 1 restart per 60 s; a restart at t leaves the window once now - 60 >= t
        ((10, 1, 60), [0, 30, 59.9, 60, 61, 120], [True, False, False, True, False, True]),
        # lifetime limit 2, no rate limit
        ((2, -1, 60), [0, 0, 0, 1000], [True, True, False, False]),
        # unlimited lifetime and no rate limit
        ((-1, -1, 60), [0] * 15, [True] * 15),
        # 2 per 10 s window
        ((-1, 2, 10), [0, 1, 2, 10, 11, 11.5, 21], [True, True, False, True, True, False, True]),
        # zero restarts allowed
        ((0, 1, 60), [0, 100], [False, False]),
    ],
)
def test_restart_policy_table(policy_args, times, expected):
    policy = RestartPolicy(*policy_args)
    assert [policy.allow_restart(now) for now in times] == expected
    assert policy.restart_count == sum(expected)


def test_lifetime_limit_counts_only_allowed_restarts():
    policy = RestartPolicy(max_lifetime_restarts=3, rate_limit_n=1, rate_limit_period_s=60)
    results = [policy.allow_restart(t) for t in (0, 10, 60, 70, 120, 180, 240)]
    assert results == [True, False, True, False, True, False, False]


def test_has_quota_does_not_count():
    policy = RestartPolicy(1, 1, 60)
    assert policy.has_quota(0) and policy.has_quota(0)
    assert policy.restart_count == 0


# --- SimulatorProcess --------------------------------------------------------------------------

def test_real_process_start_and_close():
    process = SimulatorProcess([sys.executable, "-c", "import time; time.sleep(60)"], worker_id=3)
    assert not process.is_alive() and process.returncode is None
    assert "not started" in process.describe()
    process.start()
    try:
        assert process.is_alive()
        assert os.getsid(process.pid) == process.pid  # its own session
        assert "running" in process.describe() and "worker 3" in process.describe()
    finally:
        code = process.close(timeout=5)
    assert not process.is_alive()
    assert code == process.returncode == -15  # SIGTERM
    assert "exited with code -15" in process.describe()


def _wait_for_file(path, attempts=200):
    """Poll for ``path`` (up to ~10 s); a readiness wait, not a timing assertion."""
    for _ in range(attempts):
        if path.exists():
            return True
        time.sleep(0.05)
    return False


def test_process_that_ignores_sigterm_is_killed(tmp_path):
    ready = tmp_path / "ready"
    script = (
        "import pathlib, signal, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
        f"pathlib.Path({str(ready)!r}).touch(); time.sleep(60)"
    )
    process = SimulatorProcess([sys.executable, "-c", script]).start()
    try:
        assert _wait_for_file(ready), "child never installed its SIGTERM handler"
        code = process.close(timeout=0.3)
    finally:
        if process.is_alive():
            process._process.kill()
    assert not process.is_alive()
    assert code == -9  # SIGTERM was ignored, so close had to SIGKILL


def test_output_goes_to_the_log_file_when_asked(tmp_path):
    log_path = tmp_path / "run_logs" / "Player-0.log"
    command = [sys.executable, "-c", "import sys; print('hello'); sys.exit(3)",
               "--mlagents-port", "5005", "-logFile", str(log_path)]
    process = SimulatorProcess(command, output_to_log=True)
    assert process.port == 5005 and process.log_path == str(log_path)
    process.start()
    assert process.wait_for_exit(10)
    assert process.close() == 3
    assert log_path.read_text() == "hello\n"
    assert "exited with code 3" in process.describe()
    assert process.describe().endswith("its log ends: 'hello')")  # the reason, in the trainer's error


def test_an_exited_process_is_described_by_its_last_log_line(tmp_path):
    log_path = tmp_path / "Player-0.log"
    log_path.write_text("x" * 5000 + "\nstarting\n  bad --task nosuch; known: basic  \n\n")
    process = SimulatorProcess([sys.executable, "-c", "import sys; sys.exit(2)", "-logFile", str(log_path)])
    assert process.last_log_line() == "bad --task nosuch; known: basic"
    assert process.last_log_line(limit=3) == "bad"
    assert "its log ends" not in process.describe()  # not started: nothing to report
    process.start()
    assert process.wait_for_exit(10)
    assert process.describe().endswith("exited with code 2; log %s; its log ends: "
                                       "'bad --task nosuch; known: basic')" % log_path)
    process.close()
    assert SimulatorProcess([sys.executable], log_folder=None).last_log_line() == ""


def test_stub_command_is_recognised():
    command = build_launch_command("stub:basic", 0, 5005, log_folder="/r/logs")
    process = SimulatorProcess(command)
    assert process.is_stub and process.output_to_log
    assert process.describe() == "simulator worker 0 (stub task basic, port 5005, not started; log /r/logs/Player-0.log)"
    executable = SimulatorProcess(build_launch_command("/b/Game.x86_64", 1, 5005), worker_id=1)
    assert not executable.is_stub and not executable.output_to_log
    assert executable.describe() == "simulator worker 1 (Game.x86_64, port 5006, not started)"


def test_missing_executable_is_a_user_error(tmp_path):
    with pytest.raises(EnvironmentNotFoundError, match="no such file"):
        SimulatorProcess([str(tmp_path / "nope")]).start()


def test_a_resolved_player_is_launched_with_its_port(tmp_path):
    player = _make_file(tmp_path / "Game.x86_64")
    process = SimulatorProcess(build_launch_command(resolve_env_path(str(tmp_path / "Game")), 1, 5005,
                                                    no_graphics=True), worker_id=1)
    assert process.command == [player, "-nographics", "-batchmode", "--mlagents-port", "5006"]
    assert process.port == 5006 and not process.is_stub


def test_directory_with_two_players_is_ambiguous(tmp_path):
    _make_file(tmp_path / "build" / "A.x86_64")
    _make_file(tmp_path / "build" / "B.x86_64")
    with pytest.raises(EnvironmentNotFoundError, match=r"build/\*\.x86_64"):
        resolve_env_path(str(tmp_path / "build"), platform="linux")


def test_log_folder_gives_the_log_path_when_the_command_has_none(tmp_path):
    process = SimulatorProcess([sys.executable, "-c", "print('x')"], 2, log_folder=str(tmp_path), output_to_log=True)
    assert process.log_path == str(tmp_path / "Player-2.log")
    process.start()
    assert process.wait_for_exit(10) and process.close() == 0
    assert (tmp_path / "Player-2.log").read_text() == "x\n"
    # an explicit -logFile in the command wins over log_folder
    command = ["/b/G", "-logfile", "/elsewhere/u.log"]
    assert SimulatorProcess(command, 0, log_folder=str(tmp_path)).log_path == "/elsewhere/u.log"
