"""Data-parallel ranks under a real srun (docker/slurm/train.sbatch with --ntasks=2): both ranks
train the stub task, both contribute experience (counted by rank 0 and written to TensorBoard),
and after every update the two ranks' weights hash the same (MLAGENTS_LIKE_DEBUG_WEIGHTS).
On two nodes (network namespaces) the gradients cross a veth pair and a bridge."""
from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.slurm.cluster import ROOT

pytestmark = pytest.mark.slurm

TEMPLATE = "docker/slurm/train.sbatch"
MAX_STEPS, BUFFER = 2000, 128
CONFIG = f"""
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {{batch_size: 32, buffer_size: {BUFFER}, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 3}}
    network_settings: {{normalize: true, hidden_units: 20, num_layers: 1}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    checkpoint_interval: 1000
    max_steps: {MAX_STEPS}
    time_horizon: 3
    summary_freq: 500
"""


def hashes(path: Path) -> list[tuple[str, ...]]:
    return [tuple(line.split()) for line in path.read_text().splitlines()]


def run_two_ranks(cluster, tmp_path: Path, *sbatch_args: str) -> tuple[str, Path]:
    cfg = tmp_path / "basic.yaml"
    cfg.write_text(CONFIG)
    weights = tmp_path / "weights"
    env = {**cluster.env, "MLAGENTS_LIKE_DEBUG_WEIGHTS": str(weights)}
    job = cluster.run("sbatch", "--parsable", "--mem=1G", "--cpus-per-task=1", *sbatch_args,
                      f"--output={tmp_path}/slurm-%j.out", TEMPLATE, str(cfg), "--env", "stub:basic",
                      "--seed", "1", "--results-dir", str(tmp_path / "results"), "--run-id", "ranks",
                      env=env, cwd=ROOT).stdout.strip().split(";")[0]
    info = cluster.wait_for_state(job, ("COMPLETED", "FAILED", "CANCELLED", "TIMEOUT"), 400)
    log = tmp_path / f"slurm-{job}.out"
    assert info["JobState"] == "COMPLETED", log.read_text()[-4000:]
    return log.read_text(), weights


def check_ranks(text: str, weights: Path, results: Path) -> None:
    assert "srun --kill-on-bad-exit=0" in text
    # the YAML's buffer_size and batch_size are both ranks' together: rank 0 prints the split
    assert (f"Basic: 2 ranks x buffer_size {BUFFER // 2} and batch_size 16 each (the YAML's split evenly): "
            f"{BUFFER} experiences per update, 32 per gradient step.") in text, text[-3000:]
    rank0, rank1 = hashes(Path(f"{weights}.rank0")), hashes(Path(f"{weights}.rank1"))
    # every update of 2 x (> 64) experiences, as one process's of > 128, up to 2000 steps:
    # at least 10 of them (with buffer_size per rank it was half as many)
    assert len(rank0) >= 10
    assert rank0 == rank1  # brain, update number, step, sha256 of the weights: bit for bit
    assert len({h[3] for h in rank0}) == len(rank0)  # the weights changed at every update
    per_rank = [int(n) for n in re.findall(r"experiences per rank since start: rank 0: (\d+), rank 1: (\d+)",
                                           text)[-1]]
    assert min(per_rank) >= 0.3 * MAX_STEPS  # both ranks contributed, about evenly
    assert sum(per_rank) >= MAX_STEPS
    acc = EventAccumulator(str(results / "ranks" / "Basic"), size_guidance={"scalars": 0})
    acc.Reload()
    last = {tag: acc.Scalars(tag)[-1].value for tag in ("Ranks/Steps of rank 0", "Ranks/Steps of rank 1")}
    assert last["Ranks/Steps of rank 1"] >= 0.3 * MAX_STEPS and last["Ranks/Steps of rank 0"] >= 0.3 * MAX_STEPS
    assert (results / "ranks" / "Basic.onnx").is_file()
    # both ranks' simulators wrote their logs beside the run: workers 0 and 1 (rank 1's first)
    assert {p.name for p in (results / "ranks" / "run_logs").glob("Player-*.log")} == {"Player-0.log",
                                                                                       "Player-1.log"}


def test_two_ranks_under_srun_train_one_policy(cluster, tmp_path):
    text, weights = run_two_ranks(cluster, tmp_path, "--ntasks=2")
    check_ranks(text, weights, tmp_path / "results")


def test_two_ranks_on_two_nodes_average_over_the_network(cluster2, tmp_path):
    text, weights = run_two_ranks(cluster2, tmp_path, "--nodes=2", "--ntasks-per-node=1")
    check_ranks(text, weights, tmp_path / "results")
    # rank 0 listened on its node's own address (Slurm's NodeAddr), gloo on the namespace's eth0
    node_addr = cluster2.nodes[0][1]
    assert re.search(rf"Rank 0 of 2 \(srun, gloo over eth0\): waiting for the other ranks at tcp://{node_addr}:9\d\d\d",
                     text), text[-3000:]


def test_two_ranks_survive_the_warning_signal_and_resume(cluster, tmp_path):
    """USR1 to the batch shell reaches both ranks through srun; rank 0 saves, the job is
    requeued, resumes at the saved step (rank 1 gets rank 0's restored weights) and completes."""
    cfg = tmp_path / "basic.yaml"
    cfg.write_text(CONFIG.replace(f"max_steps: {MAX_STEPS}", "max_steps: 3000"))
    weights = tmp_path / "weights"
    env = {**cluster.env, "MLAGENTS_LIKE_DEBUG_WEIGHTS": str(weights)}
    job = cluster.run("sbatch", "--parsable", "--mem=1G", "--cpus-per-task=1", "--ntasks=2",
                      f"--output={tmp_path}/slurm-%j.out", TEMPLATE, str(cfg), "--env", "stub:basic",
                      "--seed", "1", "--results-dir", str(tmp_path / "results"),
                      env=env, cwd=ROOT).stdout.strip().split(";")[0]
    log = tmp_path / f"slurm-{job}.out"
    wait_for_line(log, r"Basic\. Step: 1000\.")
    cluster.run("scancel", "--batch", "--signal=USR1", job)
    info = cluster.wait_for_state(job, ("COMPLETED", "FAILED", "CANCELLED", "TIMEOUT"), 400)
    text = log.read_text()
    assert info["JobState"] == "COMPLETED" and int(info["Restarts"]) == 1, (info, text[-4000:])
    first, second = text.split("(restart 1)")
    assert "exit 75); requeueing" in first, first[-3000:]
    saved = int(re.findall(r"Basic-(\d+)\.onnx to ", first)[-1])
    resumed = int(re.search(r"Loaded \S+checkpoint\.pt for behavior Basic at step (\d+)", second).group(1))
    assert 1000 <= saved == resumed < 3000
    rank0, rank1 = hashes(Path(f"{weights}.rank0")), hashes(Path(f"{weights}.rank1"))
    assert rank0 == rank1 and len(rank0) >= 8  # both starts' updates, bit-identical
    assert "trainer exited with status 0" in second


def wait_for_line(log: Path, pattern: str, timeout: float = 240) -> None:
    deadline = time.monotonic() + timeout
    while not (log.exists() and re.search(pattern, log.read_text(errors="replace"))):
        if time.monotonic() > deadline:
            raise TimeoutError(f"no {pattern!r} in {log}")
        time.sleep(0.2)
