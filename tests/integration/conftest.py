"""Helpers for end-to-end runs: mlagents-like-learn and the stub simulator as real processes."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def free_port_block(n: int = 1) -> int:
    """A base port such that base..base+n-1 are currently free on 127.0.0.1."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            base = s.getsockname()[1]
        if base + n >= 65535:
            continue
        ok = True
        for p in range(base, base + n):
            with socket.socket() as t:
                try:
                    t.bind(("127.0.0.1", p))
                except OSError:
                    ok = False
                    break
        if ok:
            return base
    raise RuntimeError("no free port block")


def learn(args: list[str], cwd: Path, timeout: float = 240, **kw) -> subprocess.CompletedProcess:
    """Run mlagents-like-learn in a separate process (the console script's module)."""
    cmd = [sys.executable, "-m", "trainer.cli", *args]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout, **kw)


def train_on_stub(tmp_path: Path, config: Path, task: str, behavior: str, env: dict, *, num_areas: int,
                  seed: int = 1, run_id: str = "r", timeout: float = 600):
    """Train ``config`` on ``stub:TASK`` with mlagents-like-learn in its own process (real gRPC),
    results under ``tmp_path/results/RUN_ID``; asserts it exited 0 and returns the behavior's
    TensorBoard events, read back (an EventAccumulator)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    r = learn([str(config), "--env", f"stub:{task}", "--num-areas", str(num_areas), "--seed", str(seed),
               "--run-id", run_id, "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=timeout, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    acc = EventAccumulator(str(tmp_path / "results" / run_id / behavior), size_guidance={"scalars": 0})
    acc.Reload()
    return acc


BASIC_YAML = """
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {{batch_size: 32, buffer_size: 256, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 3}}
    network_settings: {{normalize: false, hidden_units: 20, num_layers: 1}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    keep_checkpoints: {keep}
    checkpoint_interval: {interval}
    max_steps: {max_steps}
    time_horizon: 3
    summary_freq: {summary}
"""


@pytest.fixture
def basic_config(tmp_path):
    def make(max_steps=1500, interval=500, summary=500, keep=5, name="basic.yaml"):
        p = tmp_path / name
        p.write_text(textwrap.dedent(BASIC_YAML.format(max_steps=max_steps, interval=interval,
                                                       summary=summary, keep=keep)))
        return p

    return make


@pytest.fixture
def env_no_proxy():
    env = dict(os.environ)
    for k in ("http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY", "grpc_proxy"):
        env.pop(k, None)
    return env


def run_with_signals(cmd, cwd, env, triggers, timeout: float = 60) -> tuple[int, str]:
    """Run ``cmd``; when an output line contains ``triggers[0][0]`` (all of them, for a tuple of
    strings), send signal ``triggers[0][1]``, and so on in order; after the last one wait up to
    ``timeout`` s for the exit (at least one trigger). Returns (exit code, whole output)."""
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    pending, lines = list(triggers), []
    try:
        for line in proc.stdout:
            lines.append(line)
            wanted = pending[0][0]
            if all(part in line for part in ((wanted,) if isinstance(wanted, str) else wanted)):
                proc.send_signal(pending.pop(0)[1])
                if not pending:
                    break
        out, _ = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, "".join(lines) + out
