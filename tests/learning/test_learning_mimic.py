"""Learning smoke test for ``mimic`` (the mimic thesis, docs/stub-tasks.md): our trainer, the stub
as a separate process over real gRPC, 16 ragdolls (2 areas), a fixed seed and a bounded number of
steps.

The thesis' configuration (2 x 1024, up to 5e7 steps) is a bench run (bench/README.md); this test
uses a small network with a higher learning rate on the standing motion with the default absolute
PD targets (action 0 = the standing pose). A fresh policy's mean action stands, but its exploration
noise (std 1 in action units: random PD targets over the whole range) topples it within ~0.85 s;
in 64,000 steps it learns to stay up longer and closer to the pose. With the earlier map (action 0 =
the middle of each range) the seed-1 run went 4.80 -> 5.56 with r_r ~0.03 throughout.

Measured over seeds (bench/learning_seeds.py --test mimic, bench/RESULTS.md 2026-11-28): the gain of
the last three summaries over the first is +2.09..+2.47 in mean return (first summary 7.0..7.3),
+2.3..+5.4 decisions in episode length (first 41.6..43.4) and +0.050..+0.062 in r_r for seeds 1-5
with the numpy initialisation; +2.05..+2.28, +3.1..+5.3 and +0.045..+0.056 for seeds 1-3 with
torch's earlier one. Thresholds: the mean return gains >= 1.5 (a summary's standard error is
~0.1, ~200 episodes of std ~1.5 each, so a policy that does not learn gains 0 +- ~0.15; every seed
>= 2.05), the last r_r beats the first by >= 0.03 (every seed >= 0.045), and the episode length
grows by >= 1.5 decisions (the noisiest of the three, +2.3..+5.4 over the seeds; the return and
r_r gains are what a policy that does not learn cannot reach).
"""
from __future__ import annotations

import textwrap

import pytest

from tests.integration.conftest import train_on_stub

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


def train_mimic(tmp_path, env, seed: int):
    """The test's run with ``seed`` (bench/learning_seeds.py runs it with others): its TensorBoard events."""
    cfg = tmp_path / "mimic.yaml"
    cfg.write_text(textwrap.dedent(SMALL_MIMIC))
    return train_on_stub(tmp_path, cfg, "mimic", "Mimic", env, num_areas=2, seed=seed, run_id="m", timeout=900)


def test_mimic_stays_up_longer_after_64k_steps(tmp_path, env_no_proxy):
    acc = train_mimic(tmp_path, env_no_proxy, seed=1)
    reward = [(e.step, e.value) for e in acc.Scalars("Environment/Cumulative Reward")]
    length = [e.value for e in acc.Scalars("Environment/Episode Length")]
    assert reward[-1][0] == 64000 and len(reward) == 8
    last = sum(value for _, value in reward[-3:]) / 3
    assert last >= reward[0][1] + 1.5, reward
    assert sum(length[-3:]) / 3 >= length[0] + 1.5, length
    pose = [e.value for e in acc.Scalars("Mimic/r_r")]
    assert len(pose) == 8 and pose[-1] >= pose[0] + 0.03, pose
    assert (tmp_path / "results" / "m" / "Mimic.onnx").exists()
