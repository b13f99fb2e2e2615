"""The cooperative stub task ``dungeon``: its room and bodies as documented, scripted episodes with
hand-computed returns, the eaten agent's early end on the wire (in-process and as the REAL
mlagents_envs 1.1.0 receives it)."""
from __future__ import annotations

import os

import mujoco
import numpy as np
import pytest

from protos.communicator_objects import agent_action_pb2
from tests.stub.conftest import INTEROP_PYTHON, run_stub_session
from unity_stub_env.academy import Academy
from unity_stub_env.cli import main
from unity_stub_env.tasks import make_task
from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.dungeon import AREA_SPACING, MAX_STEP, OBS_SIZE, START_Y, build_model


def toward(vec: np.ndarray) -> int:
    """The discrete action along the larger component of ``vec`` (1 +y, 2 -y, 3 +x, 4 -x)."""
    if abs(vec[0]) > abs(vec[1]):
        return 3 if vec[0] > 0 else 4
    return 1 if vec[1] > 0 else 2


def sacrifice(obs: np.ndarray) -> np.ndarray:
    """The scripted group, from the observations alone (three rows per area): while the dragon is
    there the agent nearest to it walks into it; then the agent nearest to the key fetches it; the
    carrier walks to the door. Everyone else stands still. int32 [n, 1]."""
    actions = np.zeros(len(obs), dtype=np.int32)
    for first in range(0, len(obs), 3):
        rows = obs[first:first + 3]
        if rows[0, 6]:
            i = int(np.argmin(np.linalg.norm(rows[:, 4:6], axis=1)))
            actions[first + i] = toward(rows[i, 4:6])
        elif rows[:, 12].any():
            i = int(np.argmax(rows[:, 12]))
            actions[first + i] = toward(rows[i, 10:12])
        elif rows[0, 9]:
            i = int(np.argmin(np.linalg.norm(rows[:, 7:9], axis=1)))
            actions[first + i] = toward(rows[i, 7:9])
    return actions.reshape(-1, 1)


def params(**values: float) -> EnvironmentParameters:
    env_params = EnvironmentParameters()
    for key, value in values.items():
        env_params.set(key, lambda value=value: value)
    return env_params


def play_areas(policy, num_areas: int, seed: int = 0, **values: float):
    """Every area plays one group episode with ``policy(obs)``: per area (steps, group return of
    agent 0's row summed over the episode, escaped); the areas that finish are not restarted."""
    task = make_task("dungeon", num_areas=num_areas, seed=seed, env_params=params(**values))
    steps = np.zeros(num_areas, dtype=np.int64)
    returns = np.zeros(num_areas)
    escaped = np.zeros(num_areas, dtype=bool)
    running = np.ones(num_areas, dtype=bool)
    for step in range(1, MAX_STEP + 1):
        result = task.step(None, policy(task.observe()[0]))
        group_reward = result.group_rewards.reshape(num_areas, 3)
        assert (group_reward == group_reward[:, :1]).all()  # one group reward per area
        returns[running] += group_reward[running, 0]
        ended = running & result.done.reshape(num_areas, 3).all(axis=1)
        steps[ended] = step
        escaped[ended] = ~result.interrupted.reshape(num_areas, 3)[ended, 0]
        running &= ~ended
        task.reset(result.done & np.repeat(running, 3))  # the eaten agents start over; finished areas stay
        if not running.any():
            break
    assert not running.any()
    return steps, returns, escaped


def test_the_stub_lists_it(capsys):
    assert main(["--list"]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("dungeon:"))
    assert "behavior 'Dungeon', 3 agent(s) per area" in line and "VectorSensor_size18 [18]" in line
    assert "discrete_branches=[5]" in line and "max_step=100" in line


def test_room_and_bodies_are_as_documented():
    model = build_model(2)
    agent = model.body("area1/agent2")
    assert agent.mass[0] == pytest.approx(1.0)
    assert model.geom("area0/agent0").size[0] == pytest.approx(0.15)
    assert model.geom("area0/dragon").size[0] == pytest.approx(0.25)
    assert model.geom("area0/key").size[0] == pytest.approx(0.1)
    for k in range(2):
        for i in range(3):
            for axis in "xy":
                joint = model.joint(f"area{k}/agent{i}_{axis}")
                assert joint.range.tolist() == pytest.approx([-0.85, 0.85]) and model.jnt_limited[joint.id]
                assert model.dof_damping[joint.dofadr[0]] == pytest.approx(5.0)
                assert model.actuator(f"area{k}/agent{i}_{axis}").gear[0] == pytest.approx(10.0)
    assert model.nmocap == 6 and model.nu == 12 and model.nq == 12
    # only the agents collide
    solid = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(model.ngeom) if model.geom_contype[g]}
    assert solid == {f"area{k}/agent{i}" for k in range(2) for i in range(3)}
    task = make_task("dungeon", num_areas=2, seed=0)
    np.testing.assert_array_equal(task.group_ids(), [1, 1, 1, 2, 2, 2])
    assert task.observe()[0].shape == (6, OBS_SIZE)
    # the second area is AREA_SPACING further along y in the world, the same in its own frame
    assert task.data.xpos[model.body("area1/agent0").id][1] - task.data.xpos[model.body("area0/agent0").id][1] == \
        pytest.approx(AREA_SPACING + task.start[1, 0, 1] - task.start[0, 0, 1])
    np.testing.assert_allclose(task.observe()[0][:, 1], START_Y)


def test_an_agent_pushing_reaches_2_m_s_and_stops_at_the_wall():
    """10 N against 5 N s/m: 2 m/s at full speed. MuJoCo's Euler step integrates the damping
    implicitly: v <- (v + 0.02 * 10) / (1 + 0.02 * 5), so after the 25 steps of 0.5 s
    v = 2 (1 - 1.1^-25) = 1.8154; pushing on, the agent stops at the far wall (limit 0.85 m)."""
    task = make_task("dungeon", num_areas=1, seed=0)
    push_y = np.array([[1], [0], [0]], dtype=np.int32)  # agent 0 towards the far wall, nobody in its way
    for _ in range(5):
        task.step(None, push_y)
    assert task.qvel[0, 0, 1] == pytest.approx(2 * (1 - 1.1 ** -25), abs=2e-3)
    for _ in range(15):
        task.step(None, push_y)
    assert task.qpos[0, 0, 1] == pytest.approx(0.85, abs=0.01) and abs(task.qvel[0, 0, 1]) < 0.05


def test_the_scripted_sacrifice_escapes_and_a_still_group_times_out():
    penalty = -0.01
    steps, returns, escaped = play_areas(sacrifice, num_areas=20, seed=0, time_penalty=penalty)
    assert escaped.all() and (steps.min(), steps.max()) == (12, 18), steps  # measured, seed 0
    np.testing.assert_allclose(returns, 1.0 + penalty * steps, atol=1e-5)  # +1 at the door, a penalty a step
    steps, returns, escaped = play_areas(lambda obs: np.zeros((len(obs), 1), np.int32), num_areas=3, seed=0,
                                         time_penalty=penalty)
    assert not escaped.any() and (steps == MAX_STEP).all()
    np.testing.assert_allclose(returns, MAX_STEP * penalty, atol=1e-5)
    _, returns, escaped = play_areas(lambda obs: np.zeros((len(obs), 1), np.int32), num_areas=3, seed=0)
    assert not escaped.any() and (returns == 0.0).all()  # the default: no time penalty


def test_random_actions_rarely_escape():
    """Uniform random actions: the dragon eats someone in almost every episode, the key reaches the
    door in about one in five (measured 0.21 on these 300 areas, seed 0)."""
    rng = np.random.default_rng(0)
    _, _, escaped = play_areas(lambda obs: rng.integers(0, 5, (len(obs), 1)).astype(np.int32), num_areas=300)
    assert 0.08 < escaped.mean() < 0.3, escaped.mean()


def test_the_eaten_agent_ends_alone_on_the_wire_and_the_group_goes_on():
    """In-process Academy: the eaten agent's terminal info (done, not max_step, no reward, its group
    id) and then a new episode id in the same group; the +1 at the door reaches the three agents
    then in the episode, not the eaten one's finished episode."""
    academy = Academy(make_task("dungeon", num_areas=1, seed=0))
    infos = academy.collect_infos()
    assert [info.group_id for info in infos] == [1, 1, 1] and [info.id for info in infos] == [0, 1, 2]
    eaten = None
    for _ in range(MAX_STEP):
        obs = np.array([info.observations[0].float_data.data for info in infos if not info.done], dtype=np.float32)
        academy.apply_actions([_action(int(a)) for a in sacrifice(obs)[:, 0]])
        academy.advance()
        infos = academy.collect_infos()
        done = [info for info in infos if info.done]
        if done and eaten is None:
            assert len(done) == 1 and len(infos) == 4  # the terminal info, then three decision requests
            eaten = done[0]
            assert (eaten.max_step_reached, eaten.reward, eaten.group_reward, eaten.group_id) == (False, 0.0, 0.0, 1)
            assert eaten.id in (0, 1, 2) and sorted(info.id for info in infos[1:]) == sorted({0, 1, 2, 3} - {eaten.id})
            assert infos[0].observations[0].float_data.data[6] == 0.0  # the dragon is gone
            assert infos[0].observations[0].float_data.data[9] == 1.0  # the key lies on the floor
        elif done:
            assert sorted(info.id for info in done) == sorted({0, 1, 2, 3} - {eaten.id})
            assert all(not info.max_step_reached and info.group_id == 1 for info in done)
            assert [info.group_reward for info in done] == [1.0, 1.0, 1.0]
            assert ("Dungeon/Success", 1.0) in [stat[:2] for stat in academy.take_stats()]
            return
    raise AssertionError("the scripted group did not escape")


def _action(choice: int) -> agent_action_pb2.AgentActionProto:
    return agent_action_pb2.AgentActionProto(discrete_actions=[choice])


# what runs in the real UnityEnvironment session of run_stub_session (conftest): env is reset; fill out
_SCRIPT = r"""
name = "Dungeon?team=0"
spec = env.behavior_specs[name]
out = {"behaviors": list(env.behavior_specs), "branches": list(spec.action_spec.discrete_branches),
       "obs": [list(o.shape) for o in spec.observation_specs], "terminals": []}
decision, _ = env.get_steps(name)
out["group_ids"] = [int(g) for g in decision.group_id]

def toward(v):
    if abs(v[0]) > abs(v[1]):
        return 3 if v[0] > 0 else 4
    return 1 if v[1] > 0 else 2

for _ in range(100):  # the scripted sacrifice, from the observations (agent ids in order)
    obs = decision.obs[0][np.argsort(decision.agent_id)]
    order = np.sort(decision.agent_id)
    acts = np.zeros(3, np.int32)
    if obs[0, 6]:
        i = int(np.argmin(np.linalg.norm(obs[:, 4:6], axis=1))); acts[i] = toward(obs[i, 4:6])
    elif obs[:, 12].any():
        i = int(np.argmax(obs[:, 12])); acts[i] = toward(obs[i, 10:12])
    elif obs[0, 9]:
        i = int(np.argmin(np.linalg.norm(obs[:, 7:9], axis=1))); acts[i] = toward(obs[i, 7:9])
    by_id = dict(zip(order.tolist(), acts.tolist()))
    env.set_actions(name, ActionTuple(discrete=np.array([[by_id[a]] for a in decision.agent_id], np.int32)))
    env.step()
    decision, terminal = env.get_steps(name)
    if len(terminal):
        out["terminals"].append({"ids": [int(a) for a in terminal.agent_id], "groups": [int(g) for g in terminal.group_id],
                                 "reward": [float(r) for r in terminal.reward],
                                 "group_reward": [float(r) for r in terminal.group_reward],
                                 "interrupted": [bool(i) for i in terminal.interrupted],
                                 "deciding": sorted(int(a) for a in decision.agent_id)})
        if len(out["terminals"]) == 2:
            break
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_sees_the_eaten_agent_leave_and_the_group_escape():
    out = run_stub_session(["--task", "dungeon", "--num-areas", "1"], _SCRIPT)
    assert out["behaviors"] == ["Dungeon?team=0"] and out["branches"] == [5] and out["obs"] == [[OBS_SIZE]]
    assert out["group_ids"] == [1, 1, 1]
    eaten, escape = out["terminals"]
    # the eaten agent ends alone (done, not interrupted, nothing paid) while its two teammates and
    # its own next episode (id 3) request decisions in the same group
    assert len(eaten["ids"]) == 1 and eaten["groups"] == [1] and eaten["interrupted"] == [False]
    assert eaten["reward"] == [0.0] and eaten["group_reward"] == [0.0]
    assert eaten["deciding"] == sorted({0, 1, 2, 3} - set(eaten["ids"]))
    # the escape: the three agents then in the episode end together with the group reward +1
    assert sorted(escape["ids"]) == eaten["deciding"] and escape["groups"] == [1, 1, 1]
    assert escape["group_reward"] == [1.0, 1.0, 1.0] and escape["interrupted"] == [False] * 3
    assert out["exit"] == 0
