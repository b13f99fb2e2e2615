"""Self-play learning proof on the ``soccer`` stub task (1 v 1): our trainer, the stub as a
separate process over real gRPC, 16 pitches, seed 1, a bounded number of steps.

configs/soccer.yaml cut to 60,000 steps. Two numbers a user would look at:

* ``Self-play/ELO`` in TensorBoard (the learning policy's rating against its own snapshots,
  initial_elo 1200, ML-Agents' update without a K factor: at most 1 point per game). Measured at
  the first and the last summary: seed 1 1198.6 -> 1234.5, seed 2 1198.1 -> 1239.7 (and about 1320
  after the full 200k steps, bench/RESULTS.md).
* The exported ONNX (deterministic) against a player choosing uniformly at random, on the task
  itself (``soccer.play_match``, 16 pitches, 1,000 decisions): measured 379 goals for, 0 against
  (seed 1) and 385 : 1 (seed 2); random against random scores about evenly (17 : 16 in 400).

Thresholds: ELO at the last summary >= 1215 (+15), and the trained policy scores at least 5
times as many goals as it concedes against the random player, with >= 100 goals.
"""
from __future__ import annotations

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import ROOT, free_port_block, learn

pytestmark = pytest.mark.slow

STEPS = 60000


def onnx_player(path):
    import numpy as np
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])

    def act(obs):
        masks = np.ones((len(obs), 6), np.float32)
        (actions,) = session.run(["deterministic_discrete_actions"], {"obs_0": obs, "action_masks": masks})
        return actions

    return act


def random_player(seed):
    import numpy as np

    rng = np.random.default_rng(seed)
    return lambda obs: rng.integers(0, 3, size=(len(obs), 2))


def test_soccer_selfplay_elo_rises_and_the_policy_beats_a_random_player(tmp_path, env_no_proxy):
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    cfg = tmp_path / "soccer.yaml"
    text = (ROOT / "configs" / "soccer.yaml").read_text()
    cfg.write_text(text.replace("max_steps: 200000", f"max_steps: {STEPS}"))
    assert f"max_steps: {STEPS}" in cfg.read_text()
    r = learn([str(cfg), "--env", "stub:soccer", "--num-areas", "16", "--seed", "1", "--run-id", "s",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    acc = EventAccumulator(str(tmp_path / "results" / "s" / "Soccer"), size_guidance={"scalars": 0})
    acc.Reload()
    elo = [(e.step, e.value) for e in acc.Scalars("Self-play/ELO")]
    assert elo[-1][0] == STEPS
    assert abs(elo[0][1] - 1200) < 5, elo  # it starts at initial_elo...
    assert elo[-1][1] >= 1215, elo  # ...and the learner keeps beating its snapshots

    baseline = play_match(make_task("soccer", num_areas=16, seed=5), random_player(1), random_player(2), 400)
    assert baseline[0] < 3 * max(baseline[1], 1) and baseline[1] < 3 * max(baseline[0], 1), baseline
    wins, losses, _ = play_match(make_task("soccer", num_areas=16, seed=5),
                                 onnx_player(tmp_path / "results" / "s" / "Soccer.onnx"), random_player(2), 1000)
    assert wins >= 100 and wins >= 5 * losses, (wins, losses, baseline)
