"""The ``soccer`` stub task: two behaviors (one per team) sharing one MuJoCo physics, mirrored
team frames, goals and timeouts by hand, the academy's per-behavior infos and actions, and the
real mlagents_envs 1.1.0 driving it."""
from __future__ import annotations

import os

import numpy as np
import pytest

from protos.communicator_objects import agent_action_pb2
from tests.stub.conftest import INTEROP_PYTHON, run_interop_script
from unity_stub_env.academy import Academy, ActionCountError
from unity_stub_env.agents import EpisodeIdCounter
from unity_stub_env.tasks import make_task
from unity_stub_env.tasks.soccer import BALL_RADIUS, PITCH_HALF_LENGTH, TIME_PENALTY, SoccerTask

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


_SCRIPT = r"""
import json, subprocess, sys
import numpy as np
from mlagents_envs.environment import UnityEnvironment
from mlagents_envs.base_env import ActionTuple

port, stub_python, repo = int(sys.argv[1]), sys.argv[2], sys.argv[3]
stub = subprocess.Popen([stub_python, "-m", "unity_stub_env.cli", "--task", "soccer", "--num-areas", "2",
                         "--seed", "0", "--mlagents-port", str(port)], cwd=repo)
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=30)
env.reset()
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
env.close()
out["exit"] = stub.wait(timeout=20)
print("RESULT " + json.dumps(out))
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_drives_both_teams():
    """A scripted team 0 (runs at the ball) against a team 1 standing still, through the real
    UnityEnvironment: two behaviors with team ids, identical specs, +1 / -1 at the first goal."""
    out = run_interop_script(_SCRIPT, timeout=180)
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
