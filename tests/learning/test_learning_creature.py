"""Learning smoke test for ``creature`` (the creature report, docs/stub-tasks.md): our trainer, the
stub as a separate process over real gRPC, 4 arenas with the default quadruped on flat ground, a
fixed seed, 40,000 steps.

configs/creature.yaml (Walker's 3 x 512 network, 30 M steps) is a bench run (bench/RESULTS.md);
this test uses a 64 x 2 network with a higher learning rate. What it learns in 40,000 steps is to
lunge towards the target as it falls (episodes stay ~28 steps long; the reward per step rises).
Threshold: the last three summaries' mean beats the first summary by >= 0.4, about twice the
summaries' standard error (the measured run: bench/RESULTS.md, "Learning-test thresholds").
"""
from __future__ import annotations

import textwrap

import pytest

from tests.integration.conftest import train_on_stub

pytestmark = pytest.mark.slow

SMALL_CREATURE = """
behaviors:
  Creature:
    trainer_type: ppo
    hyperparameters: {batch_size: 512, buffer_size: 4096, learning_rate: 1.0e-3, beta: 1.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 4, learning_rate_schedule: constant}
    network_settings: {normalize: true, hidden_units: 64, num_layers: 2}
    reward_signals: {extrinsic: {gamma: 0.99, strength: 1.0}}
    checkpoint_interval: 1000000
    max_steps: 40000
    time_horizon: 128
    summary_freq: 4000
"""


def test_creature_return_rises_within_40k_steps(tmp_path, env_no_proxy):
    cfg = tmp_path / "creature.yaml"
    cfg.write_text(textwrap.dedent(SMALL_CREATURE))
    acc = train_on_stub(tmp_path, cfg, "creature", "Creature", env_no_proxy, num_areas=4, seed=1, run_id="c",
                        timeout=900)
    reward = [(e.step, e.value) for e in acc.Scalars("Environment/Cumulative Reward")]
    assert reward[-1][0] == 40000 and len(reward) == 10
    last = sum(value for _, value in reward[-3:]) / 3
    assert last >= reward[0][1] + 0.4, reward
    assert len(acc.Scalars("Creature/Distance")) == 10
    assert (tmp_path / "results" / "c" / "Creature.onnx").exists()
