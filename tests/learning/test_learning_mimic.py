"""Learning smoke test for ``mimic`` (seed 001): our trainer, the stub as a separate process over
real gRPC, 16 ragdolls (2 areas), a fixed seed and a bounded number of steps.

The thesis' configuration (2 x 1024, up to 5e7 steps) is a bench run (bench/README.md); this test
uses a small network with a higher learning rate on the standing motion with the spec's absolute
PD targets. A fresh policy aims every axis at the middle of its range (a deep crouch) and falls
within ~0.8 s; in 64,000 steps it learns to stay up longer. Measured (seed 1, 8 summaries of
8,000 steps): mean return 4.80 at the first summary and 5.56 over the last three (5.35..5.75),
episode length 39.7 -> 44.4 decisions. Thresholds: the last three summaries' mean return beats the
first by >= 0.4 (a summary's standard error is ~0.07: ~200 episodes of std ~1.0 each) and the mean
episode length grows by >= 2 decisions.
"""
from __future__ import annotations

import textwrap

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import free_port_block, learn

pytestmark = pytest.mark.slow

SMALL_MIMIC = """
behaviors:
  Mimic:
    trainer_type: ppo
    hyperparameters: {batch_size: 512, buffer_size: 4096, learning_rate: 3.0e-3, beta: 1.0e-4,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 5, learning_rate_schedule: constant}
    network_settings: {normalize: true, hidden_units: 64, num_layers: 2}
    reward_signals: {extrinsic: {gamma: 0.99, strength: 1.0}}
    checkpoint_interval: 1000000
    max_steps: 64000
    time_horizon: 128
    summary_freq: 8000
environment_parameters:
  motion: 0
"""


def test_mimic_stays_up_longer_after_64k_steps(tmp_path, env_no_proxy):
    cfg = tmp_path / "mimic.yaml"
    cfg.write_text(textwrap.dedent(SMALL_MIMIC))
    r = learn([str(cfg), "--env", "stub:mimic", "--seed", "1", "--run-id", "m", "--num-areas", "2",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=900, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    acc = EventAccumulator(str(tmp_path / "results" / "m" / "Mimic"), size_guidance={"scalars": 0})
    acc.Reload()
    reward = [(e.step, e.value) for e in acc.Scalars("Environment/Cumulative Reward")]
    length = [e.value for e in acc.Scalars("Environment/Episode Length")]
    assert reward[-1][0] == 64000 and len(reward) == 8
    last = sum(value for _, value in reward[-3:]) / 3
    assert last >= reward[0][1] + 0.4, reward
    assert sum(length[-3:]) / 3 >= length[0] + 2.0, length
    assert len(acc.Scalars("Mimic/r_r")) == 8 and (tmp_path / "results" / "m" / "Mimic.onnx").exists()
