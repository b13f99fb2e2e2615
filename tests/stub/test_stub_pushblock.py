"""The cooperative stub task ``pushblock``: its physics and rewards by numbers, and its group ids and
group rewards as the REAL mlagents_envs 1.1.0 (its own venv and process) receives them."""
from __future__ import annotations

import os

import numpy as np
import pytest

from tests.stub.conftest import INTEROP_PYTHON, run_stub_session
from unity_stub_env.tasks import make_task
from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.pushblock import GOAL_Y, LEAVE_REWARD, MAX_STEP, TIME_PENALTY


def play(actions: list[int], steps: int = 200, seed: int = 1, **params: float):
    """Both agents of one area repeat ``actions``: (steps to the end, group return, result, block y).
    ``params``: environment parameters, set before the first episode starts."""
    env_params = EnvironmentParameters()
    for key, value in params.items():
        env_params.set(key, lambda value=value: value)
    task = make_task("pushblock", num_areas=1, seed=seed, env_params=env_params)
    total = 0.0
    for step in range(1, steps + 1):
        result = task.step(None, np.array(actions, np.int32).reshape(2, 1))
        total += float(result.group_rewards[0])
        if result.done.any():
            return step, total, result, float(task.qpos[0, 1])
    raise AssertionError("no episode end")


def test_two_agents_push_the_block_home_one_alone_cannot_in_time():
    steps, total, result, block_y = play([1, 1])
    assert steps == 22 and result.done.all() and not result.interrupted.any() and block_y >= GOAL_Y
    # progress 1.2 m / 1.2 + success 1 + 22 hurry penalties (group reward, the same for both agents)
    assert total == pytest.approx(block_y / GOAL_Y + 1.0 + 22 * TIME_PENALTY, abs=1e-5)
    assert ("PushBlock/Success", 1.0) == result.stats[0][:2]
    steps, total, result, block_y = play([1, 0])  # agent 0 alone: the block creeps
    assert steps == MAX_STEP and result.interrupted.all() and 0.5 < block_y < GOAL_Y
    steps, total, result, block_y = play([0, 0])
    assert steps == MAX_STEP and total == pytest.approx(-0.5, abs=1e-5) and block_y == 0.0


def test_block_friction_12_only_both_move_the_block_and_progress_reward_0_is_sparse():
    """block_friction 12 N, above one agent's 10 N: pushing alone for the whole timeout moves the
    block 0.08 m (MuJoCo's friction is soft: the impact and a slow creep; 0.79 m at the default
    9 N), return -0.43; both together arrive in 28 steps instead of 22 (measured).
    progress_reward 0: only the success reward and the time penalty remain."""
    steps, total, result, block_y = play([1, 0], block_friction=12.0)
    assert steps == MAX_STEP and result.interrupted.all() and 0.0 < block_y < 0.1
    assert total == pytest.approx(-0.5 + block_y / GOAL_Y, abs=1e-5)
    steps, total, result, block_y = play([1, 1], block_friction=12.0)
    assert steps == 28 and block_y >= GOAL_Y and not result.interrupted.any()
    assert total == pytest.approx(block_y / GOAL_Y + 1.0 + steps * TIME_PENALTY, abs=1e-5)
    steps, total, result, block_y = play([1, 1], progress_reward=0.0)
    assert steps == 22 and total == pytest.approx(1.0 + 22 * TIME_PENALTY, abs=1e-5)


def test_an_agent_that_leaves_the_floor_ends_alone_and_comes_back_to_its_group():
    task = make_task("pushblock", num_areas=2, seed=3)
    np.testing.assert_array_equal(task.group_ids(), [1, 1, 2, 2])
    start = task.observe()[0][0, :2].copy()
    for step in range(1, 40):
        result = task.step(None, np.array([[4], [0], [0], [0]], np.int32))  # agent 0 walks off to -x
        if result.done.any():
            break
    np.testing.assert_array_equal(result.done, [True, False, False, False])
    assert not result.interrupted.any() and result.rewards[0] == LEAVE_REWARD
    task.reset(result.done)
    np.testing.assert_allclose(task.observe()[0][0, :2], start)  # back at its start spot, same group


# what runs in the real UnityEnvironment session of run_stub_session (conftest): env is reset; fill out
_SCRIPT = r"""
out = {"behaviors": list(env.behavior_specs)}
name = "PushBlock?team=0"
spec = env.behavior_specs[name]
out["branches"] = list(spec.action_spec.discrete_branches)
decision, _ = env.get_steps(name)
out["group_ids"] = [int(g) for g in decision.group_id]
group_rewards, terminal_groups, ended = [], [], 0
for _ in range(30):  # both agents of both areas push towards the goal
    env.set_actions(name, ActionTuple(discrete=np.ones((4, 1), dtype=np.int32)))
    env.step()
    decision, terminal = env.get_steps(name)
    group_rewards.append([float(r) for r in decision.group_reward])
    if len(terminal):
        ended += len(terminal)
        terminal_groups += [int(g) for g in terminal.group_id]
        out["terminal_group_reward"] = [float(r) for r in terminal.group_reward]
        out["terminal_interrupted"] = [bool(i) for i in terminal.interrupted]
        break
out["group_rewards"] = group_rewards
out["terminal_groups"] = terminal_groups
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_sees_the_groups_and_their_rewards():
    out = run_stub_session(["--task", "pushblock", "--num-areas", "2"], _SCRIPT)
    assert out["behaviors"] == ["PushBlock?team=0"] and out["branches"] == [5]
    assert out["group_ids"] == [1, 1, 2, 2]
    # every step's group reward: the hurry penalty plus the block's progress / GOAL_Y (the same for
    # the two agents of an area), and the success bonus in the terminal step
    first = out["group_rewards"][0]
    assert first[0] == first[1] and first[2] == first[3] and all(r != 0 for r in first)
    moving = out["group_rewards"][10]
    assert moving[0] == pytest.approx(TIME_PENALTY + 0.069 / GOAL_Y, abs=0.01)  # 0.69 m/s for 0.1 s
    assert sorted(out["terminal_groups"]) == [1, 1, 2, 2] and out["terminal_interrupted"] == [False] * 4
    assert all(r > 1.0 for r in out["terminal_group_reward"])
    assert out["exit"] == 0
