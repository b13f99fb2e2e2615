"""Data-parallel ranks outside Slurm (trainer/distributed.py): two trainer processes on this
machine, each with its own stub simulator, train one policy. Started by torchrun, or by hand
with RANK / WORLD_SIZE / MASTER_ADDR / MASTER_PORT. A stop signal that reaches one rank stops
both at the same exchange; a rank that dies ends the run with rank 0's final checkpoint.
(tests/slurm/test_ranks.py runs the same under srun, on one node and on two.)"""
from __future__ import annotations

import multiprocessing
import os
import queue
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
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
    # the YAML's buffer_size 128 and batch_size 32 are the two ranks' together
    assert "Basic: 2 ranks x buffer_size 64 and batch_size 16 each (the YAML's split evenly): 128 experiences " \
           "per update, 32 per gradient step." in text
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


# ------------------------------------------------------------------ one YAML, any number of ranks
UPDATE_ROWS = 220  # the buffer of the single process; each of 2 ranks holds half of it


def _update_weights(rank: int, world: int, port: int, numpy_update: bool, out) -> None:
    """One PPO update (3 epochs of one minibatch, batch_size = buffer_size = UPDATE_ROWS in the
    YAML) on this rank's share of the same experiences; its flat weights into ``out``."""
    import torch.distributed as dist

    from protos.types import ActionSpec, BehaviorSpec
    from tests.unit.test_ppo_numpy_update import feed, vec
    from trainer.config.settings import NetworkSettings, PPOSettings, TrainerSettings
    from trainer.distributed import Ranks
    from trainer.ppo.hyperparams import PPOHyperparams
    from trainer.ppo.trainer import PPOTrainer

    torch.set_num_threads(1)
    settings = TrainerSettings(
        hyperparameters=PPOSettings(batch_size=UPDATE_ROWS, buffer_size=UPDATE_ROWS, learning_rate=3e-3,
                                    num_epoch=3, beta=5e-3),
        network_settings=NetworkSettings(normalize=True, hidden_units=24, num_layers=2))
    ranks = Ranks(rank=rank, world=world, backend="gloo" if world > 1 else None)
    if world > 1:
        dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    mine = ranks.settings_for(settings, "B")
    share = UPDATE_ROWS // world
    assert (mine.hyperparameters.batch_size, mine.hyperparameters.buffer_size) == (share, share)
    spec = BehaviorSpec((vec(5), vec(3, "w")), ActionSpec(2, (4,)))
    trainer = PPOTrainer("B", spec, PPOHyperparams.from_settings(mine), seed=5, use_numpy_update=numpy_update)
    feed([trainer], True, (70, 90, 60), done=lambda k, length: length == 90)  # the same 220 rows everywhere
    data = trainer.buffer.concatenated()
    trainer.buffer.clear()
    trainer.buffer.append({key: value[rank * share:(rank + 1) * share] for key, value in data.items()})
    before = torch.cat([p.detach().flatten().clone() for p in trainer.optimizer.params])
    if world > 1:
        ranks.wire(trainer)
    trainer.update(rows=share)
    after = torch.cat([p.detach().flatten() for p in trainer.optimizer.params])
    out.put((rank, before.numpy(), after.numpy()))
    if world > 1:
        dist.destroy_process_group()


def _updates(world: int, numpy_update: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    context = multiprocessing.get_context("spawn")
    out = context.Queue()
    port = free_port_block(1)
    procs = [context.Process(target=_update_weights, args=(rank, world, port, numpy_update, out))
             for rank in range(world)]
    for p in procs:
        p.start()
    got = {}
    deadline = time.monotonic() + 240
    while len(got) < world:  # a rank that dies (an import error, say) fails the test now, not at the deadline
        try:
            rank, before, after = out.get(timeout=1)
            got[rank] = (before, after)
        except queue.Empty:
            dead = [p.exitcode for p in procs if p.exitcode not in (None, 0)]
            assert not dead and time.monotonic() < deadline, f"rank processes exited with {dead} or hung"
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    return [got[rank] for rank in range(world)]


@pytest.mark.parametrize("numpy_update", [True, False], ids=["numpy-update", "torch-update"])
def test_the_same_data_in_one_and_two_ranks_gives_the_same_update(numpy_update):
    """buffer_size and batch_size are global: 2 gloo ranks holding half the experiences each
    (minibatches of batch_size / 2, gradients averaged, advantages normalised over both buffers)
    make the update one process makes on all of them, to 1e-6."""
    (before, alone), = _updates(1, numpy_update)
    (before0, rank0), (before1, rank1) = _updates(2, numpy_update)
    np.testing.assert_array_equal(before0, before)  # the same start everywhere
    np.testing.assert_array_equal(before1, before)
    np.testing.assert_array_equal(rank0, rank1)  # the ranks stay bit-identical
    assert np.abs(alone - before).max() > 1e-3  # the update moved the weights: 1e-6 means something
    np.testing.assert_allclose(rank0, alone, rtol=0, atol=1e-6)


def test_a_batch_the_ranks_cannot_share_is_one_message_and_exit_2(tmp_path, env_no_proxy):
    """batch_size 30 does not split over 4 ranks: refused at start, before a simulator or a
    results folder exists, with the nearest values that do and the per-rank flag."""
    cfg = tmp_path / "odd.yaml"
    cfg.write_text(BASIC.format(max_steps=100).replace("batch_size: 32", "batch_size: 30"))
    args = [str(cfg), "--env", "stub:basic", "--run-id", "odd", "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block(2))]
    env = {**_env(env_no_proxy), "RANK": "0", "WORLD_SIZE": "4", "MASTER_ADDR": "127.0.0.1",
           "MASTER_PORT": str(free_port_block(1))}
    r = subprocess.run([sys.executable, "-m", "trainer.cli", *args], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120, env=env)
    assert r.returncode == 2, r.stderr[-2000:]
    assert ("behaviors.Basic.hyperparameters.batch_size is 30: with 4 data-parallel ranks it must be a multiple "
            "of 4") in r.stderr and "Use 28 or 32, or --batch-per-rank" in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "results" / "odd").exists()
    # --batch-per-rank: each rank takes the YAML's values as they are; the same YAML passes the check
    from trainer.config.cli_args import parse_run_options
    from trainer.distributed import check_split, split

    options = parse_run_options([str(cfg), "--batch-per-rank"])
    check_split(options, 4)
    assert split(options.behaviors["Basic"], 4, options.batch_per_rank).hyperparameters.batch_size == 30
    halves = split(options.behaviors["Basic"], 2, False).hyperparameters
    assert (halves.batch_size, halves.buffer_size) == (15, 64)
