"""Misbehaving simulators against a live trainer (mlagents-like-learn as a real process, the
simulator a real process speaking real HTTP/2: tests/integration/hostile_sim.py).

Each case must end in one clear message naming the simulator or behavior and the fault, exit
code 2, no traceback, within --timeout-wait (no hang), under an address-space limit of
``MEMORY_LIMIT`` for the trainer and its simulator: a spec the trainer cannot afford (10^8
continuous actions, 10^6 branches, a 20000x20000 PNG) is refused before anything is allocated
for it. docs/reliability.md ("Wire and messages") lists them.
"""
from __future__ import annotations

import json
import resource
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tests.integration.conftest import free_port_block

# the trainer imports torch (about 1.5 GB of address space, little of it resident); a hostile
# spec that were allocated (10^8 actions x 20 hidden units = 8 GB) would not fit
MEMORY_LIMIT = 4 << 30

CONFIG = """
behaviors:
  H:
    trainer_type: ppo
    hyperparameters: {batch_size: 16, buffer_size: 64, learning_rate: 3.0e-4, num_epoch: 1}
    network_settings: {normalize: false, hidden_units: 20, num_layers: 1}
    reward_signals: {extrinsic: {gamma: 0.9, strength: 1.0}}
    max_steps: %d
    time_horizon: 8
    summary_freq: 20
    checkpoint_interval: 100000
"""


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


HOSTILE_SIM = Path(__file__).with_name("hostile_sim.py")


def run_trainer(tmp_path, env_no_proxy, case: str, after: int = 0, max_steps: int = 100000,
                timeout_wait: int = 60, extra: tuple = ()) -> subprocess.CompletedProcess:
    # --timeout-wait also bounds the simulator's boot (as in mlagents-learn): since torch is
    # imported while the simulator boots (trainer/warmup.py) the import no longer adds to that
    # budget, and on a loaded machine a 20 s budget was too short for this script to start
    game = tmp_path / "Hostile.x86_64"
    # by path, not ``-m tests...``: a fresh clone's venv has the project packages but not ``tests``
    game.write_text(f"#!/bin/sh\nexec {sys.executable} {HOSTILE_SIM} \"$@\"\n")
    game.chmod(0o755)
    config = tmp_path / "h.yaml"
    config.write_text(textwrap.dedent(CONFIG % max_steps))
    env = dict(env_no_proxy, HOSTILE_CASE=case, HOSTILE_AFTER=str(after))
    cmd = [sys.executable, "-m", "trainer.cli", str(config), "--env", str(tmp_path / "Hostile"),
           "--base-port", str(free_port_block()), "--results-dir", str(tmp_path / "results"), "--run-id", "r",
           "--timeout-wait", str(timeout_wait), "--torch-device", "cpu", *extra]
    return subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=180, env=env,
                          preexec_fn=_limit_memory)


CASES = [
    ("wrong_version", "speaks communication API 0.9.0, which is not compatible"),
    ("huge_continuous", "Behavior 'H?team=0' declares 100000000 continuous actions (at most 2048)"),
    ("huge_branches", "Behavior 'H?team=0' declares 1000000 discrete branches (at most 1024)"),
    ("zero_branch", "declares discrete branch sizes [3, 0]: every branch needs at least one option"),
    ("branch_count_mismatch", "Behavior 'H?team=0' declares 3 discrete branches but lists 2 branch sizes [3, 2]"),
    ("no_observations", "Behavior 'H' sent an agent without any observation"),
    ("no_brain_parameters", "agents of behavior 'H?team=0' without ever sending its brain_parameters"),
    ("missing_observation", "sent fewer observations than its first agent"),
    ("wrong_sized_observation", "Observation 0 of agent id 2 (behavior 'H?team=0') has 3 floats"),
    ("mask_wrong_length", "Agent id 1 of behavior 'H?team=0' sent an action mask of 2 entries"),
    ("mask_everything", "Agent id 1 masked every action of discrete branch 0 (size 3)"),
    ("corrupt_png", "A PNG observation could not be decoded"),
    ("png_bomb", "A PNG observation declares 20000x20000 pixels but the sensor's shape needs 8x8"),
]


@pytest.mark.parametrize("case, message", CASES, ids=[c for c, _ in CASES])
def test_a_hostile_first_message_is_one_clear_error_and_exit_2(tmp_path, env_no_proxy, case, message):
    r = run_trainer(tmp_path, env_no_proxy, case)
    assert r.returncode == 2, r.stderr[-3000:]
    assert message.replace("'H'", "'H?team=0'") in r.stderr or message in r.stderr, r.stderr[-3000:]
    assert "Traceback" not in r.stderr and "MemoryError" not in r.stderr
    if case not in ("wrong_version", "no_observations"):  # (found in the handshake / by the trainer)
        assert "The simulator (" in r.stderr and "Hostile" in r.stderr, r.stderr[-3000:]  # which one


def test_a_spec_change_mid_run_stops_with_a_final_checkpoint(tmp_path, env_no_proxy):
    r = run_trainer(tmp_path, env_no_proxy, "spec_change", after=40)
    assert r.returncode == 2, r.stderr[-3000:]
    assert "Behavior 'H?team=0' changed its specification mid-run, from observations (2,) with 2 continuous " \
           "actions" in r.stderr
    assert "to observations (3,) with 3 continuous actions" in r.stderr and "Traceback" not in r.stderr
    status = json.loads((tmp_path / "results" / "r" / "run_logs" / "training_status.json").read_text())
    assert status["H"]["final_checkpoint"]["steps"] >= 40
    assert (tmp_path / "results" / "r" / "H" / "checkpoint.pt").is_file()


@pytest.mark.parametrize("case, message", [
    ("never_sends", "No simulator"),
    ("disconnect_mid_exchange", "exited"),
])
def test_a_simulator_that_goes_silent_or_away_is_restarted_then_reported(tmp_path, env_no_proxy, case, message):
    """Restarted once (the default limit is one per 60 s), then the same fault again: one
    message naming the simulator, exit 2, well within the bound --timeout-wait sets."""
    r = run_trainer(tmp_path, env_no_proxy, case, after=3 if case != "never_sends" else 0, timeout_wait=3)
    assert r.returncode == 2, r.stderr[-3000:]
    assert message in r.stderr and "Hostile" in r.stderr and "Traceback" not in r.stderr
    if case != "never_sends":  # the handshake completed, the player died mid-run: restarted once
        assert "restarting it" in r.stdout + r.stderr


def test_agents_sending_nan_or_inf_are_dropped_counted_and_the_run_completes(tmp_path, env_no_proxy):
    """Every step, beside a well-behaved agent: one with a NaN reward, one with an infinite
    observation, one finishing with one. They never reach the networks (the run's losses stay
    finite); each is counted in TensorBoard; training completes."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    r = run_trainer(tmp_path, env_no_proxy, "nan_every_step", max_steps=150)  # two PPO updates
    assert r.returncode == 0, r.stderr[-3000:]
    log = r.stdout + r.stderr
    assert log.count("sent a NaN or infinite reward or observation") == 1  # one line, then counted
    events = EventAccumulator(str(tmp_path / "results" / "r" / "H"))
    events.Reload()
    dropped = [e.value for e in events.Scalars("Environment/Non-finite Agent Steps Dropped")]
    # 3 per message; the summaries written (every 20 steps) cover at least 140 of the 150 messages
    assert sum(dropped) >= 3 * 140 and sum(dropped) % 3 == 0, dropped
    losses = [e.value for tag in events.Tags()["scalars"] if tag.startswith("Losses/") for e in events.Scalars(tag)]
    assert losses and np.isfinite(losses).all()
    assert (tmp_path / "results" / "r" / "H.onnx").is_file()


def test_a_second_m1_in_the_handshake_still_trains(tmp_path, env_no_proxy):
    """A player that sends its initialization twice: the second stands where M2 belongs (M2's
    content is not read), so the run goes on."""
    r = run_trainer(tmp_path, env_no_proxy, "handshake_twice", max_steps=60)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "results" / "r" / "H.onnx").is_file()


def test_editor_mode_port_in_use_gives_advice_that_works(tmp_path, env_no_proxy):
    """Without --env the Editor connects to 5004 whatever --base-port says: the message must
    not send the user to --base-port."""
    with socket.socket() as blocker:
        try:
            blocker.bind(("127.0.0.1", 5004))
        except OSError:
            pytest.skip("port 5004 (the Editor's) is taken on this machine")
        blocker.listen(1)
        config = tmp_path / "h.yaml"
        config.write_text(textwrap.dedent(CONFIG % 100))
        r = subprocess.run([sys.executable, "-m", "trainer.cli", str(config), "--results-dir",
                            str(tmp_path / "results"), "--base-port", str(free_port_block())],
                           cwd=tmp_path, capture_output=True, text=True, timeout=60, env=env_no_proxy)
    assert r.returncode == 2, r.stderr[-3000:]
    assert "the Unity Editor always connects to port 5004, so --base-port cannot help" in r.stderr
    assert "pick other ports with --base-port" not in r.stderr and "Traceback" not in r.stderr
