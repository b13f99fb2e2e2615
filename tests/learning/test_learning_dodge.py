"""Learning smoke test for ``dodge`` (the dodge thesis, docs/stub-tasks.md): our trainer, the stub
as a separate process over real gRPC, 14 agents, a fixed seed and a bounded number of steps.

The thesis' configuration (3 x 512; its 5 M 0.x environment steps of 14 agents are 70 M agent steps,
docs/configuration.md "Legacy formats") is a bench run (bench/RESULTS.md, "dodge: a 5 M
agent-step run"); this test uses a
small network with a higher learning rate so that a short run shows learning. What it can learn
in 120,000 steps is mostly to spend less effort: the effort terms cost a random-acting character
~1.35 per episode and a still one ~0.39 (unity-stub-env --task dodge --evaluate zero). Measured
(seed 1): mean return -4.26 at the first summary and -3.87 over the last three (-3.75..-3.97);
episode effort 1.34 -> 1.09. Thresholds: the last three summaries' mean return beats the first
summary by >= 0.2 (the summaries' standard error is ~0.07: ~285 episodes of std ~1.15 each), and
the episode effort falls by >= 0.1.
"""
from __future__ import annotations

import textwrap

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import free_port_block, learn

pytestmark = pytest.mark.slow

SMALL_DODGE = """
behaviors:
  Dodge:
    trainer_type: ppo
    hyperparameters: {batch_size: 512, buffer_size: 4096, learning_rate: 3.0e-3, beta: 1.0e-4,
                      epsilon: 0.2, lambd: 0.93, num_epoch: 5, learning_rate_schedule: constant}
    network_settings: {normalize: true, hidden_units: 64, num_layers: 2}
    reward_signals: {extrinsic: {gamma: 0.995, strength: 1.0}}
    checkpoint_interval: 1000000
    max_steps: 120000
    time_horizon: 128
    summary_freq: 10000
"""


def test_dodge_spends_less_effort_after_120k_steps(tmp_path, env_no_proxy):
    cfg = tmp_path / "dodge.yaml"
    cfg.write_text(textwrap.dedent(SMALL_DODGE))
    r = learn([str(cfg), "--env", "stub:dodge", "--seed", "1", "--run-id", "d",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    acc = EventAccumulator(str(tmp_path / "results" / "d" / "Dodge"), size_guidance={"scalars": 0})
    acc.Reload()
    reward = [(e.step, e.value) for e in acc.Scalars("Environment/Cumulative Reward")]
    effort = [e.value for e in acc.Scalars("Dodge/Episode Effort")]
    assert reward[-1][0] == 120000 and len(reward) == 12
    last = sum(value for _, value in reward[-3:]) / 3
    assert last >= reward[0][1] + 0.2, reward
    assert effort[-1] <= effort[0] - 0.1, effort
    assert (tmp_path / "results" / "d" / "Dodge.onnx").exists()
