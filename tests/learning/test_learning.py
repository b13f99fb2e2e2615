"""Learning proofs: fixed seeds, real gRPC, the stub as a separate process, bounded steps.

Thresholds are read back from the TensorBoard events the run wrote (Environment/Cumulative
Reward at the last summaries), i.e. the number a user would look at.
"""
from __future__ import annotations

import shutil

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import ROOT, free_port_block, learn
from unity_stub_env.tasks.basic import OPTIMAL_RETURN

pytestmark = pytest.mark.slow


def cumulative_reward(folder) -> list[tuple[int, float]]:
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    return [(e.step, e.value) for e in acc.Scalars("Environment/Cumulative Reward")]


def train_ball3d(tmp_path, env, seed: int) -> list[tuple[int, float]]:
    """The PPO ball3d test's run with ``seed`` (bench/learning_seeds.py runs it with others):
    its Environment/Cumulative Reward curve."""
    cfg = tmp_path / "ball3d.yaml"
    text = (ROOT / "configs" / "ball3d.yaml").read_text()
    cfg.write_text(text.replace("max_steps: 500000", "max_steps: 120000")
                       .replace("checkpoint_interval: 100000", "checkpoint_interval: 1000000"))
    assert "max_steps: 120000" in cfg.read_text()
    r = learn([str(cfg), "--env", "stub:ball3d", "--num-areas", "2", "--seed", str(seed), "--run-id", "b3",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    return cumulative_reward(tmp_path / "results" / "b3" / "3DBall")


def test_basic_reaches_90_percent_of_optimal_within_20k_steps(tmp_path, env_no_proxy):
    """configs/basic.yaml as shipped (20,000 steps), 4 areas, seed 1: the last summary's mean
    return must be >= 0.9 * 0.93 (walk right 7 steps: 7 * -0.01 + 1.0)."""
    cfg = tmp_path / "basic.yaml"
    shutil.copy(ROOT / "configs" / "basic.yaml", cfg)
    r = learn([str(cfg), "--env", "stub:basic", "--num-areas", "4", "--seed", "1", "--run-id", "b",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    curve = cumulative_reward(tmp_path / "results" / "b" / "Basic")
    assert curve[-1][0] == 20000
    assert curve[0][1] < 0.5 * OPTIMAL_RETURN  # it starts far from optimal...
    assert curve[-1][1] >= 0.9 * OPTIMAL_RETURN, curve  # ...and ends within 10% of it


def test_ball3d_learns_to_hold_the_ball(tmp_path, env_no_proxy):
    """configs/ball3d.yaml (ML-Agents' 3DBall hyperparameters) cut to 120,000 steps, 2 areas
    (24 agents), seed 3. A policy that does nothing holds the ball ~13 decisions (mean return
    ~1.35: +0.1 per decision, -1 at the fall; the maximum is 100); with 500k steps, as the YAML is
    written, both trainers end at 100 (bench/train.py).

    Measured over seeds (bench/learning_seeds.py --test ball3d, bench/RESULTS.md 2026-11-28): the
    first summary 1.42..1.50, then 20.4..25.4 at 96k, 30.9..50.2 at 108k and 40.4, 67.2, 63.7,
    61.6, 60.6 at 120k for seeds 3, 1, 2, 4, 5 with the numpy initialisation; with torch's earlier one seed 3 went 1.48
    -> 70.2 and seed 1 1.39 -> 16.4 (96k) -> 22.5 (108k) -> 39.0. The last summaries sit on the
    steep part of the curve, so the value at 120k spreads widely between seeds. Thresholds: the
    first summary < 1.6 (untrained), the last >= 20: about 15x the untrained return, passed by
    every seed by 108k, half the lowest seed's 39.0 at 120k."""
    curve = train_ball3d(tmp_path, env_no_proxy, seed=3)
    assert curve[-1][0] == 120000
    first, last = curve[0][1], curve[-1][1]
    assert first < 1.6, curve
    assert last >= 20.0, curve


def test_sac_basic_reaches_90_percent_of_optimal_within_20k_steps(tmp_path, env_no_proxy):
    """configs/basic_sac.yaml as shipped (ML-Agents' Basic SAC hyperparameters, 20,000 steps), 4
    areas, seed 1: the same threshold as PPO's (measured 0.930 from step 14,000 on, -0.027 at the
    first summary; with torch's initialisation before 2026-11-28: 0.930 from 16,000, -0.013)."""
    r = learn([str(ROOT / "configs" / "basic_sac.yaml"), "--env", "stub:basic", "--num-areas", "4", "--seed", "1",
               "--run-id", "s", "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    curve = cumulative_reward(tmp_path / "results" / "s" / "Basic")
    assert curve[-1][0] == 20000
    assert curve[0][1] < 0.5 * OPTIMAL_RETURN
    assert curve[-1][1] >= 0.9 * OPTIMAL_RETURN, curve


def test_sac_ball3d_learns_to_hold_the_ball(tmp_path, env_no_proxy):
    """configs/ball3d_sac.yaml (ML-Agents' 3DBall SAC hyperparameters) cut to 84,000 steps (PPO's
    test needs 120,000), 2 areas, seed 3: a mean return >= 40 at the last summary (one seed
    measured, not a spread: 1.51 at the first summary, 9.4 at 60k, 92.4 at 72k, 100 at 84k; since
    the initialisation is drawn in numpy, 2026-11-28: 1.36, 4.1, 37.7, 100)."""
    cfg = tmp_path / "ball3d_sac.yaml"
    text = (ROOT / "configs" / "ball3d_sac.yaml").read_text()
    cfg.write_text(text.replace("max_steps: 200000", "max_steps: 84000")
                       .replace("checkpoint_interval: 100000", "checkpoint_interval: 1000000"))
    assert "max_steps: 84000" in cfg.read_text()
    r = learn([str(cfg), "--env", "stub:ball3d", "--num-areas", "2", "--seed", "3", "--run-id", "s3",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=900, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    curve = cumulative_reward(tmp_path / "results" / "s3" / "3DBall")
    assert curve[-1][0] == 84000
    assert curve[0][1] < 1.6, curve
    assert curve[-1][1] >= 40.0, curve
