"""Self-play (trainer/selfplay.py): ELO against hand-computed values, the snapshot / swap /
team-change schedule against a hand-computed timeline, and its checkpoint state."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.artifacts.checkpoints import load_checkpoint, save_checkpoint
from trainer.config.settings import SelfPlaySettings
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer
from trainer.selfplay import ELO_STAT, SelfPlay, TeamController, elo_change, game_result

SPEC = BehaviorSpec(
    (ObservationSpec((4,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector"),),
    ActionSpec(0, (3, 3)),
)
HYPER = PPOHyperparams(hidden_units=8, num_layers=1, batch_size=4, buffer_size=8, max_steps=1000)


def mark(trainer: PPOTrainer, value: float) -> None:
    """Stamp ``value`` into the policy's first weight, to recognise its snapshots later."""
    with torch.no_grad():
        next(trainer.policy.actor.parameters()).view(-1)[0] = value


def marker(weights: dict) -> float:
    return float(next(v for v in weights.values() if v.dtype.is_floating_point).view(-1)[0])


def layer(settings: SelfPlaySettings, seed: int = 0) -> tuple[SelfPlay, PPOTrainer, TeamController]:
    trainer = PPOTrainer("Soccer", SPEC, HYPER, seed=0)
    controller = TeamController()
    sp = SelfPlay(settings, trainer, controller, seed=seed)
    return sp, trainer, controller


# ------------------------------------------------------------------------------------ ELO
def test_game_result_is_the_sign_of_the_last_reward():
    assert (game_result(0.99), game_result(-1.01), game_result(0.0)) == (1.0, 0.0, 0.5)


def test_elo_change_by_hand():
    # equal ratings: expected 0.5
    assert elo_change(1200, 1200, 1.0) == pytest.approx(0.5)
    assert elo_change(1200, 1200, 0.0) == pytest.approx(-0.5)
    # 200 points ahead: expected 1 / (1 + 10^(-200/400)) = 0.7597469266
    assert elo_change(1400, 1200, 1.0) == pytest.approx(1 - 0.7597469266, abs=1e-9)
    assert elo_change(1200, 1400, 0.0) == pytest.approx(-(1 - 0.7597469266), abs=1e-9)
    assert elo_change(1200, 1400, 0.5) == pytest.approx(0.5 - 0.2402530734, abs=1e-9)


def test_a_game_moves_the_learner_and_the_snapshot_opposite():
    sp, _, _ = layer(SelfPlaySettings(window=3))
    sp.add_team(0)
    sp.add_team(1)
    sp.elos = [1200.0, 1250.0, 1300.0, 1400.0]  # three snapshots, the learner last
    sp.current_opponent = 0
    assert sp.rate_trajectory(0.98, done=True, interrupted=False) == pytest.approx(1400.2402530734)
    assert sp.elos[0] == pytest.approx(1199.7597469266)
    assert sp.elos[1:3] == [1250.0, 1300.0]
    # a loss against snapshot 2 (1300): expected for 1400.24 vs 1300 is 1/(1+10^(-100.24/400))
    expected = 1 / (1 + 10 ** ((1300 - 1400.2402530734) / 400))
    sp.current_opponent = 2
    sp.rate_trajectory(-1.0, done=True, interrupted=False)
    assert sp.current_elo == pytest.approx(1400.2402530734 - expected)
    assert sp.elos[2] == pytest.approx(1300 + expected)


def test_games_that_do_not_end_or_are_interrupted_are_not_rated_and_self_games_change_nothing():
    sp, _, _ = layer(SelfPlaySettings(window=2, initial_elo=1000.0))
    sp.add_team(0)
    sp.add_team(1)
    assert sp.rate_trajectory(1.0, done=False, interrupted=False) is None
    assert sp.rate_trajectory(1.0, done=True, interrupted=True) is None
    assert sp.rate_trajectory(1.0, done=True, interrupted=False, group_done=False) is None  # a teammate plays on
    sp.current_opponent = -1  # playing the latest policy: one rating on both sides
    assert sp.rate_trajectory(1.0, done=True, interrupted=False) == pytest.approx(1000.0)
    assert sp.elos == [1000.0, 1000.0, 1000.0]


# ------------------------------------------------------------------------------- controller
def test_the_learning_team_cycles_through_the_queue():
    c = TeamController()
    for team in (0, 1, 2):
        c.subscribe(team, object())
    c.subscribe(1, object())  # a second behavior of the same team does not queue it twice
    order = [c.learning_team]
    for _ in range(4):
        c.change_team()
        order.append(c.learning_team)
    assert order == [0, 1, 2, 0, 1]


# --------------------------------------------------------------------------------- schedule
def test_snapshot_swap_and_team_change_follow_the_hand_computed_timeline():
    """save_steps 100, swap_steps 100, team_change 250, window 3, always a snapshot (ratio 0).
    Each call: trainer step and ghost step move to the value in the first column; the policy's
    first weight is stamped with the step, so each snapshot says when it was taken. By hand (the
    reference's strict '>' comparisons: a difference of exactly 100 or 250 does nothing):
        step  team change      snapshot (ring of 3)        swap (ghost - last swap > 100)
          60  -                -                           -
         120  -                [0, 120]                    yes
         180  -                -                           -
         240  -                [0, 120, 240]               yes
         300  yes (300) -> 1   -   (300 - 240 = 60)        yes (the team changed)
         360  -                [360, 120, 240]             -   (60)
         420  -                -                           yes (120)
         460  -                -   (460 - 360 = 100)       -   (40)
         550  -   (250)        [360, 550, 240]             yes (130)
         560  yes (260) -> 0   -                           yes (the team changed)
         660  -                [360, 550, 660]             -   (100)
    """
    sp, trainer, controller = layer(SelfPlaySettings(save_steps=100, swap_steps=100, team_change=250,
                                                     window=3, play_against_latest_model_ratio=0.0))
    mark(trainer, 0.0)
    assert sp.policy_for(0) is trainer.policy
    opponent = sp.policy_for(1)
    assert opponent is not trainer.policy and controller.learning_team == 0
    timeline = []
    for step in (60, 120, 180, 240, 300, 360, 420, 460, 550, 560, 660):
        mark(trainer, float(step))
        sp.count_ghost_steps(step - sp.ghost_step)
        changed = sp.advance(step)
        timeline.append((step, changed, controller.learning_team, [marker(w) for w in sp.snapshots],
                         sp.last_swap))
    assert timeline == [
        (60, False, 0, [0.0], 0),
        (120, False, 0, [0.0, 120.0], 120),
        (180, False, 0, [0.0, 120.0], 120),
        (240, False, 0, [0.0, 120.0, 240.0], 240),
        (300, True, 1, [0.0, 120.0, 240.0], 300),
        (360, False, 1, [360.0, 120.0, 240.0], 300),
        (420, False, 1, [360.0, 120.0, 240.0], 420),
        (460, False, 1, [360.0, 120.0, 240.0], 420),
        (550, False, 1, [360.0, 550.0, 240.0], 550),
        (560, True, 0, [360.0, 550.0, 240.0], 560),
        (660, False, 0, [360.0, 550.0, 660.0], 560),
    ]
    assert sp.snapshot_counter == 0
    # team 1 plays the snapshot drawn at the last swap (step 560, before 240 was overwritten);
    # team 0 learns with the trainer's policy
    assert sp.policy_for(0) is trainer.policy and sp.policy_for(1) is opponent
    assert marker(opponent.actor.state_dict()) == [360.0, 550.0, 240.0][sp.current_opponent]


def test_play_against_latest_model_ratio_one_always_plays_the_current_weights():
    sp, trainer, _ = layer(SelfPlaySettings(save_steps=10, swap_steps=10, team_change=10**6, window=4,
                                            play_against_latest_model_ratio=1.0))
    assert sp.policy_for(0) is trainer.policy  # the first team seen learns
    assert sp.policy_for(1) is not trainer.policy
    for step in range(20, 200, 20):
        mark(trainer, float(step))
        sp.count_ghost_steps(20)
        sp.advance(step)
        assert sp.current_opponent == -1
        assert marker(sp.policy_for(1).actor.state_dict()) == float(step)  # swapped at every call


def test_the_draw_follows_the_ratio():
    """ratio 0.25: about three swaps in four pick a snapshot (binomial, 400 draws: 5 sigma ~ 0.11)."""
    sp, trainer, _ = layer(SelfPlaySettings(save_steps=1, swap_steps=0, team_change=10**9, window=5,
                                            play_against_latest_model_ratio=0.25), seed=3)
    sp.policy_for(0), sp.policy_for(1)
    picks = []
    for step in range(1, 401):
        sp.count_ghost_steps(1)
        sp.advance(step * 2)
        picks.append(sp.current_opponent >= 0)
    assert abs(np.mean(picks) - 0.75) < 0.11


def test_opponent_acts_with_its_snapshot_in_one_batched_call():
    sp, trainer, _ = layer(SelfPlaySettings(play_against_latest_model_ratio=0.0, save_steps=1, swap_steps=0))
    assert sp.policy_for(0) is trainer.policy
    frozen = sp.policy_for(1)
    obs = np.random.default_rng(0).normal(size=(64, 4)).astype(np.float32)
    before = frozen.act([obs], deterministic=True).discrete.copy()
    with torch.no_grad():
        for p in trainer.policy.actor.parameters():
            p.add_(1.0)  # the learner moves on; the opponent keeps its snapshot until a swap
    assert np.array_equal(frozen.act([obs], deterministic=True).discrete, before)
    assert not np.array_equal(trainer.policy.act([obs], deterministic=True).discrete, before)
    sp.count_ghost_steps(1)
    sp.advance(2)  # a new snapshot (save_steps 1), then a swap to one of the window's two
    assert [marker(w) for w in sp.snapshots][0] != marker(sp.snapshots[1])
    assert marker(frozen.actor.state_dict()) == marker(sp.snapshots[sp.current_opponent])


# ------------------------------------------------------------------------------- checkpoints
def test_state_survives_a_checkpoint_file(tmp_path):
    settings = SelfPlaySettings(save_steps=10, swap_steps=5, team_change=35, window=3,
                                play_against_latest_model_ratio=0.5)
    sp, trainer, controller = layer(settings, seed=7)
    sp.policy_for(0), sp.policy_for(1)
    for step in range(10, 101, 10):
        mark(trainer, float(step))
        sp.count_ghost_steps(10)
        sp.advance(step)
        sp.current_opponent = sp.current_opponent  # noqa: PLW0127 (ratings move below)
        sp.rate_trajectory(1.0 if step % 20 else -1.0, done=True, interrupted=False)
    path = tmp_path / "c.pt"
    save_checkpoint(path, {"SelfPlay": sp.state_dict()})
    restored, trainer2, controller2 = layer(settings, seed=99)
    restored.load_state_dict(load_checkpoint(path)["SelfPlay"])
    assert restored.elos == pytest.approx(sp.elos)
    assert [marker(w) for w in restored.snapshots] == [marker(w) for w in sp.snapshots]
    assert (restored.snapshot_counter, restored.current_opponent, restored.ghost_step, restored.last_save,
            restored.last_swap, restored.last_team_change) == (
        sp.snapshot_counter, sp.current_opponent, sp.ghost_step, sp.last_save, sp.last_swap, sp.last_team_change)
    assert controller2.learning_team == controller.learning_team and list(controller2.queue) == list(controller.queue)
    restored.add_team(0), restored.add_team(1)
    assert marker(restored.policy_for(1 - controller.learning_team).actor.state_dict()) == marker(
        sp.policy_for(1 - controller.learning_team).actor.state_dict())
    assert restored.rng.uniform() == sp.rng.uniform()  # the draws continue where they were
    assert not math.isnan(restored.current_elo)


def test_before_the_first_swap_the_opponent_is_the_first_snapshot_and_rated_as_such():
    sp, trainer, _ = layer(SelfPlaySettings(window=4, initial_elo=1200.0))
    mark(trainer, 7.0)
    sp.policy_for(0)
    opponent = sp.policy_for(1)
    mark(trainer, 8.0)  # the learner moves on
    assert sp.current_opponent == 0 and marker(opponent.actor.state_dict()) == 7.0
    assert sp.rate_trajectory(1.0, done=True, interrupted=False) == pytest.approx(1200.5)
    assert sp.elos == pytest.approx([1199.5, 1200.0, 1200.0, 1200.0, 1200.5])


def test_resume_without_the_window_takes_the_elo_of_training_status(tmp_path):
    """A checkpoint without ``SelfPlay`` (written by mlagents-learn, or before self_play was on):
    --resume starts every rating from training_status.json's "elo", as ML-Agents does."""
    from trainer.artifacts.training_status import TrainingStatus
    from trainer.behavior import BehaviorRunner
    from trainer.config.settings import TrainerSettings

    settings = TrainerSettings(self_play=SelfPlaySettings(window=3))
    first = BehaviorRunner.create("Soccer", SPEC, settings, str(tmp_path), seed=0, device="cpu", training=True)
    save_checkpoint(first.paths.latest, first.trainer.state_dict())
    status = TrainingStatus()
    status.set_elo("Soccer", 1350.0)
    runner = BehaviorRunner.create("Soccer", SPEC, settings, str(tmp_path), seed=0, device="cpu", training=True)
    runner.resume(status)
    assert runner.self_play.elos == [1350.0] * 4
    # with the layer's state in the checkpoint, that state wins over training_status.json
    runner.self_play.elos = [1.0, 2.0, 3.0, 1401.0]
    runner.save_checkpoint(status)
    again = BehaviorRunner.create("Soccer", SPEC, settings, str(tmp_path), seed=0, device="cpu", training=True)
    status.set_elo("Soccer", 1350.0)
    again.resume(status)
    assert again.self_play.elos == [1.0, 2.0, 3.0, 1401.0]


# ------------------------------------------------------------------------ a team of two (POCA)
def _steps(ids, group_reward, terminal=False, interrupted=False):
    from protos.types import DecisionSteps, TerminalSteps

    n = len(ids)
    common = dict(obs=[np.zeros((n, 4), np.float32)], reward=np.zeros(n, np.float32),
                  agent_id=np.array(ids, np.int64), group_id=np.ones(n, np.int32),
                  group_reward=np.full(n, group_reward, np.float32))
    if terminal:
        return TerminalSteps(interrupted=np.full(n, interrupted), **common)
    return DecisionSteps(action_mask=None, **common)


def test_a_team_of_two_is_rated_once_per_player_when_its_group_game_ends(tmp_path):
    """soccer_twos' shape (unity_stub_env/tasks/soccer.py): the learning team's two players are one
    agent group, a goal ends both episodes with a group reward, no individual reward. As the
    reference's ghost trainer: each player's trajectory that ends with its whole group done (and not
    interrupted) is one game, so a goal is two games; a timeout none."""
    from protos.types import TerminalSteps
    from trainer.artifacts.training_status import TrainingStatus
    from trainer.behavior import BehaviorRunner
    from trainer.config.settings import TrainerSettings
    from trainer.rollout import GroupTracker

    settings = TrainerSettings(trainer_type="poca", self_play=SelfPlaySettings(window=3, initial_elo=1200.0))
    runner = BehaviorRunner.create("SoccerTwos", SPEC, settings, str(tmp_path), seed=0, device="cpu", training=True)
    runner.next_checkpoint = 10**9
    sp, status = runner.self_play, TrainingStatus()
    sp.add_team(0)
    sp.add_team(1)  # team 0 learns, team 1 plays the first snapshot (rated 1200)
    tracker = GroupTracker(SPEC, time_horizon=64)
    none = TerminalSteps.empty(SPEC)
    trajectories = []

    def play(end_reward, interrupted=False):
        """One group episode of players 1 and 2: two decisions, then both end together."""
        for _ in range(2):
            slots = tracker.on_step(none, _steps([1, 2], 0.0), trajectories.append)
            tracker.on_actions(slots, np.zeros((2, 0), np.float32), np.zeros((2, 2), np.int32),
                               np.zeros((2, 2), np.float32), None)
        tracker.on_step(_steps([1, 2], end_reward, terminal=True, interrupted=interrupted),
                        _steps([], 0.0), trajectories.append)
        ended, trajectories[:] = list(trajectories), []
        assert len(ended) == 2 and all(t.done and t.group.all_done for t in ended)
        return [runner.add_trajectory(t, status).get(ELO_STAT) for t in ended]

    # a goal in the 100th control step: +1 - 99 / 250 for both players = two wins against 1200
    first = 1200.0 + 0.5
    expected = 1 / (1 + 10 ** ((1199.5 - first) / 400))  # 0.50144 after the first game
    assert play(1 - 99 / 250) == [pytest.approx(first), pytest.approx(first + 1 - expected)]
    assert sp.elos[0] == pytest.approx(1200.0 - 0.5 - (1 - expected))  # the snapshot lost both
    before = list(sp.elos)
    assert play(0.0, interrupted=True) == [None, None]  # a timeout is no game
    assert sp.elos == before
    lost = play(-1.0)  # conceded: two losses, each moving the learner down by its expected score
    e1 = 1 / (1 + 10 ** ((before[0] - before[-1]) / 400))
    assert lost[0] == pytest.approx(before[-1] - e1)
    assert lost[1] < lost[0] and sp.elos[0] > before[0]
