"""The real ``mlagents-learn`` 1.1.0 trains the stub's ``basic`` task through a Unity-style build.

Known limitation of the peer, not of the stub: mlagents 1.1.0 calls ``torch.onnx.export`` without
``dynamo=False``; on torch 2.13 the default dynamo exporter imports ``onnxscript``, which the
interop venv does not have. The export runs at every checkpoint, so a checkpoint inside the run
crashes training at that step (observed: ``Basic-997.pt`` written, then ModuleNotFoundError).
The test therefore puts ``checkpoint_interval`` above ``max_steps``: training runs to the end,
the FINAL export fails the same way (exit code 1), and everything written before it is checked.
If onnxscript is ever present the run exits 0 and ``Basic.onnx`` appears; both outcomes pass.
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

MAX_STEPS = 3000
SUMMARY_FREQ = 1000
CONFIG = {
    "behaviors": {
        "Basic": {
            "trainer_type": "ppo",
            "hyperparameters": {"batch_size": 32, "buffer_size": 256},
            "network_settings": {"hidden_units": 20, "num_layers": 1},
            "max_steps": MAX_STEPS,
            "summary_freq": SUMMARY_FREQ,
            "checkpoint_interval": 100 * MAX_STEPS,  # > max_steps: see the module docstring
            "time_horizon": 3,
        }
    }
}
# Basic's episode return by hand: best 7 * -0.01 + 1.0 = 0.93; worst 100 steps of -0.01 = -1.0
BEST_RETURN, WORST_RETURN = 0.93, -1.0


def _stub_processes_on_port(port: int) -> list[int]:
    """Live pids whose command line carries ``--mlagents-port <port>`` (zombies excluded)."""
    needle = f"--mlagents-port\0{port}\0".encode()
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if needle in (entry / "cmdline").read_bytes() and "Z" not in _state(entry):
                pids.append(int(entry.name))
        except OSError:
            continue
    return pids


def _state(proc_dir: Path) -> str:
    for line in (proc_dir / "status").read_text().splitlines():
        if line.startswith("State:"):
            return line.split(":", 1)[1].strip()[:1]
    return ""


@pytest.fixture(scope="module")
def trained_run(interop_python, tmp_path_factory, stub_launcher, free_port):
    """Runs mlagents-learn once for all checks of this module."""
    folder = tmp_path_factory.mktemp("mlagents_learn")
    exe = stub_launcher(folder, "basic")
    config = folder / "basic.yaml"
    config.write_text(yaml.safe_dump(CONFIG))
    results = folder / "results"
    port = free_port()
    learn = interop_python.parent / "mlagents-learn"
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    completed = subprocess.run(
        [str(learn), str(config), "--env", str(exe.with_suffix("")), "--run-id", "interop",
         "--results-dir", str(results), "--no-graphics", "--base-port", str(port), "--seed", "3"],
        capture_output=True, text=True, timeout=240, cwd=folder, env=env,
    )
    return completed, results / "interop", port


def test_training_ran_to_max_steps(trained_run):
    completed, run_dir, _ = trained_run
    output = completed.stdout + completed.stderr
    if completed.returncode != 0:
        assert completed.returncode == 1 and "No module named 'onnxscript'" in output, output[-4000:]
    assert "Connected to Unity environment with package version 3.0.0 and communication version 1.5.0" in output
    assert "Connected new brain: Basic?team=0" in output
    for step in range(SUMMARY_FREQ, MAX_STEPS + 1, SUMMARY_FREQ):
        assert f"Basic. Step: {step}. Time Elapsed:" in output


def test_stub_exited_cleanly(trained_run):
    _, run_dir, port = trained_run
    assert _stub_processes_on_port(port) == []
    player_log = (run_dir / "run_logs" / "Player-0.log").read_text()
    assert "Task basic: behavior Basic?team=0, 1 agents (1 areas), seed 3" in player_log
    # mlagents-learn's close answers the last call with status 400, then stops its grpcio server:
    # the answer or the server's end may reach the stub first; either way it quits cleanly
    assert ("The trainer closed the session (status 400)." in player_log
            or f"The trainer at localhost:{port} went away (INTERNAL); quitting like a Unity player does." in player_log
            or f"The trainer at localhost:{port} went away (UNAVAILABLE); quitting like a Unity player does."
            in player_log), player_log


def test_configuration_and_timers(trained_run):
    _, run_dir, _ = trained_run
    configuration = yaml.safe_load((run_dir / "configuration.yaml").read_text())
    basic = configuration["behaviors"]["Basic"]
    assert basic["hyperparameters"]["batch_size"] == 32
    assert basic["hyperparameters"]["buffer_size"] == 256
    assert basic["network_settings"]["hidden_units"] == 20
    assert basic["time_horizon"] == 3 and basic["max_steps"] == MAX_STEPS
    timers = json.loads((run_dir / "run_logs" / "timers.json").read_text())
    assert timers["name"] == "root"
    assert timers["metadata"]["mlagents_version"] == "1.1.0"
    assert timers["metadata"]["communication_protocol_version"] == "1.5.0"
    assert timers["gauges"]["Basic.Step.mean"]["count"] == MAX_STEPS // SUMMARY_FREQ


def test_tensorboard_scalars(trained_run):
    _, run_dir, _ = trained_run
    events = EventAccumulator(str(run_dir / "Basic"))
    events.Reload()
    reward = events.Scalars("Environment/Cumulative Reward")
    assert [e.step for e in reward] == [1000, 2000, 3000]
    assert all(WORST_RETURN <= e.value <= BEST_RETURN for e in reward)
    lengths = [e.value for e in events.Scalars("Environment/Episode Length")]
    assert all(1 <= value <= 100 for value in lengths)  # max_step = 100
    # A 3-way discrete policy starts near the uniform entropy ln 3 = 1.0986
    entropy = [e.value for e in events.Scalars("Policy/Entropy")]
    np.testing.assert_allclose(entropy, np.log(3), atol=0.05)
    # The stub's StatsSideChannel values land under their own keys
    goal = [e.value for e in events.Scalars("Basic/Large Goal Reached")]
    assert len(goal) == 3 and all(0.0 <= value <= 1.0 for value in goal)
    final_position = [e.value for e in events.Scalars("Basic/Last Final Position")]
    assert final_position and all(value == int(value) and 0 <= value <= 19 for value in final_position)


def test_checkpoint_files(trained_run):
    _, run_dir, _ = trained_run
    numbered = sorted((run_dir / "Basic").glob("Basic-*.pt"))
    assert numbered, "the final checkpoint's .pt is written before the ONNX export"
    step = int(numbered[-1].stem.split("-")[1])
    assert MAX_STEPS <= step <= MAX_STEPS + 3  # the last trajectory may overshoot by < time_horizon
    state = torch.load(run_dir / "Basic" / "checkpoint.pt", map_location="cpu", weights_only=False)
    assert {"Policy", "global_step", "Optimizer:value_optimizer", "Optimizer:critic"} <= set(state)
