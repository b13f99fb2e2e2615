"""mlagents-like-learn end to end against the stub simulator: outputs, resume, and bad input.

Every run here is a real trainer process serving real gRPC to a real stub process.
"""
from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import free_port_block, learn, run_with_signals
from trainer.stop import EXIT_STOPPED


def processes_naming(text: str) -> dict[int, str]:
    """{pid: command line} of this machine's processes whose command line contains ``text`` (a
    simulator's names its log file, under the run's results folder)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:  # exited meanwhile
                continue
            if text in command:
                found[int(entry.name)] = command
    return found


def assert_no_process_left(text: str) -> None:
    left = processes_naming(text)
    for pid in left:  # a failing test leaves nothing behind either
        os.kill(pid, signal.SIGKILL)
    assert not left


def scalars(folder):
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0, "tensors": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}, acc


def test_basic_run_writes_mlagents_outputs(tmp_path, basic_config, env_no_proxy):
    cfg = basic_config(max_steps=1500, interval=500, summary=500, keep=2)
    port = free_port_block()
    r = learn([str(cfg), "--env", "stub:basic", "--run-id", "r1", "--results-dir", str(tmp_path / "results"),
               "--base-port", str(port), "--seed", "3", "--no-graphics"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    run = tmp_path / "results" / "r1"
    # the console summary line in ML-Agents' format, at summary_freq multiples
    assert "Basic. Step: 500. Time Elapsed:" in r.stdout
    assert "Mean Reward:" in r.stdout and "Connected new brain: Basic?team=0" in r.stdout
    for f in ["configuration.yaml", "run_logs/timers.json", "run_logs/training_status.json",
              "run_logs/Player-0.log", "Basic.onnx", "Basic/checkpoint.pt"]:
        assert (run / f).is_file(), f
    status = json.loads((run / "run_logs/training_status.json").read_text())
    ckpts = status["Basic"]["checkpoints"]
    assert len(ckpts) == 2  # keep_checkpoints 2 trims older ones (and their files)
    steps = [c["steps"] for c in ckpts]
    assert steps == sorted(steps) and steps[-1] > 1500
    for c in ckpts:
        assert os.path.isfile(c["file_path"]) and c["file_path"].endswith(".onnx")
        assert all(os.path.isfile(p) for p in c["auxillary_file_paths"])
    onnx_files = sorted(p.name for p in (run / "Basic").glob("Basic-*.onnx"))
    assert len(onnx_files) == 2
    assert status["Basic"]["final_checkpoint"]["file_path"].endswith("Basic.onnx")
    assert status["metadata"]["stats_format_version"] == "0.3.0"
    # TensorBoard events, read back
    tags, acc = scalars(run / "Basic")
    for tag in ["Environment/Cumulative Reward", "Environment/Episode Length", "Losses/Policy Loss",
                "Losses/Value Loss", "Policy/Entropy", "Policy/Learning Rate", "Policy/Epsilon", "Policy/Beta",
                "Policy/Extrinsic Value Estimate", "Policy/Extrinsic Reward"]:
        assert tag in tags, (tag, sorted(tags))
    assert [s for s, _ in tags["Environment/Cumulative Reward"]][:3] == [500, 1000, 1500]
    assert "Is Training" not in tags and "Step" not in tags
    # the learning rate decays linearly from 3e-4 towards 1e-10 over max_steps
    lr = dict(tags["Policy/Learning Rate"])
    assert all(0 < v < 3.0e-4 for v in lr.values())
    timers = json.loads((run / "run_logs/timers.json").read_text())
    assert timers["name"] == "root" and timers["metadata"]["communication_protocol_version"] == "1.5.0"
    # an existing run id is refused without --resume/--force, with one message and exit 2
    r2 = learn([str(cfg), "--env", "stub:basic", "--run-id", "r1", "--results-dir", str(tmp_path / "results"),
                "--base-port", str(port)], cwd=tmp_path, env=env_no_proxy)
    assert r2.returncode == 2
    assert "--resume" in r2.stderr and "--force" in r2.stderr and "Traceback" not in r2.stderr


def test_resume_continues_at_saved_step(tmp_path, basic_config, env_no_proxy):
    port = free_port_block()
    res = str(tmp_path / "results")
    r = learn([str(basic_config(max_steps=600, interval=300)), "--env", "stub:basic", "--run-id", "r",
               "--results-dir", res, "--base-port", str(port), "--seed", "1"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    first = json.loads((tmp_path / "results/r/run_logs/training_status.json").read_text())
    first_step = first["Basic"]["final_checkpoint"]["steps"]
    assert first_step > 600
    cfg2 = basic_config(max_steps=1200, interval=300, name="more.yaml")
    r = learn([str(cfg2), "--env", "stub:basic", "--run-id", "r", "--results-dir", res, "--resume",
               "--base-port", str(port), "--seed", "1"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert f"at step {first_step}" in r.stdout
    second = json.loads((tmp_path / "results/r/run_logs/training_status.json").read_text())
    assert second["Basic"]["final_checkpoint"]["steps"] > 1200
    assert min(c["steps"] for c in second["Basic"]["checkpoints"]) <= first_step + 300
    # --initialize-from: a new run starts at step 0 from the other run's weights
    init_cfg = basic_config(max_steps=300, interval=300, name="init.yaml")
    init_cfg.write_text(init_cfg.read_text().replace("    trainer_type: ppo\n", "    trainer_type: ppo\n    threaded: true\n"))
    r = learn([str(init_cfg), "--env", "stub:basic",
               "--run-id", "r2", "--initialize-from", "r", "--results-dir", res, "--base-port", str(port)],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "results/r/Basic/checkpoint.pt for behavior Basic at step 0" in r.stdout
    assert "threaded: true is accepted but has no effect" in r.stdout  # said, not silently ignored
    third = json.loads((tmp_path / "results/r2/run_logs/training_status.json").read_text())
    assert 300 < third["Basic"]["final_checkpoint"]["steps"] < 400


@pytest.mark.parametrize("case", ["malformed", "unknown_key", "wrong_type", "missing_env", "missing_yaml",
                                  "unknown_stub_task"])
def test_bad_input_is_one_message_and_exit_2(tmp_path, case, env_no_proxy):
    cfg = tmp_path / "c.yaml"
    args = [str(cfg), "--env", "stub:basic", "--results-dir", str(tmp_path / "res")]
    expect = ""
    if case == "malformed":
        cfg.write_text("behaviors:\n  Basic: [unclosed\n")
        expect = "c.yaml"
    elif case == "unknown_key":
        cfg.write_text("behaviors:\n  Basic:\n    trainer_type: ppo\n    hyperparameters:\n      lamda: 0.9\n")
        expect = "lambd"
    elif case == "wrong_type":
        cfg.write_text("behaviors:\n  Basic:\n    trainer_type: ppo\n    hyperparameters:\n      batch_size: big\n")
        expect = "batch_size"
    elif case == "missing_env":
        cfg.write_text("behaviors: {}\n")
        args = [str(cfg), "--env", str(tmp_path / "NoSuchGame"), "--results-dir", str(tmp_path / "res")]
        expect = "NoSuchGame"
    elif case == "missing_yaml":
        expect = "c.yaml"
    elif case == "unknown_stub_task":
        cfg.write_text("behaviors: {}\n")
        args[2] = "stub:nosuch"
        expect = "unknown stub task 'nosuch'; use --env stub:TASK with one of: ball3d, basic"
    r = learn(args, cwd=tmp_path, timeout=60, env=env_no_proxy)
    assert r.returncode == 2, (r.stdout[-2000:], r.stderr[-2000:])
    assert expect in r.stderr
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout
    assert not (tmp_path / "res").exists()  # nothing written, no simulator started


@pytest.mark.parametrize("name, value, allowed", [
    ("MLAGENTS_LIKE_TORCH_THREADS", "lots", "is not a whole number >= 1"),
    ("MLAGENTS_LIKE_BLAS_THREADS", "0", "is not a whole number >= 1"),
    ("MLAGENTS_LIKE_SPIN_WAIT_MS", "fast", "is not a number of milliseconds >= 0"),
    ("MLAGENTS_LIKE_TRANSPORT", "quic", "is not a transport; use MLAGENTS_LIKE_TRANSPORT=http2 (the default) or"),
    ("MLAGENTS_LIKE_NUMPY_UPDATE", "yes", "is neither 0 nor 1"),
    ("MLAGENTS_LIKE_TORCH_THREAD", "2", "is not a variable mlagents-like-learn knows"),
])
def test_bad_environment_variable_is_refused_before_anything_is_written(tmp_path, basic_config, env_no_proxy,
                                                                        name, value, allowed):
    env = dict(env_no_proxy, **{name: value})
    r = learn([str(basic_config()), "--env", "stub:basic", "--results-dir", str(tmp_path / "res")],
              cwd=tmp_path, timeout=60, env=env)
    assert r.returncode == 2, (r.stdout[-2000:], r.stderr[-2000:])
    assert f"mlagents-like-learn: error: {name}={value!r} {allowed}" in r.stderr
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout
    assert not (tmp_path / "res").exists()  # no results folder, so no simulator either


def test_environment_variables_reach_their_consumers(tmp_path, basic_config, monkeypatch):
    """In this process, so the run's own objects can be looked at: torch's thread count, the
    transport each server used and the stub was told, the pool's polling budget, whether PPO's
    update went through numpy, and the BLAS limit, all as the MLAGENTS_LIKE_* variables say
    (each differs from its default)."""
    import torch

    from trainer import cli
    from trainer.envs import pool as pool_module
    from trainer.ppo import numpy_update
    from trainer.envs import cpus
    from trainer.protocol import server

    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "http_proxy", "https_proxy",
                 "HTTP_PROXY", "HTTPS_PROXY", "grpc_proxy"):
        monkeypatch.delenv(name, raising=False)
    for name, value in {"MLAGENTS_LIKE_TORCH_THREADS": "3", "MLAGENTS_LIKE_BLAS_THREADS": "2",
                        "MLAGENTS_LIKE_SPIN_WAIT_MS": "7", "MLAGENTS_LIKE_TRANSPORT": "grpcio",
                        "MLAGENTS_LIKE_NUMPY_UPDATE": "0"}.items():
        monkeypatch.setenv(name, value)
    seen: dict = {"transports": [], "numpy_steppers": 0}
    start, pool_init, stepper_init = server.UnityEndpoint.start, pool_module.EnvPool.__init__, numpy_update.NumpyPPO.__init__

    def spy_start(self):
        seen["transports"].append(self.transport_name)
        return start(self)

    def spy_pool(self, settings, *args, **kwargs):
        seen["pool_spin_wait_s"] = settings.spin_wait_s
        return pool_init(self, settings, *args, **kwargs)

    def spy_stepper(self, *args, **kwargs):
        seen["numpy_steppers"] += 1
        return stepper_init(self, *args, **kwargs)

    monkeypatch.setattr(server.UnityEndpoint, "start", spy_start)
    monkeypatch.setattr(pool_module.EnvPool, "__init__", spy_pool)
    monkeypatch.setattr(numpy_update.NumpyPPO, "__init__", spy_stepper)
    # what main() changes in this process besides the run: signal handlers, torch threads, its logger
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGQUIT, signal.SIGUSR1)}
    threads = torch.get_num_threads()
    log = logging.getLogger("mlagents_like")
    log_state = (log.handlers[:], log.level, log.propagate)
    try:
        code = cli.main([str(basic_config(max_steps=300, interval=300)), "--env", "stub:basic", "--run-id", "vars",
                         "--results-dir", str(tmp_path / "res"), "--base-port", str(free_port_block())])
        run_threads = torch.get_num_threads()
    finally:
        torch.set_num_threads(threads)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        log.handlers[:], log.level, log.propagate = log_state
    assert code == 0
    assert run_threads == 3
    assert seen["transports"] == ["grpcio"] and seen["pool_spin_wait_s"] == 0.007
    player_log = (tmp_path / "res" / "vars" / "run_logs" / "Player-0.log").read_text()
    polls = 7 if cpus.usable_cpus() >= 2 else 0  # the trainer and its one simulator need a CPU each
    assert f"grpcio client, polling up to {polls} ms" in player_log
    assert seen["numpy_steppers"] == 0  # MLAGENTS_LIKE_NUMPY_UPDATE=0: torch autograd
    assert os.environ["OPENBLAS_NUM_THREADS"] == os.environ["MKL_NUM_THREADS"] == "2"
    assert (tmp_path / "res" / "vars" / "Basic" / "checkpoint.pt").exists()  # it trained (and updated)


def test_port_in_use_is_a_clear_error(tmp_path, basic_config, env_no_proxy):
    with socket.socket() as blocker:
        blocker.bind(("127.0.0.1", 0))
        blocker.listen(1)
        port = blocker.getsockname()[1]
        r = learn([str(basic_config()), "--env", "stub:basic", "--base-port", str(port),
                   "--results-dir", str(tmp_path / "res")], cwd=tmp_path, timeout=60, env=env_no_proxy)
    assert r.returncode == 2
    assert str(port) in r.stderr and "Traceback" not in r.stderr


def test_simulator_that_never_connects_times_out(tmp_path, basic_config, env_no_proxy):
    game = tmp_path / "Silent.x86_64"
    game.write_text("#!/bin/sh\nexec sleep 120\n")
    game.chmod(0o755)
    r = learn([str(basic_config()), "--env", str(tmp_path / "Silent"), "--timeout-wait", "2",
               "--base-port", str(free_port_block()), "--results-dir", str(tmp_path / "res")],
              cwd=tmp_path, timeout=60, env=env_no_proxy)
    assert r.returncode == 2
    assert "--timeout-wait" in r.stderr or "timeout" in r.stderr.lower()
    assert "Traceback" not in r.stderr


def test_simulator_that_dies_is_reported(tmp_path, basic_config, env_no_proxy):
    game = tmp_path / "Crash.x86_64"
    # like a player that fails at start: it writes its reason to its -logFile, then exits
    game.write_text('#!/bin/sh\nfor a; do [ "$prev" = -logFile ] && echo "Fatal: no display" >> "$a"; '
                    'prev="$a"; done\nexit 3\n')
    game.chmod(0o755)
    r = learn([str(basic_config()), "--env", str(tmp_path / "Crash"), "--timeout-wait", "30",
               "--base-port", str(free_port_block()), "--results-dir", str(tmp_path / "res")],
              cwd=tmp_path, timeout=60, env=env_no_proxy)
    assert r.returncode == 2
    assert "Crash" in r.stderr and "Traceback" not in r.stderr
    assert "exited with code 3" in r.stderr and "its log ends: 'Fatal: no display'" in r.stderr
    # the folder it left holds no checkpoint, model or summary: the rerun needs no --force ...
    left = sorted(str(p.relative_to(tmp_path / "res" / "ppo")) for p in (tmp_path / "res" / "ppo").rglob("*"))
    assert left == ["configuration.yaml", "run_logs", "run_logs/Player-0.log", "run_logs/timers.json",
                    "run_logs/training_status.json"]
    again = [str(basic_config(max_steps=300, interval=1000, summary=100)), "--env", "stub:basic",
             "--base-port", str(free_port_block()), "--results-dir", str(tmp_path / "res")]
    r = learn(again, cwd=tmp_path, timeout=120, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "earlier start that never trained" in r.stdout + r.stderr
    assert (tmp_path / "res" / "ppo" / "Basic.onnx").is_file()
    # ... but once a run has trained there, its results are kept
    r = learn(again, cwd=tmp_path, timeout=120, env=env_no_proxy)
    assert r.returncode == 2 and "Previous data from this run ID" in r.stderr


def _assert_final_save(run, min_steps: int) -> None:
    assert (run / "Basic.onnx").is_file() and (run / "Basic" / "checkpoint.pt").is_file()
    status = json.loads((run / "run_logs/training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] >= min_steps


def _endless_basic(tmp_path, basic_config, run_id: str) -> list[str]:
    cfg = basic_config(max_steps=10_000_000, interval=10_000_000, summary=1000)
    return [sys.executable, "-m", "trainer.cli", str(cfg), "--env", "stub:basic", "--run-id", run_id,
            "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())]


def test_sigint_saves_a_checkpoint_and_onnx(tmp_path, basic_config, env_no_proxy):
    # wait until training has produced at least one summary
    code, text = run_with_signals(_endless_basic(tmp_path, basic_config, "stop"), tmp_path, env_no_proxy,
                                  [("Basic. Step: 1000.", signal.SIGINT)])
    assert code == EXIT_STOPPED == 75, text  # unfinished: a batch script requeues on this status
    assert "Learning was interrupted" in text and "continue this run with --resume" in text
    run = tmp_path / "results" / "stop"
    _assert_final_save(run, 1000)
    # the stop summarised its unfinished period early (label: its end); the checkpoint says the
    # resumed run continues with the next one
    saved = json.loads((run / "run_logs/training_status.json").read_text())["Basic"]["final_checkpoint"]["steps"]
    label = -(-saved // 1000) * 1000  # the end of the period holding the saved step
    checkpoint = torch.load(run / "Basic" / "checkpoint.pt", weights_only=True)
    assert int(checkpoint["Summaries"]["next_step"]) == label + 1000
    r = learn([str(basic_config(max_steps=label + 1000, interval=10_000_000, summary=1000, name="more.yaml")),
               "--env", "stub:basic", "--run-id", "stop", "--resume", "--results-dir", str(tmp_path / "results"),
               "--base-port", str(free_port_block())], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert f"at step {saved}" in r.stdout
    steps = [s for s, _ in scalars(run / "Basic")[0]["Environment/Episode Length"]]
    # each summary step once: 1000 .. label from the first process (label only if an episode
    # ended in its few steps), label + 1000 from the resumed one
    assert steps in ([*range(1000, label, 1000), label + 1000], [*range(1000, label + 1, 1000), label + 1000]), steps


def test_a_second_signal_during_the_final_save_loses_nothing(tmp_path, basic_config, env_no_proxy):
    """Slurm and impatient users send more than one signal: the second lands while the final
    checkpoint and ONNX are written, and must not cut them short (a third would)."""
    code, text = run_with_signals(
        _endless_basic(tmp_path, basic_config, "twice"), tmp_path, env_no_proxy,
        [("Basic. Step: 1000.", signal.SIGTERM),
         ("Learning was interrupted", signal.SIGTERM)])  # finish_run starts now: checkpoint, then ONNX
    assert code == EXIT_STOPPED, text
    assert "already stopping" in text
    _assert_final_save(tmp_path / "results" / "twice", 1000)


def _children(pid: int) -> list[int]:
    return [int(c) for t in Path(f"/proc/{pid}/task").iterdir()
            for c in (t / "children").read_text().split()]


def test_a_stop_signal_after_the_simulator_closed_still_means_unfinished(tmp_path, basic_config, env_no_proxy):
    """scancel and a preemption signal every process of a job in turn: the simulator's TERM can
    close the connection before the trainer's own TERM arrives, which then lands during the
    final save. The run is still unfinished: exit 75 (resume me), not 0."""
    proc = subprocess.Popen(_endless_basic(tmp_path, basic_config, "late"), cwd=tmp_path, env=env_no_proxy,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    try:
        for line in proc.stdout:
            lines.append(line)
            if "Basic. Step: 1000." in line:
                simulators = _children(proc.pid)
                assert len(simulators) == 1, simulators
                os.kill(simulators[0], signal.SIGTERM)
            elif "The simulator closed the connection" in line:
                proc.send_signal(signal.SIGTERM)
                break
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = "".join(lines) + out
    assert proc.returncode == EXIT_STOPPED, text
    assert "continue this run with --resume" in text
    _assert_final_save(tmp_path / "results" / "late", 1000)


def test_sigterm_while_waiting_for_the_editor_stops_at_once(tmp_path, basic_config, env_no_proxy):
    """No --env: the trainer waits (here up to 600 s) for the Editor's Play button; a stop signal
    ends that wait within a fraction of a second, not at the next poll of the timeout."""
    cmd = [sys.executable, "-m", "trainer.cli", str(basic_config()), "--run-id", "editor",
           "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block()),
           "--timeout-wait", "600"]
    # the wait would otherwise last 600 s (60 s per poll)
    code, text = run_with_signals(cmd, tmp_path, env_no_proxy, [("Listening on port", signal.SIGTERM)], timeout=40)
    assert code == EXIT_STOPPED, text  # nothing trained yet: still unfinished
    assert "Traceback" not in text


@pytest.mark.parametrize("device", ["bogus", "cuda:7"])
def test_unusable_torch_device_is_one_message_and_exit_2(tmp_path, basic_config, device, env_no_proxy):
    res = str(tmp_path / "res")
    r = learn([str(basic_config(max_steps=300)), "--env", "stub:basic", "--torch-device", device,
               "--base-port", str(free_port_block()), "--results-dir", res], cwd=tmp_path, timeout=120,
              env=env_no_proxy)
    assert r.returncode == 2, (r.stdout[-2000:], r.stderr[-2000:])
    assert f"torch_settings.device '{device}' cannot be used here" in r.stderr
    assert "Traceback" not in r.stderr + r.stdout
    assert not (tmp_path / "res" / "ppo" / "Basic").exists()  # nothing was trained or saved
    assert (tmp_path / "res" / "ppo" / "run_logs" / "Player-0.log").is_file()  # a simulator was launched
    assert_no_process_left(str(tmp_path / "res"))  # and is gone
    # the folder that start left is only configuration: the corrected rerun needs no --force
    r = learn([str(basic_config(max_steps=300)), "--env", "stub:basic", "--torch-device", "cpu",
               "--base-port", str(free_port_block()), "--results-dir", res], cwd=tmp_path, timeout=120,
              env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "res" / "ppo" / "Basic.onnx").is_file()


LAUNCH_THEN_FAIL = """
import sys
from trainer.cli import entry
from trainer.errors import ConfigError

class Refuse:  # the loop's modules cannot be imported: a user error found after the simulators' launch
    def find_spec(self, name, path=None, target=None):
        if name == "trainer.run":
            raise ConfigError("the loop cannot start (test)")

sys.meta_path.insert(0, Refuse())
entry()  # the console script: os._exit at the end, no interpreter teardown to clean up after it
"""


def test_simulator_launched_before_the_loop_is_stopped_when_the_start_fails(tmp_path, basic_config, env_no_proxy):
    """trainer/cli.py launches the simulators before it imports the loop's modules; if the start
    fails there, the simulator it launched is stopped, not left behind. The simulator here never
    connects and would sleep for 120 s."""
    game = tmp_path / "Sleeper.x86_64"
    game.write_text(f"#!/bin/sh\nexec {sys.executable} -c 'import time; time.sleep(120)' \"$@\"\n")
    game.chmod(0o755)
    driver = tmp_path / "driver.py"
    driver.write_text(LAUNCH_THEN_FAIL)
    res = tmp_path / "res"
    r = subprocess.run([sys.executable, str(driver), str(basic_config(max_steps=300)), "--env", str(game),
                        "--run-id", "r", "--results-dir", str(res), "--base-port", str(free_port_block()),
                        "--debug"], cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env_no_proxy)
    assert "Launching " in r.stdout  # it had launched the simulator
    assert_no_process_left(str(res))
    assert r.returncode == 2, r.stderr[-2000:]
    assert "mlagents-like-learn: error: the loop cannot start (test)" in r.stderr


def test_force_starts_the_run_id_again_from_step_0(tmp_path, basic_config, env_no_proxy):
    res = tmp_path / "results"
    cfg = basic_config(max_steps=600, interval=300, summary=300)
    base = [str(cfg), "--env", "stub:basic", "--run-id", "f", "--results-dir", str(res), "--seed", "2"]
    r = learn(base + ["--base-port", str(free_port_block())], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-2000:]
    first_events = sorted(p.name for p in (res / "f" / "Basic").glob("events.out.tfevents.*"))
    assert len(first_events) == 1
    cfg.write_text(cfg.read_text().replace("max_steps: 600", "max_steps: 300"))
    r = learn(base + ["--force", "--base-port", str(free_port_block())], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "at step" not in r.stdout  # nothing restored: a new run under the same id
    status = json.loads((res / "f" / "run_logs" / "training_status.json").read_text())
    assert 300 < status["Basic"]["final_checkpoint"]["steps"] < 400  # not 600 + 300
    events = sorted(p.name for p in (res / "f" / "Basic").glob("events.out.tfevents.*"))
    assert len(events) == 1 and events != first_events  # the old summaries were cleared
    steps = [step for step, _ in scalars(res / "f" / "Basic")[0]["Environment/Cumulative Reward"]]
    assert steps == [300]


def test_extrinsic_reward_and_timers_gauges_as_mlagents(tmp_path, basic_config, env_no_proxy):
    """Policy/Extrinsic Reward is what the extrinsic signal paid (strength x return here: basic
    sends no group reward); every summary is mirrored into timers.json gauges, Step included."""
    cfg = basic_config(max_steps=900, interval=900, summary=300)
    cfg.write_text(cfg.read_text().replace("strength: 1.0", "strength: 0.5"))
    assert "strength: 0.5" in cfg.read_text()
    res = tmp_path / "results"
    r = learn([str(cfg), "--env", "stub:basic", "--run-id", "g", "--results-dir", str(res), "--seed", "4",
               "--base-port", str(free_port_block())], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-2000:]
    tags, _ = scalars(res / "g" / "Basic")
    returns, paid = dict(tags["Environment/Cumulative Reward"]), dict(tags["Policy/Extrinsic Reward"])
    assert sorted(returns) == sorted(paid) == [300, 600, 900]
    for step, value in returns.items():
        assert paid[step] == pytest.approx(0.5 * value, rel=1e-5, abs=1e-7)
    assert "Step" not in tags and "Is Training" not in tags  # hidden from TensorBoard, as in ML-Agents
    gauges = json.loads((res / "g" / "run_logs" / "timers.json").read_text())["gauges"]
    assert gauges["Basic.Step.mean"]["count"] == 3 and 900 <= gauges["Basic.Step.mean"]["value"] < 1000
    assert gauges["Basic.Environment.CumulativeReward.mean"]["value"] == pytest.approx(returns[900], rel=1e-6)
    assert gauges["Basic.Policy.ExtrinsicReward.mean"]["count"] == 3


@pytest.mark.may_skip_in_ci  # another program may hold port 5004 on any machine, CI's included
def test_editor_mode_listens_on_5004_and_trains_the_player_that_connects(tmp_path, basic_config, env_no_proxy):
    """No --env: the trainer says it waits on 5004 (--base-port is for built players only); a
    'Play' (here the stub, started by hand on 5004, as the Editor would connect) is trained."""
    with socket.socket() as probe:
        try:
            probe.bind(("127.0.0.1", 5004))
        except OSError:
            pytest.skip("port 5004 (the Editor's) is taken on this machine")
    cmd = [sys.executable, "-m", "trainer.cli", str(basic_config(max_steps=300, interval=300)),
           "--run-id", "editor", "--results-dir", str(tmp_path / "results"),
           "--base-port", str(free_port_block()), "--timeout-wait", "60"]
    trainer = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               env=env_no_proxy)
    player = None
    try:
        lines = []
        for line in trainer.stdout:
            lines.append(line)
            if "Listening on port 5004" in line:
                break
        assert "Start training by pressing the Play button" in "".join(lines), "".join(lines)
        player = subprocess.Popen([sys.executable, "-m", "unity_stub_env.cli", "--task", "basic",
                                   "--mlagents-port", "5004", "-logFile", str(tmp_path / "editor.log")],
                                  cwd=tmp_path, env=env_no_proxy)
        out, _ = trainer.communicate(timeout=120)
        assert trainer.returncode == 0, out[-3000:]
        assert player.wait(timeout=30) == 0  # the trainer ended the session with status 400
    finally:
        for proc in (trainer, player):
            if proc is not None and proc.poll() is None:
                proc.kill()
    assert (tmp_path / "results" / "editor" / "Basic.onnx").is_file()
    status = json.loads((tmp_path / "results" / "editor" / "run_logs" / "training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] > 300
