"""The real ``mlagents-learn`` 1.1.0 trains the stub's ``dodge`` task for a few thousand steps,
through the player that ``unity-stub-env --task dodge --write-launcher DIR`` writes.

The reference's final ONNX export fails on torch 2.13 without onnxscript (see
test_mlagents_learn.py); exit code 1 with that message is accepted, everything before is checked.
"""
from __future__ import annotations

import os
import subprocess
import sys

import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.interop.conftest import REPO

MAX_STEPS = 4200  # 300 decisions of 14 agents
SUMMARY_FREQ = 1400
CONFIG = {"behaviors": {"Dodge": {
    "trainer_type": "ppo",
    "hyperparameters": {"batch_size": 256, "buffer_size": 1400, "lambd": 0.93, "beta": 1.0e-2, "epsilon": 0.3},
    "network_settings": {"normalize": True, "hidden_units": 32, "num_layers": 2},
    "reward_signals": {"extrinsic": {"gamma": 0.995, "strength": 1.0}},
    "max_steps": MAX_STEPS, "summary_freq": SUMMARY_FREQ, "time_horizon": 64,
    "checkpoint_interval": 100 * MAX_STEPS,
}}}


def test_mlagents_learn_trains_dodge_through_the_written_launcher(interop_python, tmp_path, free_port):
    written = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "--task", "dodge",
                              "--write-launcher", str(tmp_path / "build")],
                             capture_output=True, text=True, timeout=60, cwd=REPO)
    assert written.returncode == 0, written.stderr
    player = tmp_path / "build" / "StubDodge"
    assert f"--env {player}" in written.stdout
    config = tmp_path / "dodge.yaml"
    config.write_text(yaml.safe_dump(CONFIG))
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the peer never sees our packages
    completed = subprocess.run(
        [str(interop_python.parent / "mlagents-learn"), str(config), "--env", str(player), "--run-id", "dodge",
         "--results-dir", str(tmp_path / "results"), "--no-graphics", "--base-port", str(free_port()),
         "--seed", "4"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env,
    )
    output = completed.stdout + completed.stderr
    if completed.returncode != 0:
        assert completed.returncode == 1 and "No module named 'onnxscript'" in output, output[-4000:]
    assert "Connected new brain: Dodge?team=0" in output
    for step in range(SUMMARY_FREQ, MAX_STEPS + 1, SUMMARY_FREQ):
        assert f"Dodge. Step: {step}. Time Elapsed:" in output
    run_dir = tmp_path / "results" / "dodge"
    player_log = (run_dir / "run_logs" / "Player-0.log").read_text()
    assert "Task dodge: behavior Dodge?team=0, 14 agents (1 areas), seed 4" in player_log
    events = EventAccumulator(str(run_dir / "Dodge"))
    events.Reload()
    assert [e.step for e in events.Scalars("Environment/Cumulative Reward")] == [1400, 2800, 4200]
    # one throw per episode: 0.4-1.4 s at 50 decisions/s; the stub's stats reach the reference
    assert all(20 <= e.value <= 65 for e in events.Scalars("Environment/Episode Length"))
    assert all(0.0 <= e.value <= 1.0 for e in events.Scalars("Dodge/Hit"))
    assert len(events.Scalars("Dodge/Episode Effort")) == 3
