"""Self-play learning proofs on the ``soccer`` stub task (1 v 1, PPO) and on ``soccer_twos`` (2 v 2,
MA-POCA, each team one agent group): our trainer, the stub as a separate process over real gRPC,
16 pitches, a fixed seed, a bounded number of steps.

configs/soccer.yaml cut to 60,000 steps. Two numbers a user would look at:

* ``Self-play/ELO`` in TensorBoard (the learning policy's rating against its own snapshots,
  initial_elo 1200, ML-Agents' update without a K factor: at most 1 point per game).
* The exported ONNX (deterministic) against a player choosing uniformly at random, on the task
  itself (``soccer.play_match``, 16 pitches, 1,000 decisions, goals for : against).

Measured over seeds (bench/learning_seeds.py --test soccer, bench/RESULTS.md 2026-11-28), ELO at
10k -> 60k and the match: seeds 1-5 with the numpy initialisation 1199.0 -> 1207.6 (100 : 36),
1202.5 -> 1208.3 (100 : 38), 1199.8 -> 1244.8 (462 : 1), 1200.1 -> 1222.0 (182 : 13), 1199.3 -> 1211.7
(218 : 34); with torch's earlier one 1198.6 -> 1234.5
(379 : 0), 1198.1 -> 1239.2 (378 : 4), 1199.7 -> 1248.3 (323 : 30). At 60k some seeds have only
begun to learn (about 1320 after the full 200k steps, bench/RESULTS.md). An untrained policy (the
ONNX of a run stopped before its first update, seeds 1-3, bench/learning_seeds.py --test
soccer_untrained) scores 8 : 54, 34 : 42, 32 : 34 against the random player, random against
random 37 : 52.

Thresholds: against the random player >= 70 goals and at least twice as many as conceded (every
trained seed >= 100 and 2.6x; no untrained policy scored more than it conceded, nor over 34), and
ELO at the last summary >= 1204 (every seed >= 1207.6). The ELO check alone is weak: a rating
that does not learn drifts by several points by 60k (the 10k summaries already lie 1198.1..1202.5),
so the match is the proof that the policy learned.
"""
from __future__ import annotations

import pytest

from tests.integration.conftest import ROOT, train_on_stub

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


def train_soccer(tmp_path, env, seed: int):
    """The 1 v 1 test's run with ``seed`` (bench/learning_seeds.py runs it with others): its
    TensorBoard events; the exported policy is tmp_path/results/s/Soccer.onnx."""
    cfg = tmp_path / "soccer.yaml"
    text = (ROOT / "configs" / "soccer.yaml").read_text()
    cfg.write_text(text.replace("max_steps: 200000", f"max_steps: {STEPS}"))
    assert f"max_steps: {STEPS}" in cfg.read_text()
    return train_on_stub(tmp_path, cfg, "soccer", "Soccer", env, num_areas=16, seed=seed, run_id="s", timeout=600)


def test_soccer_selfplay_elo_rises_and_the_policy_beats_a_random_player(tmp_path, env_no_proxy):
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    acc = train_soccer(tmp_path, env_no_proxy, seed=1)
    elo = [(e.step, e.value) for e in acc.Scalars("Self-play/ELO")]
    assert elo[-1][0] == STEPS
    assert abs(elo[0][1] - 1200) < 5, elo  # it starts at initial_elo...
    assert elo[-1][1] >= 1204, elo  # ...and the learner keeps beating its snapshots

    baseline = play_match(make_task("soccer", num_areas=16, seed=5), random_player(1), random_player(2), 400)
    assert baseline[0] < 3 * max(baseline[1], 1) and baseline[1] < 3 * max(baseline[0], 1), baseline
    wins, losses, _ = play_match(make_task("soccer", num_areas=16, seed=5),
                                 onnx_player(tmp_path / "results" / "s" / "Soccer.onnx"), random_player(2), 1000)
    assert wins >= 70 and wins >= 2 * losses, (wins, losses, baseline)


TWOS_STEPS = 100000


# 100,000 steps take longer than the 1 v 1's 60,000 (this test: 2 min 10 s at load 8, 8 min 16 s at
# load 19): the default 300 s is not enough on a machine shared by several trainings
@pytest.mark.timeout(900)
def test_soccer_twos_poca_selfplay_elo_rises_and_the_team_beats_a_random_team(tmp_path, env_no_proxy):
    """configs/soccer_twos.yaml (MA-POCA + self_play) cut to 100,000 steps, seed 2. A goal is two
    games (one per player of the learning group, rated once the group's episode is over), and only
    the learning team's 2 players per pitch count as steps, so the rating moves about half as fast
    per step as on the 1 v 1, and over 100k steps its noise (a few hundred games of about +-0.5
    points) is roughly +-10. 60,000 steps were not enough (seven runs at or through 60k: ELO
    1205.7-1229.7; of five final policies played against the random team three lost to it:
    19 : 37, 11 : 14, 44 : 80).

    Measured, this test (run three times, the same numbers every time): ELO 1205.3 at 10k, at most 1216.8
    (60k), 1211.7 at 100k; the exported ONNX (deterministic) against a team of two players choosing
    uniformly at random, 16 pitches, 1,000 decisions: 266 goals for, 41 against (at 50k still even,
    48 : 50; random against random 21 : 23 in 400 decisions). Runs with a larger max_steps decay
    beta and epsilon more slowly and learn differently: seed 2 with max_steps 150k gave ELO 1264.5
    at 100k (1232.0 with batch_size 256), 236 : 52 and 234 : 9 against random; bench/RESULTS.md has
    a 300k run (seed 1: 1243.0 at 100k, 1342.2 at 300k).

    Thresholds: ELO at the last summary >= 1208 (+8 over initial_elo: this seed's slow rise, near
    the rating's noise; the win over the random team is the stronger part); against the random team
    >= 100 goals and at least twice as many as conceded."""
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    cfg = tmp_path / "soccer_twos.yaml"
    text = (ROOT / "configs" / "soccer_twos.yaml").read_text()
    cfg.write_text(text.replace("max_steps: 300000", f"max_steps: {TWOS_STEPS}"))
    assert f"max_steps: {TWOS_STEPS}" in cfg.read_text() and "trainer_type: poca" in text
    acc = train_on_stub(tmp_path, cfg, "soccer_twos", "SoccerTwos", env_no_proxy, num_areas=16, seed=2, run_id="t",
                        timeout=900)
    elo = [(e.step, e.value) for e in acc.Scalars("Self-play/ELO")]
    print(elo)
    assert elo[-1][0] == TWOS_STEPS
    assert abs(elo[0][1] - 1200) < 10, elo
    assert elo[-1][1] >= 1208, elo

    baseline = play_match(make_task("soccer_twos", num_areas=16, seed=5), random_player(1), random_player(2), 400)
    assert baseline[0] < 3 * max(baseline[1], 1) and baseline[1] < 3 * max(baseline[0], 1), baseline
    wins, losses, _ = play_match(make_task("soccer_twos", num_areas=16, seed=5),
                                 onnx_player(tmp_path / "results" / "t" / "SoccerTwos.onnx"), random_player(2), 1000)
    print(wins, losses, baseline)
    assert wins >= 100 and wins >= 2 * losses, (wins, losses, baseline)
