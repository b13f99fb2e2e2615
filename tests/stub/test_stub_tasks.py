"""Task physics and rules with hand-computed numbers (no protocol)."""
from __future__ import annotations

import numpy as np
import pytest

from unity_stub_env.tasks import TASKS, EnvironmentParameters, make_task
from unity_stub_env.tasks.ball3d import TILT_RATE
from unity_stub_env.tasks.basic import OPTIMAL_RETURN


def _basic_run(task, actions):
    rewards, done = [], []
    for action in actions:
        result = task.step(np.zeros((1, 0)), np.array([[action]]))
        rewards.append(float(result.rewards[0]))
        done.append(bool(result.done[0]))
    return rewards, done


def test_registry_and_specs():
    assert sorted(TASKS) == ["ball3d", "basic", "creature", "dodge", "dungeon", "mimic", "pushblock", "runner", "soccer",
                            "soccer_twos"]
    basic, ball = make_task("basic", num_areas=3, seed=0), make_task("ball3d", num_areas=2, seed=0)
    assert (basic.behavior_name, basic.num_agents, basic.action_spec.discrete_branches) == ("Basic", 3, (3,))
    assert basic.observation_specs[0].shape == (20,)
    assert (ball.behavior_name, ball.num_agents, ball.action_spec.continuous_size) == ("3DBall", 24, 2)
    assert ball.observation_specs[0].shape == (8,) and ball.observe()[0].shape == (24, 8)
    with pytest.raises(KeyError, match="basic"):
        make_task("nope")


def test_basic_scripted_reward_sequence():
    task = make_task("basic", num_areas=1, seed=0)
    # 10 -> 11, 12, 11, 11, 12, 13, 14, 15, 16, 17 (large goal on the 10th step)
    rewards, done = _basic_run(task, [2, 2, 1, 0, 2, 2, 2, 2, 2, 2])
    assert np.allclose(rewards, [-0.01] * 9 + [0.99])
    assert done == [False] * 9 + [True]
    assert np.argmax(task.observe()[0][0]) == 17


def test_basic_optimal_and_small_goal_returns():
    assert OPTIMAL_RETURN == pytest.approx(0.93)
    task = make_task("basic", num_areas=1, seed=0)
    rewards, done = _basic_run(task, [2] * 7)
    assert sum(rewards) == pytest.approx(0.93) and done[-1]
    task.reset()
    rewards, done = _basic_run(task, [1] * 3)
    assert sum(rewards) == pytest.approx(-0.02 + 0.09) and done == [False, False, True]


def test_basic_max_step_interrupts_and_masks_walls():
    task = make_task("basic", num_areas=2, seed=0)
    for step in range(100):
        result = task.step(np.zeros((2, 0)), np.zeros((2, 1), dtype=int))
        assert result.done.all() == (step == 99)
    assert result.interrupted.all()
    task.position[:] = [0, 19]
    assert task.action_mask().tolist() == [[False, True, False], [False, False, True]]


def _p_controller(obs: np.ndarray) -> np.ndarray:
    """Tilt the plate so the ball rolls back to the centre; action = change of target tilt."""
    desired = np.column_stack([0.3 * obs[:, 3] + 0.3 * obs[:, 6], -0.3 * obs[:, 2] - 0.3 * obs[:, 5]])
    return np.clip((desired - obs[:, :2]) / TILT_RATE, -1, 1)


def test_ball3d_is_deterministic_for_a_seed():
    actions = np.random.default_rng(123).uniform(-1, 1, size=(150, 12, 2))
    runs = []
    for _ in range(2):
        task = make_task("ball3d", num_areas=1, seed=7)
        trace = [task.observe()[0].copy()]
        for action in actions:
            result = task.step(action, np.zeros((12, 0)))
            task.reset(result.done)
            trace.append(task.observe()[0].copy())
        runs.append(np.stack(trace))
    assert np.array_equal(runs[0], runs[1])
    other = make_task("ball3d", num_areas=1, seed=8).observe()[0]
    assert not np.array_equal(other, runs[0][0])


def test_ball3d_first_step_is_free_fall():
    task = make_task("ball3d", num_areas=1, seed=0)
    start = task.observe()[0]
    assert np.allclose(start[:, 4], 4.0) and np.allclose(start[:, 5:], 0.0)
    assert np.all(np.abs(start[:, 2:4]) <= 1.5) and np.all(np.abs(start[:, :2]) <= np.deg2rad(10))
    task.step(np.zeros((12, 2)), np.zeros((12, 0)))
    obs = task.observe()[0]
    # two semi-implicit Euler steps of 0.01 s: v = -g*0.02, drop = 0.01*(g*0.01) + 0.01*(g*0.02)
    assert np.allclose(obs[:, 7], -9.81 * 0.02, atol=1e-5)
    assert np.allclose(obs[:, 4], 4.0 - 0.01 * 9.81 * 0.03, atol=1e-5)
    assert np.allclose(obs[:, 2:4], start[:, 2:4], atol=1e-6)


def test_ball3d_ball_rolls_off_without_control_but_stays_with_a_p_controller():
    idle = make_task("ball3d", num_areas=1, seed=1)
    fell = np.zeros(12, dtype=bool)
    for _ in range(1000):
        result = idle.step(np.zeros((12, 2)), np.zeros((12, 0)))
        fell |= result.done & ~result.interrupted
        assert np.all(result.rewards[result.done] == -1.0)
    assert fell.sum() >= 6  # a random tilt of up to 10 degrees rolls most balls off in 20 s

    held = make_task("ball3d", num_areas=1, seed=1)
    for _ in range(500):
        result = held.step(_p_controller(held.observe()[0]), np.zeros((12, 0)))
        assert not result.done.any()
        assert np.all(result.rewards == np.float32(0.1))
    assert np.all(np.abs(held.observe()[0][:, 2:4]) < 1.0)


def test_ball3d_environment_parameters_are_read_at_episode_start():
    params = EnvironmentParameters()
    params.set("scale", lambda: 2.0)
    params.set("mass", lambda: 3.0)
    task = make_task("ball3d", num_areas=1, seed=2, env_params=params)
    assert np.allclose(task.model.geom_size[task.ball_geom, 0], 1.0)
    assert np.allclose(task.model.body_mass[task.ball_body], 3.0)
    assert np.allclose(task.model.body_inertia[task.ball_body], 0.4 * 3.0 * 1.0**2)
    for _ in range(250):
        task.step(_p_controller(task.observe()[0]), np.zeros((12, 0)))
    # resting on the plate: centre height = plate half-thickness 0.2 + radius 1.0
    assert np.allclose(task.observe()[0][:, 4], 1.2, atol=0.05)


@pytest.mark.parametrize("mass,scale", [(0.5, 1.0), (10.0, 1.0), (10.0, 3.0)])
def test_ball3d_stays_stable_across_the_3dball_parameter_ranges(mass, scale):
    params = EnvironmentParameters()
    params.set("mass", lambda: mass)
    params.set("scale", lambda: scale)
    task = make_task("ball3d", num_areas=1, seed=3, env_params=params)
    for _ in range(400):
        result = task.step(_p_controller(task.observe()[0]), np.zeros((12, 0)))
        assert not result.done.any()
    # nothing faster than the 4 m drop: v = sqrt(2 g h) with h <= 4 - plate - radius
    assert np.abs(task.observe()[0][:, 5:]).max() < np.sqrt(2 * 9.81 * 4.0)
