"""The ``dodge`` task (the dodge thesis, docs/stub-tasks.md): model, pose, rewards and outcomes
against hand-computed numbers."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from unity_stub_env.cli import main
from unity_stub_env.geometry import euler_to_quat
from unity_stub_env.tasks import TASKS, make_task
from unity_stub_env.tasks.dodge import (
    CROUCH_RATE,
    HIT_PENALTY,
    NECK_RATE,
    POSE_JOINTS,
    REGIONS,
    TORSO_RATE,
    XML_PATH,
    Throws,
    effort,
)

N = 14
NO_DISCRETE = np.zeros((N, 0))


def _task(seed: int = 0):
    return make_task("dodge", num_areas=1, seed=seed)


def _act(**columns) -> np.ndarray:
    """[14, 9] actions: zero except the named columns (crouch, torso_axis, torso_angle, ...)."""
    action = np.zeros((N, 9))
    slots = {"crouch": [0], "torso_axis": [1, 2, 3], "torso_angle": [4], "neck_axis": [5, 6, 7], "neck_angle": [8]}
    for name, value in columns.items():
        action[:, slots[name]] = value
    return action


def _throw_all(task, start, target, speed=7.0):
    task.launch(np.arange(N), Throws(np.tile(start, (N, 1)).astype(float), np.tile(target, (N, 1)).astype(float),
                                     np.full(N, float(speed))))


def test_mjcf_loads_with_masses_from_volumes_and_the_documented_limits():
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    body = lambda name: model.body(name).id  # noqa: E731
    # density 1000 kg/m3 times each body's geom volumes, by hand
    sphere = lambda r: 4.0 / 3.0 * math.pi * r**3  # noqa: E731
    capsule = lambda r, length: math.pi * r**2 * length + sphere(r)  # noqa: E731
    assert model.body_mass[body("head")] == pytest.approx(1000 * (sphere(0.1) + capsule(0.05, 0.07)))
    assert model.body_mass[body("thigh_r")] == pytest.approx(1000 * capsule(0.07, 0.39))
    assert model.body_mass[body("foot_l")] == pytest.approx(1000 * 0.1 * 0.26 * 0.07)
    assert model.body_mass[body("torso")] == pytest.approx(
        1000 * (capsule(0.11, 0.16) + capsule(0.12, 0.14) + capsule(0.055, 0.32)))
    assert model.body_subtreemass[body("pelvis")] == pytest.approx(79.03, abs=0.01)  # the docstring's 79.0 kg
    limits = {name: tuple(np.round(np.degrees(model.jnt_range[model.joint(name).id]), 6))
              for name in POSE_JOINTS[1:]}
    assert limits == {
        "hip_r": (-30, 120), "knee_r": (-150, 0), "ankle_r": (-50, 45),
        "hip_l": (-30, 120), "knee_l": (-150, 0), "ankle_l": (-50, 45),
        "waist_x": (-80, 30), "waist_y": (-35, 35), "waist_z": (-45, 45),
        "neck_x": (-50, 60), "neck_y": (-45, 45), "neck_z": (-80, 80),
    }
    # the crouch stops where the first coupled joint reaches its limit: the ankle at 45 degrees
    crouch_max = _task().crouch_max
    assert math.degrees(crouch_max) == pytest.approx(45.0)
    assert model.jnt_range[model.joint("root_z").id, 0] <= -0.86 * (1 - math.cos(crouch_max))


def test_spec_and_cli_list_show_17_observations_and_9_actions(capsys):
    task = _task()
    assert "dodge" in TASKS and task.behavior_name == "Dodge" and task.num_agents == 14
    assert task.observation_specs[0].shape == (17,) and task.action_spec.continuous_size == 9
    assert task.action_spec.discrete_branches == () and task.observe()[0].shape == (14, 17)
    assert make_task("dodge", num_areas=2, seed=0).num_agents == 28
    assert main(["--list"]) == 0
    line = [row for row in capsys.readouterr().out.splitlines() if row.startswith("dodge:")][0]
    assert "behavior 'Dodge'" in line and "14 agent(s) per area" in line
    assert "[17]" in line and "continuous=9" in line and "discrete_branches=[]" in line


def test_crouch_keeps_the_feet_fixed_and_the_observed_quaternions_are_mujocos():
    task = _task()
    model, data = task.model, task.data
    rng = np.random.default_rng(1)
    task.crouch[:] = np.linspace(0, task.crouch_max, N)
    task.euler[:] = rng.uniform(task.rot_low, task.rot_high, (N, 2, 3))
    data.qpos[task.pose_qpos] = task._pose_rows()
    mujoco.mj_forward(model, data)
    for side in ("r", "l"):
        feet = [model.body(f"a{i}/foot_{side}").id for i in range(N)]
        assert np.allclose(data.xpos[feet] - task.base, [0.1 if side == "r" else -0.1, 0.0, 0.08], atol=1e-12)
        assert np.allclose(data.xquat[feet], [1, 0, 0, 0], atol=1e-12)
    pelvis_z = data.xpos[task.pelvis_body, 2]
    assert np.allclose(pelvis_z, 0.94 - 0.86 * (1 - np.cos(task.crouch)))
    obs = task.observe()[0]
    torso = [model.body(f"a{i}/torso").id for i in range(N)]
    head = [model.body(f"a{i}/head").id for i in range(N)]
    for i in range(N):
        relative = np.zeros(4)
        inverse = np.zeros(4)
        mujoco.mju_negQuat(inverse, data.xquat[torso[i]])
        mujoco.mju_mulQuat(relative, inverse, data.xquat[head[i]])
        assert abs(np.dot(obs[i, 1:5], data.xquat[torso[i]])) == pytest.approx(1.0, abs=1e-6)
        assert abs(np.dot(obs[i, 5:9], relative)) == pytest.approx(1.0, abs=1e-6)
    assert np.allclose(obs[:, 0], task.crouch)
    # the crouch action saturates at the limit: 16 steps of 3 degrees stop at 45
    task = _task()
    for _ in range(16):
        task.step(_act(crouch=1.0), NO_DISCRETE)
    assert np.allclose(task.observe()[0][:, 0], math.radians(45.0))


def test_start_observation_and_zero_action_reward_by_hand():
    task = _task()
    model, data = task.model, task.data
    obs = task.observe()[0]
    assert np.allclose(obs[:, 0], 0) and np.allclose(obs[:, 1:9], [1, 0, 0, 0, 1, 0, 0, 0])
    # the CoM from the body masses and their centres (xipos), independently of subtree_com
    bodies = [model.body(f"a0/{name}").id for name in ("pelvis", "thigh_r", "shank_r", "foot_r", "thigh_l",
                                                        "shank_l", "foot_l", "torso", "upper_arm_r", "forearm_r",
                                                        "upper_arm_l", "forearm_l", "head")]
    masses = model.body_mass[bodies]
    com = (masses[:, None] * data.xipos[bodies]).sum(0) / masses.sum() - task.base[0]
    # the support polygon is the hull of the soles: x in [-0.15, 0.15], y in [-0.07, 0.19]
    assert np.allclose(task.support_centroid, [0.0, 0.06])
    assert np.allclose(obs[0, 9:11], com[:2] - [0.0, 0.06], atol=1e-6)
    # sphere relative to the pelvis (hips at 0.94 m) and its velocity
    assert np.allclose(obs[:, 11:14], data.qpos[task.ball_pos_qpos] - (task.base + [0, 0, 0.94]), atol=1e-5)
    assert np.allclose(obs[:, 14:17], data.qvel[task.ball_lin_dof], atol=1e-5)
    result = task.step(np.zeros((N, 9)), NO_DISCRETE)
    # not crouched, torso and neck still: only the balance term, the distance in centimetres
    distance_cm = 100 * np.linalg.norm(com[:2] - [0.0, 0.06])
    assert np.allclose(result.rewards[~result.done], -math.exp(distance_cm / 100) / 100, atol=1e-7)


def test_effort_terms_by_hand():
    assert effort(0.0) == pytest.approx(0.01) and effort(100.0) == pytest.approx(math.e / 100)
    balance = effort(100 * np.linalg.norm(_task().com[0] - [0.0, 0.06]))
    cases = [
        # crouch one step: alpha = 3 deg, term with 3 * alpha = 9 (the CoM barely moves: checked below)
        (_act(crouch=1.0), effort(3 * math.degrees(CROUCH_RATE))),
        # torso about its forward axis (lateral bend, no CoM shift along y) by 4 deg
        (_act(torso_axis=[0, 1, 0], torso_angle=1.0), effort(math.degrees(TORSO_RATE))),
        # neck twist by 6 deg: half the angle
        (_act(neck_axis=[0, 0, 1], neck_angle=1.0), effort(0.5 * math.degrees(NECK_RATE))),
        # inside the dead zone nothing moves and nothing costs
        (_act(crouch=0.04, torso_axis=[1, 0, 0], torso_angle=0.05, neck_axis=[0, 0, 1], neck_angle=-0.05), 0.0),
        # crouching "up" from the start pose is clipped at 0: no crouch cost
        (_act(crouch=-1.0), 0.0),
    ]
    for action, expected in cases:
        task = _task()
        result = task.step(action, NO_DISCRETE)
        com_term = effort(100 * np.linalg.norm(task.com - task.support_centroid, axis=1))
        assert np.allclose(com_term, balance, atol=5e-5)  # one small step leaves the CoM term ~unchanged
        assert np.allclose(task.last_effort, expected + com_term, atol=1e-12)
        assert np.allclose(result.rewards[~result.done], -(expected + com_term)[~result.done], atol=1e-6)
    # the torso term uses the accumulated torso-pelvis angle: 5 steps of 4 degrees -> 20 degrees
    task = _task()
    for _ in range(5):
        task.step(_act(torso_axis=[0, 1, 0], torso_angle=1.0), NO_DISCRETE)
    com_term = effort(100 * np.linalg.norm(task.com - task.support_centroid, axis=1))
    assert np.allclose(task.last_effort, effort(20.0) + com_term, atol=1e-9)
    # at the limit (lateral bend 35 deg) further pushing moves nothing and costs nothing
    for _ in range(10):
        task.step(_act(torso_axis=[0, 1, 0], torso_angle=1.0), NO_DISCRETE)
    assert np.allclose(np.degrees(task.euler[:, 0, 1]), 35.0)
    com_term = effort(100 * np.linalg.norm(task.com - task.support_centroid, axis=1))
    assert np.allclose(task.last_effort, com_term)
    # the crouch term is paid every step while crouched, even without moving: 3 * 6 deg
    task = _task()
    task.step(_act(crouch=1.0), NO_DISCRETE)
    task.step(_act(crouch=1.0), NO_DISCRETE)
    task.step(np.zeros((N, 9)), NO_DISCRETE)
    com_term = effort(100 * np.linalg.norm(task.com - task.support_centroid, axis=1))
    assert np.allclose(task.last_effort, effort(18.0) + com_term)


def test_a_sphere_at_the_head_is_a_head_hit_and_a_wide_one_passes():
    task = _task()
    _throw_all(task, start=[0.0, 5.0, 1.5], target=[0.0, 0.01, 1.64])  # from the front, at the head
    for step in range(60):
        result = task.step(np.zeros((N, 9)), NO_DISCRETE)
        if result.done.any():
            break
    assert result.done.all() and not result.interrupted.any()
    assert (task.last_hit_region == REGIONS.index("head")).all()
    # 5 m at 7 m/s = 0.714 s; first contact 0.2 m earlier (two radii of 0.1): step 35 of 0.02 s
    assert step + 1 == 35
    assert np.allclose(result.rewards, HIT_PENALTY[0] - task.last_effort)
    assert HIT_PENALTY[0] == -5.0 and HIT_PENALTY[REGIONS.index("legs")] == -2.0

    task = _task()
    _throw_all(task, start=[5.0, 0.0, 1.5], target=[0.0, 1.0, 1.2])  # from the right, 1 m in front
    for step in range(80):
        result = task.step(np.zeros((N, 9)), NO_DISCRETE)
        if result.done.any():
            break
    assert result.done.all() and task.last_passed.all() and (task.last_hit_region == -1).all()
    assert np.allclose(result.rewards, 5.0 - task.last_effort)
    # called 0.8 m past the closest approach to the axis: 25 / sqrt(26) + 0.8 = 5.70 m at 7 m/s
    # (horizontal) = 0.815 s, in step 41
    assert step + 1 == 41


def test_hit_regions_are_graded_and_a_crouch_dodges_the_head_throw():
    # from the front (the pelvis throw rises to its apex at the target, so it arrives level)
    expected = {"torso": ([0.0, 5.0, 1.36], [0.0, 0.0, 1.36], 7.0), "pelvis": ([0.0, 5.0, 0.3], [0.0, 0.0, 0.93], 14.0),
                "legs": ([0.0, 5.0, 0.3], [-0.1, 0.0, 0.3], 7.0), "arms": ([5.0, 0.0, 1.5], [0.0, 0.0, 1.16], 7.0)}
    for region, (start, target, speed) in expected.items():
        task = _task()
        _throw_all(task, start=start, target=target, speed=speed)
        for _ in range(60):
            result = task.step(np.zeros((N, 9)), NO_DISCRETE)
            if result.done.any():
                break
        assert (task.last_hit_region == REGIONS.index(region)).all(), region
        assert np.allclose(result.rewards, HIT_PENALTY[REGIONS.index(region)] - task.last_effort)
    assert list(HIT_PENALTY[:3]) == [-5.0, -4.0, -3.0]  # head > torso > pelvis > limbs
    # a level throw at the head (apex at the head: start 0.625 m lower, 14 m/s, 0.36 s): it hits the
    # head of a character that stands still and passes over one that crouches at once (45 degrees
    # after 15 steps drop the head by 0.86 (1 - cos 45) = 0.25 m > the two radii, 0.2 m)
    for crouch, region, passed in ((0.0, REGIONS.index("head"), False), (1.0, -1, True)):
        task = _task()
        _throw_all(task, start=[0.0, 5.0, 1.64 - 0.625], target=[0.0, 0.01, 1.64], speed=14.0)
        for _ in range(60):
            result = task.step(_act(crouch=crouch), NO_DISCRETE)
            if result.done.any():
                break
        assert result.done.all() and (task.last_hit_region == region).all() and (task.last_passed == passed).all()


def test_balance_loss_ends_the_episode_with_minus_5():
    task = _task()
    # within the human limits the CoM cannot leave the soles (module docstring), so this test
    # moves the polygon's front edge to 0.05 m: a deep forward flexion then leaves it
    front = np.argmax(task.support_normals[:, 1])
    task.support_offsets[front] = 0.05 * task.support_normals[front, 1]
    _throw_all(task, start=[0.0, 5.0, 1.5], target=[0.0, 1.5, 1.5])  # a throw that cannot hit
    lost_at = None
    for step in range(40):
        result = task.step(_act(torso_axis=[1, 0, 0], torso_angle=-1.0), NO_DISCRETE)  # flex forward 4 deg/step
        if result.done.any():
            lost_at = step
            break
    assert lost_at is not None and task.last_balance_lost.all() and not task.last_passed.any()
    assert (task.com[:, 1] > 0.05).all()
    assert np.allclose(result.rewards, -5.0 - task.last_effort)


def test_reset_returns_to_the_start_pose_with_a_new_throw_and_is_deterministic():
    task = _task(seed=3)
    first = task.observe()[0].copy()
    for _ in range(5):
        task.step(np.random.default_rng(0).uniform(-1, 1, (N, 9)), NO_DISCRETE)
    mask = np.zeros(N, dtype=bool)
    mask[[2, 5]] = True
    before = task.observe()[0].copy()
    task.reset(mask)
    after = task.observe()[0]
    assert np.allclose(after[mask, :9], [0, 1, 0, 0, 0, 1, 0, 0, 0])
    assert not np.allclose(after[mask, 11:], first[mask, 11:])  # a new throw
    assert np.array_equal(after[~mask], before[~mask])
    assert np.array_equal(_task(seed=3).observe()[0], first) and not np.array_equal(_task(seed=4).observe()[0], first)
    # every throw starts 4-6 m from the character's axis, in front or to the side, and aims at it
    throws = task.draw_throws(2000)
    distance = np.linalg.norm(throws.start[:, :2], axis=1)
    assert distance.min() >= 4.0 and distance.max() <= 6.0
    assert (np.degrees(np.abs(np.arctan2(throws.start[:, 0], throws.start[:, 1]))) <= 120.0).all()
    assert (np.abs(throws.target[:, 0]) <= 0.3).all() and (throws.target[:, 2] <= 1.74).all()


def test_each_sphere_only_touches_its_own_character():
    task = make_task("dodge", num_areas=2, seed=0)
    model = task.model
    bits = model.geom_conaffinity[task.geom_agent == 0]
    assert (bits == 2).all() and (model.geom_contype[task.is_character_geom] == 0).all()
    # agent k's sphere can touch agent k's geoms and the floor, no other agent's
    for k in (0, 5, 13, 14, 27):
        ball = model.geom_contype[task.ball_geom[k]]
        touches = (ball & model.geom_conaffinity) != 0
        owners = set(task.geom_agent[touches].tolist())
        assert owners == {-1, k % 14, k % 14 + 14}, owners  # the floor and agent k of each area
    # the same bit repeats in the next area, 25 m away: farther than a sphere ever gets (7 m)
    assert np.linalg.norm(task.base[14] - task.base[0]) == 25.0
