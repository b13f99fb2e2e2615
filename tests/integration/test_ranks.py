"""Data-parallel ranks outside Slurm (trainer/distributed.py): two trainer processes on this
machine, each with its own stub simulator, train one policy. Started by torchrun, or by hand
with RANK / WORLD_SIZE / MASTER_ADDR / MASTER_PORT. A stop signal that reaches one rank stops
both at the same exchange; a rank that dies ends the run with rank 0's final checkpoint.
(tests/slurm/test_ranks.py runs the same under srun, on one node and on two.)"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import torch

from tests.integration.conftest import free_port_block

BASIC = """
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {{batch_size: 32, buffer_size: 128, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 3}}
    network_settings: {{normalize: true, hidden_units: 20, num_layers: 1}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    checkpoint_interval: 500
    max_steps: {max_steps}
    time_horizon: 3
    summary_freq: 500
"""


def _args(tmp_path: Path, max_steps: int) -> list[str]:
    cfg = tmp_path / "basic.yaml"
    cfg.write_text(BASIC.format(max_steps=max_steps))
    return [str(cfg), "--env", "stub:basic", "--seed", "3", "--run-id", "ranks",
            "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block(2))]


def _env(env_no_proxy: dict, **extra: str) -> dict:
    return {**env_no_proxy, "PYTHONPATH": os.pathsep.join(p for p in (str(Path(__file__).parents[2]),
                                                                      env_no_proxy.get("PYTHONPATH")) if p),
            **extra}


def _start_ranks(tmp_path: Path, args: list[str], env: dict) -> list[subprocess.Popen]:
    port = str(free_port_block(1))
    procs = []
    for rank in range(2):
        out = open(tmp_path / f"rank{rank}.log", "w")
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "trainer.cli", *args], cwd=tmp_path, stdout=out, stderr=subprocess.STDOUT,
            env={**env, "RANK": str(rank), "WORLD_SIZE": "2", "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": port}))
        out.close()
    return procs


def _wait_for(path: Path, pattern: str, procs: list[subprocess.Popen], timeout: float = 180) -> None:
    deadline = time.monotonic() + timeout
    while not re.search(pattern, path.read_text(errors="replace")):
        if time.monotonic() > deadline or any(p.poll() is not None for p in procs):
            raise AssertionError(f"no {pattern!r} in {path}:\n{path.read_text()[-3000:]}")
        time.sleep(0.2)


def _finish(procs: list[subprocess.Popen], timeout: float = 120) -> list[int]:
    try:
        return [p.wait(timeout=timeout) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()


def _step_of(checkpoint: Path) -> int:
    return int(torch.load(checkpoint, weights_only=True)["global_step"]["step"])


def test_torchrun_two_ranks_train_one_policy_bit_identically(tmp_path, env_no_proxy):
    weights = tmp_path / "weights"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
           "-m", "trainer.cli", *_args(tmp_path, 1500)]
    r = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env=_env(env_no_proxy, MLAGENTS_LIKE_DEBUG_WEIGHTS=str(weights),
                                MLAGENTS_LIKE_DIST_SYNC_EVERY="1"))  # the others: the default 8
    text = r.stdout + r.stderr
    assert r.returncode == 0, text[-4000:]
    rank0 = Path(f"{weights}.rank0").read_text().splitlines()
    assert len(rank0) >= 4 and rank0 == Path(f"{weights}.rank1").read_text().splitlines()
    counts = [int(n) for n in re.findall(r"rank 0: (\d+), rank 1: (\d+)", text)[-1]]
    assert min(counts) >= 400 and sum(counts) >= 1500  # both ranks' experience counted
    assert "buffer_size 128 and batch_size 32 per rank x 2 ranks: 256 experiences per update" in text
    results = tmp_path / "results" / "ranks"
    assert (results / "Basic.onnx").is_file() and _step_of(results / "Basic" / "checkpoint.pt") >= 1500
    # rank 1's simulator is worker 1: its own port, seed and log
    assert sorted(p.name for p in (results / "run_logs").glob("Player-*.log")) == ["Player-0.log", "Player-1.log"]


def test_a_stop_signal_on_one_rank_stops_both_at_the_same_exchange(tmp_path, env_no_proxy):
    procs = _start_ranks(tmp_path, _args(tmp_path, 1_000_000), _env(env_no_proxy))
    _wait_for(tmp_path / "rank0.log", r"Basic\. Step: 1000\.", procs)
    procs[1].send_signal(signal.SIGUSR1)  # only rank 1 hears it
    assert _finish(procs) == [75, 75]
    text = (tmp_path / "rank0.log").read_text()
    assert "Learning was interrupted" in text and "another rank is gone" not in text
    saved = _step_of(tmp_path / "results" / "ranks" / "Basic" / "checkpoint.pt")
    assert saved >= 1000
    assert (tmp_path / "results" / "ranks" / "Basic.onnx").is_file()


def test_a_rank_that_dies_ends_the_run_with_rank_0s_checkpoint(tmp_path, env_no_proxy):
    procs = _start_ranks(tmp_path, _args(tmp_path, 1_000_000), _env(env_no_proxy))
    _wait_for(tmp_path / "rank0.log", r"Basic\. Step: 1000\.", procs)
    procs[1].kill()  # SIGKILL: no goodbye
    codes = _finish(procs)
    assert codes == [75, -signal.SIGKILL]
    text = (tmp_path / "rank0.log").read_text()
    assert "another rank is gone" in text
    assert _step_of(tmp_path / "results" / "ranks" / "Basic" / "checkpoint.pt") >= 1000
    assert (tmp_path / "results" / "ranks" / "Basic.onnx").is_file()


def test_sac_under_two_ranks_is_one_message_and_exit_2(tmp_path, env_no_proxy):
    """Ranks average PPO gradients only: a SAC config under WORLD_SIZE=2 is refused at start,
    before a simulator or a results folder exists."""
    cfg = tmp_path / "sac.yaml"
    cfg.write_text("behaviors:\n  Basic:\n    trainer_type: sac\n    max_steps: 100\n")
    args = [str(cfg), "--env", "stub:basic", "--run-id", "sac", "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block(2))]
    r = subprocess.run([sys.executable, "-m", "trainer.cli", *args], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120, env={**_env(env_no_proxy), "RANK": "0", "WORLD_SIZE": "2",
                                         "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(free_port_block(1))})
    assert r.returncode == 2, r.stderr[-2000:]
    assert "average PPO gradients only" in r.stderr and "trainer_type sac" in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "results" / "sac").exists()


def test_self_play_under_two_ranks_is_one_message_and_exit_2(tmp_path, env_no_proxy):
    """One self-play schedule per run: a self_play config under WORLD_SIZE=2 is refused at start."""
    cfg = tmp_path / "sp.yaml"
    cfg.write_text("behaviors:\n  Soccer:\n    max_steps: 100\n    self_play: {save_steps: 50}\n")
    args = [str(cfg), "--env", "stub:soccer", "--run-id", "sp", "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block(2))]
    r = subprocess.run([sys.executable, "-m", "trainer.cli", *args], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120, env={**_env(env_no_proxy), "RANK": "0", "WORLD_SIZE": "2",
                                         "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(free_port_block(1))})
    assert r.returncode == 2, r.stderr[-2000:]
    assert "cannot share one self-play schedule" in r.stderr and "Traceback" not in r.stderr, r.stderr[-2000:]
    assert not (tmp_path / "results" / "sp").exists()
