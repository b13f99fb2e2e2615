"""The ``soccer`` (1 v 1) and ``soccer_twos`` (2 v 2) stub tasks: two behaviors (one per team)
sharing one MuJoCo physics, mirrored team frames, goals and timeouts by hand, the 2 v 2's groups and
group rewards, the academy's per-behavior infos and actions, and the real mlagents_envs 1.1.0
driving them."""
from __future__ import annotations

import os

import numpy as np
import pytest

from protos.communicator_objects import agent_action_pb2
from tests.stub.conftest import INTEROP_PYTHON, run_stub_session
from unity_stub_env.academy import Academy, ActionCountError
from unity_stub_env.agents import EpisodeIdCounter
from unity_stub_env.tasks import make_task
from unity_stub_env.tasks.soccer import (
    BALL_MASS, BALL_RADIUS, PITCH_HALF_LENGTH, PLAYER_MASS, PLAYER_RADIUS, TIME_PENALTY, SoccerTask, SoccerTwosTask,
    play_match,
)

NO_CONT = np.zeros((4, 0), np.float32)


def place(task: SoccerTask, area: int, p0, p1, ball) -> None:
    """Players (area-relative x, y) and the ball, all at rest."""
    import mujoco

    q = task.qpos_rows[area]
    q[0:2], q[2:4] = p0, p1
    q[4:6] = task.origin[area] + np.asarray(ball)
    task.qvel_rows[area] = 0.0
    mujoco.mj_forward(task.model, task.data)


def test_specs_and_behaviors():
    task = make_task("soccer", num_areas=3, seed=0)
    assert task.num_agents == 6
    assert [key for key, _ in task.behaviors()] == ["Soccer?team=0", "Soccer?team=1"]
    assert [rows.tolist() for _, rows in task.behaviors()] == [[0, 2, 4], [1, 3, 5]]
    assert task.observation_specs[0].shape == (12,) and task.action_spec.discrete_branches == (3, 3)


def test_each_team_sees_the_pitch_in_its_own_frame():
    """Mirrored positions (turned by 180 degrees) give both players the same observation."""
    task = make_task("soccer", num_areas=2, seed=0)
    place(task, 1, (-0.8, 0.3), (0.8, -0.3), (0.2, 0.1))
    place(task, 0, (-0.8, 0.3), (0.8, -0.3), (0.0, 0.0))
    obs = task.observe()[0]
    np.testing.assert_allclose(obs[0], obs[1], atol=1e-6)  # area 0: symmetric, ball in the centre
    # area 1 by hand, team 0: own (-0.8, 0.3) / (L, W) = (-0.5, 0.25); ball - own = (1.0, -0.2) / L
    np.testing.assert_allclose(obs[2, [0, 1, 4, 5, 8, 9, 10, 11]],
                               [-0.5, 0.25, 1.0 / 1.6, -0.2 / 1.6, 1.6 / 1.6, -0.6 / 1.6, 0.2 / 1.6, 0.1 / 1.2],
                               atol=1e-5)
    # team 1 at (0.8, -0.3) sees itself at (-0.8, 0.3) and the ball at (-0.2, -0.1) in its frame
    np.testing.assert_allclose(obs[3, [0, 1, 4, 5, 10, 11]],
                               [-0.5, 0.25, 0.6 / 1.6, -0.4 / 1.6, -0.2 / 1.6, -0.1 / 1.2], atol=1e-5)


def test_forward_means_towards_the_goal_the_team_attacks():
    task = make_task("soccer", num_areas=1, seed=0)
    place(task, 0, (-0.8, 0.5), (0.8, -0.5), (0.0, 0.0))
    for _ in range(5):
        task.step(NO_CONT[:2], np.array([[1, 0], [1, 0]]))  # both: forward
    players = task.qpos_rows[0, 0:4].reshape(2, 2)
    # from rest under force F and damping c (tau = m / c = 1/6 s, top speed F / c = 2 m/s), in
    # t = 5 x 0.04 s: x = 2 (t - tau (1 - exp(-t / tau))) = 0.167 m; team 1 the mirror image
    assert players[0, 0] == pytest.approx(-0.8 + 0.167, abs=0.015)
    assert players[1, 0] == pytest.approx(0.8 - 0.167, abs=0.015)
    assert players[0, 0] + players[1, 0] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(players[:, 1], [0.5, -0.5])  # no sideways action, no sideways motion


def test_a_goal_pays_plus_and_minus_one_and_ends_the_episode_for_both():
    task = make_task("soccer", num_areas=2, seed=0)
    place(task, 1, (-0.8, 0.0), (0.8, 0.0), (PITCH_HALF_LENGTH + BALL_RADIUS + 0.05, 0.0))  # in team 1's goal
    place(task, 0, (-0.8, 0.0), (0.8, 0.0), (-(PITCH_HALF_LENGTH + BALL_RADIUS + 0.05), 0.0))  # in team 0's
    result = task.step(NO_CONT, np.zeros((4, 2), np.int64))
    np.testing.assert_allclose(result.rewards, [-1 - TIME_PENALTY, 1 - TIME_PENALTY,
                                                1 - TIME_PENALTY, -1 - TIME_PENALTY], atol=1e-6)
    assert result.done.tolist() == [True] * 4 and not result.interrupted.any()


def test_no_goal_until_max_step_is_an_interrupted_draw():
    task = make_task("soccer", num_areas=1, seed=0)
    rewards = []
    for t in range(task.max_step):
        result = task.step(NO_CONT[:2], np.zeros((2, 2), np.int64))
        rewards.append(result.rewards.copy())
        if t < task.max_step - 1:
            assert not result.done.any()
    assert result.done.tolist() == [True, True] and result.interrupted.tolist() == [True, True]
    assert np.sum(rewards, axis=0) == pytest.approx([-0.5, -0.5], abs=1e-4)  # 250 x -0.5 / 250


def test_the_academy_sends_each_team_as_its_own_behavior():
    academy = Academy(make_task("soccer", num_areas=2, seed=0), episode_counter=EpisodeIdCounter())
    batches = academy.collect_batches()
    assert [key for key, _ in batches] == ["Soccer?team=0", "Soccer?team=1"]
    infos = {key: b.protos() for key, b in batches}
    assert [len(v) for v in infos.values()] == [2, 2]
    ids = [i.id for v in infos.values() for i in v]
    assert len(set(ids)) == 4
    # team 0 forward (+x), team 1 nothing: only the rows of team 0 move
    forward = [agent_action_pb2.AgentActionProto(discrete_actions=[1, 0]) for _ in range(2)]
    academy.apply_actions(forward, behavior=0)
    academy.apply_actions([], behavior=1)
    assert academy.discrete.tolist() == [[1, 0], [0, 0], [1, 0], [0, 0]]
    with pytest.raises(ActionCountError, match=r"'Soccer\?team=1'"):
        academy.apply_actions(forward[:1], behavior=1)


def test_terminal_infos_go_to_each_team():
    task = make_task("soccer", num_areas=1, seed=0)
    academy = Academy(task, episode_counter=EpisodeIdCounter())
    academy.collect_batches()
    place(task, 0, (-0.8, 0.0), (0.8, 0.0), (PITCH_HALF_LENGTH + BALL_RADIUS + 0.05, 0.0))
    academy.advance()
    batches = {key: b.protos() for key, b in academy.collect_batches()}
    for key, sign in (("Soccer?team=0", 1), ("Soccer?team=1", -1)):
        done = [i for i in batches[key] if i.done]
        assert len(done) == 1 and len(batches[key]) == 2  # the terminal info, then the new episode
        assert done[0].reward == pytest.approx(sign - TIME_PENALTY, abs=1e-6)


# what runs in the real UnityEnvironment session of run_stub_session (conftest): env is reset; fill out
_SCRIPT = r"""
out = {"behaviors": sorted(env.behavior_specs)}
specs = [env.behavior_specs[f"Soccer?team={t}"] for t in (0, 1)]
out["same_specs"] = specs[0] == specs[1]
out["obs"] = [list(o.shape) for o in specs[0].observation_specs]
out["branches"] = list(specs[0].action_spec.discrete_branches)
ids = [env.get_steps(f"Soccer?team={t}")[0].agent_id.tolist() for t in (0, 1)]
out["ids"] = ids
results = {0: [], 1: []}
for _ in range(300):
    d0, _ = env.get_steps("Soccer?team=0")
    rel = d0.obs[0][:, 4:6] + np.array([-0.05, 0.0])  # chase a point just behind the ball
    a0 = np.where(rel > 0.02, 1, np.where(rel < -0.02, 2, 0)).astype(np.int32)
    env.set_actions("Soccer?team=0", ActionTuple(discrete=a0))
    n1 = len(env.get_steps("Soccer?team=1")[0])
    env.set_actions("Soccer?team=1", ActionTuple(discrete=np.zeros((n1, 2), np.int32)))
    env.step()
    ends = [env.get_steps(f"Soccer?team={t}")[1] for t in (0, 1)]
    for t in (0, 1):
        results[t] += [(float(r), bool(i)) for r, i in zip(ends[t].reward, ends[t].interrupted)]
    if any(not i for i in ends[0].interrupted):  # a goal (a timeout is interrupted)
        out["goal"] = [[(float(r), bool(i)) for r, i in zip(e.reward, e.interrupted) if not i] for e in ends]
        break
out["results"] = results
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_drives_both_teams():
    """A scripted team 0 (runs at the ball) against a team 1 standing still, through the real
    UnityEnvironment: two behaviors with team ids, identical specs, +1 / -1 at the first goal."""
    out = run_stub_session(["--task", "soccer", "--num-areas", "2", "--seed", "0"], _SCRIPT, timeout=180)
    assert out["behaviors"] == ["Soccer?team=0", "Soccer?team=1"]
    assert out["same_specs"] and out["obs"] == [[12]] and out["branches"] == [3, 3]
    assert len(out["ids"][0]) == 2 and len(out["ids"][1]) == 2 and not set(out["ids"][0]) & set(out["ids"][1])
    # timeouts before the goal: interrupted, the last decision's time penalty (5 x 0.002)
    assert all(r == [pytest.approx(-5 * TIME_PENALTY, abs=1e-6), True] for r in out["results"]["0"][:-1])
    # the goal: the scorer +1, the other team -1, both minus the k control steps' time penalty
    # of the decision period up to the goal (1 <= k <= 5), both not interrupted
    [(scored, i0)], [(conceded, i1)] = out["goal"]
    assert not i0 and not i1
    k = (1 - scored) / TIME_PENALTY
    assert abs(k - round(k)) < 1e-3 and 1 <= round(k) <= 5, scored
    assert conceded == pytest.approx(-1 - round(k) * TIME_PENALTY, abs=1e-6)
    assert out["exit"] == 0


# ------------------------------------------------------------------------------ soccer_twos (2 v 2)
def place_twos(task: SoccerTwosTask, area: int, players, ball) -> None:
    """Four players (area-relative x, y: team 0's two, then team 1's) and the ball, all at rest."""
    import mujoco

    q = task.qpos_rows[area]
    q[0:8] = np.asarray(players, dtype=np.float64).reshape(-1)
    q[8:10] = task.origin[area] + np.asarray(ball)
    task.qvel_rows[area] = 0.0
    mujoco.mj_forward(task.model, task.data)


def test_twos_model_has_four_players_per_pitch_with_the_documented_masses_and_sizes():
    task = make_task("soccer_twos", num_areas=2, seed=0)
    model = task.model
    assert task.num_agents == 8 and task.agents_per_area == 4 and task.players_per_team == 2
    assert model.nbody == 1 + 2 * (1 + 4 + 1)  # world; per area: walls, 4 players, ball
    assert model.nq == 2 * (4 * 2 + 7) and model.nu == 2 * 4 * 2
    for a in range(2):
        for i in range(4):
            body = model.body(f"player{a}_{i}")
            assert model.body_mass[body.id] == pytest.approx(PLAYER_MASS)
            geom = model.geom(int(model.body_geomadr[body.id]))
            np.testing.assert_allclose(geom.size[:2], [PLAYER_RADIUS, PLAYER_RADIUS / 2])
            joint = model.joint(f"px{a}_{i}")
            assert model.dof_damping[joint.dofadr[0]] == pytest.approx(6.0)
        ball = model.body(f"ball{a}")
        assert model.body_mass[ball.id] == pytest.approx(BALL_MASS)
        assert model.geom(int(model.body_geomadr[ball.id])).size[0] == pytest.approx(BALL_RADIUS)
    np.testing.assert_allclose(model.actuator_gear[:, 0], 12.0)
    # start spots: team 0 at x = -1 on lanes y = +0.55 / -0.55 (+- 0.15), team 1 mirrored
    xy = task.qpos_rows[:, 0:8].reshape(2, 4, 2)
    np.testing.assert_allclose(xy[:, :, 0], [[-1, -1, 1, 1]] * 2)
    assert (np.abs(xy[:, [0, 1], 1] - [0.55, -0.55]) <= 0.15).all()
    assert (np.abs(xy[:, [2, 3], 1] - [-0.55, 0.55]) <= 0.15).all()


def test_twos_behaviors_groups_and_specs():
    task = make_task("soccer_twos", num_areas=3, seed=0)
    assert [key for key, _ in task.behaviors()] == ["SoccerTwos?team=0", "SoccerTwos?team=1"]
    assert [rows.tolist() for _, rows in task.behaviors()] == [[0, 1, 4, 5, 8, 9], [2, 3, 6, 7, 10, 11]]
    # one group per team and pitch, distinct everywhere: 2 * area + team + 1
    assert task.group_ids().tolist() == [1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6]
    assert make_task("soccer", num_areas=2, seed=0).group_ids() is None
    assert task.observation_specs[0].shape == (16,) and task.observation_specs[0].name == "VectorSensor_size16"
    assert task.action_spec.discrete_branches == (3, 3) and task.observe()[0].shape == (12, 16)


def test_twos_each_player_sees_its_teammate_and_both_opponents_in_its_team_frame():
    task = make_task("soccer_twos", num_areas=2, seed=0)
    # area 0 symmetric (team 1 = team 0 turned by 180 degrees, ball in the centre)
    place_twos(task, 0, [(-0.8, 0.5), (-1.0, -0.4), (0.8, -0.5), (1.0, 0.4)], (0.0, 0.0))
    place_twos(task, 1, [(-0.8, 0.5), (-1.0, -0.4), (0.8, -0.5), (1.0, 0.4)], (0.32, 0.12))
    obs = task.observe()[0]
    np.testing.assert_allclose(obs[0], obs[2], atol=1e-6)  # player k of team 0 == player k of team 1
    np.testing.assert_allclose(obs[1], obs[3], atol=1e-6)
    # area 1, team 0's player 0 at (-0.8, 0.5), by hand: own (-0.8 / 1.6, 0.5 / 1.2), ball - own =
    # (1.12, -0.38) / 1.6, teammate - own = (-0.2, -0.9) / 1.6, opponents - own = (1.6, -1.0) and
    # (1.8, -0.1) / 1.6, ball (0.32 / 1.6, 0.12 / 1.2)
    expected = [-0.5, 0.5 / 1.2, 0, 0, 0.7, -0.38 / 1.6, 0, 0, -0.125, -0.5625, 1.0, -0.625, 1.125, -0.0625, 0.2, 0.1]
    np.testing.assert_allclose(obs[4], expected, atol=1e-5)
    # team 1's player 1 at (1.0, 0.4) sees itself at (-1.0, -0.4), its teammate (0.8, -0.5) at
    # (-0.8, 0.5) - (-1.0, -0.4) = (0.2, 0.9), the opponents (-0.8, 0.5) -> (0.8, -0.5) and
    # (-1.0, -0.4) -> (1.0, 0.4) relative (1.8, -0.1) and (2.0, 0.8), the ball at (-0.32, -0.12)
    np.testing.assert_allclose(obs[7, 8:], [0.125, 0.5625, 1.125, -0.0625, 1.25, 0.5, -0.2, -0.1], atol=1e-5)


def test_twos_a_goal_is_a_group_reward_less_the_time_used_and_ends_the_group_episode():
    task = make_task("soccer_twos", num_areas=2, seed=0)
    out = PITCH_HALF_LENGTH + BALL_RADIUS + 0.05
    spots = [(-0.8, 0.5), (-0.8, -0.5), (0.8, -0.5), (0.8, 0.5)]
    place_twos(task, 0, spots, (out, 0.0))  # in team 1's goal: team 0 scores
    place_twos(task, 1, spots, (-out, 0.0))  # in team 0's goal: team 1 scores
    task.episode_step[:] = [99, 0]  # area 0's goal comes in its 100th control step, area 1's in its 1st
    result = task.step(np.zeros((8, 0), np.float32), np.zeros((8, 2), np.int64))
    np.testing.assert_array_equal(result.rewards, np.zeros(8))  # no individual reward
    np.testing.assert_allclose(result.group_rewards, [1 - 99 / 250] * 2 + [-1, -1] + [-1, -1] + [1, 1], atol=1e-6)
    assert result.done.all() and not result.interrupted.any()
    assert [(k, v) for k, v, _ in result.stats] == [("SoccerTwos/Goal Scored", 1.0)] * 2
    task.reset(result.done)
    assert task.episode_step.tolist() == [0, 0]


def test_twos_no_goal_until_max_step_is_an_interrupted_draw_without_reward():
    task = make_task("soccer_twos", num_areas=1, seed=0)
    total = np.zeros(4)
    for t in range(task.max_step):
        result = task.step(np.zeros((4, 0), np.float32), np.zeros((4, 2), np.int64))
        total += result.rewards + result.group_rewards
        assert result.done.all() == (t == task.max_step - 1)
    assert result.interrupted.all() and result.stats == [("SoccerTwos/Goal Scored", 0.0, result.stats[0][2])]
    np.testing.assert_array_equal(total, np.zeros(4))


def test_twos_teams_are_symmetric_under_mirrored_play():
    """The same scripted policy for both teams from a mirrored start: the game stays the mirror
    image (every player's observation equals its counterpart's) and ends in a draw. Exactly while
    only the ground touches anything (2 decisions); once the players push the ball and one another,
    MuJoCo's contact solver is symmetric only to rounding, which grows slowly (measured: at most
    7e-4 in the first 25 decisions, 0.02 at the 50th)."""
    task = make_task("soccer_twos", num_areas=1, seed=0)
    place_twos(task, 0, [(-1.0, 0.6), (-1.0, -0.5), (1.0, -0.6), (1.0, 0.5)], (0.0, 0.0))
    for decision in range(task.max_step // 5):
        obs = task.observe()[0]
        tolerance = 1e-6 if decision < 2 else 2e-3 if decision < 25 else 0.05
        np.testing.assert_allclose(obs[0:2], obs[2:4], atol=tolerance)
        rel = obs[:, 4:6]
        actions = np.where(rel > 0.02, 1, np.where(rel < -0.02, 2, 0))
        for _ in range(5):
            result = task.step(np.zeros((4, 0), np.float32), actions)
    assert result.done.all() and result.interrupted.all()


def test_twos_play_match_counts_goals_per_pitch():
    """A scripted team (run at a point just behind the ball) against a team standing still scores
    at least 10 times as often as it concedes (an own goal happens: measured 55 : 1, 20 draws);
    both standing still: every episode a draw (400 decisions / 50 per episode = 8 per pitch)."""
    def chase(obs):
        rel = obs[:, 4:6] + np.array([-0.05, 0.0])
        return np.where(rel > 0.02, 1, np.where(rel < -0.02, 2, 0))

    still = lambda obs: np.zeros((len(obs), 2), np.int64)  # noqa: E731
    wins, losses, draws = play_match(make_task("soccer_twos", num_areas=4, seed=5), chase, still, 400)
    assert wins >= 20 and wins >= 10 * max(losses, 1), (wins, losses, draws)
    assert wins + losses + draws >= 4 * 8
    assert play_match(make_task("soccer_twos", num_areas=4, seed=5), still, still, 400) == (0, 0, 32)


def test_twos_the_academy_sends_group_ids_and_group_rewards_per_team():
    task = make_task("soccer_twos", num_areas=2, seed=0)
    academy = Academy(task, episode_counter=EpisodeIdCounter())
    batches = {key: b.protos() for key, b in academy.collect_batches()}
    assert [i.group_id for i in batches["SoccerTwos?team=0"]] == [1, 1, 3, 3]
    assert [i.group_id for i in batches["SoccerTwos?team=1"]] == [2, 2, 4, 4]
    place_twos(task, 1, [(-0.8, 0.5), (-0.8, -0.5), (0.8, -0.5), (0.8, 0.5)],
               (-(PITCH_HALF_LENGTH + BALL_RADIUS + 0.05), 0.0))  # team 1 scores on pitch 1, in step 1
    academy.advance()
    batches = {key: b.protos() for key, b in academy.collect_batches()}
    for key, group, value in (("SoccerTwos?team=0", 3, -1.0), ("SoccerTwos?team=1", 4, 1.0)):
        done = [i for i in batches[key] if i.done]
        assert [(i.group_id, i.reward, i.max_step_reached) for i in done] == [(group, 0.0, False)] * 2
        assert [i.group_reward for i in done] == pytest.approx([value] * 2)
        assert len(batches[key]) == 6  # 2 terminal infos, then all 4 players deciding


# likewise for soccer_twos
_TWOS_SCRIPT = r"""
keys = [f"SoccerTwos?team={t}" for t in (0, 1)]
out = {"behaviors": sorted(env.behavior_specs),
       "groups": [[int(g) for g in env.get_steps(k)[0].group_id] for k in keys]}
for _ in range(400):
    d0, _ = env.get_steps(keys[0])
    rel = d0.obs[0][:, 4:6] + np.array([-0.05, 0.0])  # chase a point just behind the ball
    a0 = np.where(rel > 0.02, 1, np.where(rel < -0.02, 2, 0)).astype(np.int32)
    env.set_actions(keys[0], ActionTuple(discrete=a0))
    n1 = len(env.get_steps(keys[1])[0])
    env.set_actions(keys[1], ActionTuple(discrete=np.zeros((n1, 2), np.int32)))
    env.step()
    ends = [env.get_steps(k)[1] for k in keys]
    if len(ends[0]) and not ends[0].interrupted.any():  # a goal (a timeout is interrupted)
        out["goal"] = [{"groups": [int(g) for g in e.group_id], "reward": [float(r) for r in e.reward],
                        "group_reward": [float(r) for r in e.group_reward],
                        "interrupted": [bool(i) for i in e.interrupted]} for e in ends]
        break
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_sees_the_twos_groups_and_their_goal_rewards():
    """soccer_twos through the real UnityEnvironment: group ids 2 area + team + 1 per team, and at
    the first goal (team 0 chases the ball, team 1 stands) both players of the pitch's two groups
    end, individual reward 0, group reward +1 - (k - 1) / 250 for the scorers and -1 for the others."""
    out = run_stub_session(["--task", "soccer_twos", "--num-areas", "2", "--seed", "0"], _TWOS_SCRIPT, timeout=180)
    assert out["behaviors"] == ["SoccerTwos?team=0", "SoccerTwos?team=1"]
    assert out["groups"] == [[1, 1, 3, 3], [2, 2, 4, 4]]
    team0, team1 = out["goal"]
    # every pitch with a goal ends both its groups: two players of team 0 (group 2 a + 1) and two of
    # team 1 (group 2 a + 2), no individual reward, one group reward per group
    for group in set(team0["groups"]):
        mine = [i for i, g in enumerate(team0["groups"]) if g == group]
        theirs = [i for i, g in enumerate(team1["groups"]) if g == group + 1]
        assert len(mine) == 2 and len(theirs) == 2
        r0 = {team0["group_reward"][i] for i in mine}
        r1 = {team1["group_reward"][i] for i in theirs}
        assert len(r0) == 1 and len(r1) == 1
        won, lost = max(r0 | r1), min(r0 | r1)
        assert lost == -1.0
        k = 1 + (1 - won) * 250  # the control step of the goal
        assert abs(k - round(k)) < 1e-3 and 1 <= round(k) <= 250, won
    assert len(team0["groups"]) == len(team1["groups"]) in (2, 4)
    assert set(team0["reward"] + team1["reward"]) == {0.0}
    assert not any(team0["interrupted"] + team1["interrupted"])
    assert out["exit"] == 0
