"""The ``mimic`` task (the mimic thesis, docs/stub-tasks.md): model, reference motions, reward
terms, RSI, early termination, pushes and the action mapping, against hand-computed numbers."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from unity_stub_env.cli import main
from unity_stub_env.geometry import cross, quat_angle, quat_matrix, quat_mul
from unity_stub_env.tasks import TASKS, make_task
from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.mimic import (
    CONTROL_DT,
    OBSERVED,
    SCALES,
    XML_PATH,
    BalanceExpert,
    MimicTask,
    reward_terms,
    run_trials,
)
from unity_stub_env.tasks.mimic.motions import JOINTS, MOTIONS, RATE, _soles, load_motion

N = 8
NO_DISCRETE = np.zeros((N, 0))
ZERO = np.zeros((N, len(JOINTS)))


def _task(seed: int = 0, **params) -> MimicTask:
    env = EnvironmentParameters()
    for key, value in params.items():
        env.set(key, lambda value=value: value)
    return MimicTask(1, seed, env)


def test_mjcf_masses_are_the_human_fractions_and_limits_the_documented_ones():
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    mass = lambda name: model.body_mass[model.body(name).id]  # noqa: E731
    assert model.body_subtreemass[model.body("pelvis").id] == pytest.approx(70.0, abs=1e-3)
    fractions = {"head": 6.81, "upper_arm_r": 2.63, "forearm_l": 1.5, "hand_r": 0.585, "thigh_l": 14.47,
                 "shank_r": 4.57, "foot_l": 1.33}
    for body, percent in fractions.items():
        assert mass(body) == pytest.approx(0.7 * percent, abs=2e-3), body
    assert mass("pelvis") + mass("torso") == pytest.approx(0.7 * 43.02, abs=2e-3)  # the trunk
    degrees = {j: tuple(np.round(np.degrees(model.jnt_range[model.joint(j).id]), 6)) for j in JOINTS}
    assert degrees["waist_x"] == (-30, 80) and degrees["neck_z"] == (-80, 80)
    assert degrees["shoulder_x_l"] == (-60, 170) and degrees["shoulder_y_r"] == (-30, 160)
    assert degrees["elbow_r"] == (0, 150) and degrees["knee_l"] == (0, 150)
    assert degrees["hip_x_r"] == (-30, 120) and degrees["hip_y_l"] == (-30, 45)
    assert degrees["ankle_x_r"] == (-50, 40) and degrees["ankle_y_l"] == (-25, 25)
    # one position actuator per unlocked axis, in JOINTS order, its control range the joint's
    assert model.nu == len(JOINTS) == 26 and model.nv == 6 + 26
    for a, joint in enumerate(JOINTS):
        assert model.joint(model.actuator_trnid[a, 0]).name == joint
        np.testing.assert_allclose(model.actuator_ctrlrange[a], model.jnt_range[model.joint(joint).id])
    kp = {model.actuator(a).name: model.actuator_gainprm[a, 0] for a in range(model.nu)}
    assert kp["hip_x_r"] == kp["knee_l"] == kp["ankle_x_r"] == 1500 and kp["shoulder_x_r"] == 150
    assert kp["elbow_l"] == 80 and kp["neck_x"] == 100
    assert model.geom_friction[model.geom("foot_r").id, 0] == 2.0
    assert model.geom_friction[model.geom("shank_r").id, 0] == 1.0
    assert model.opt.timestep == 0.004


def test_reference_motions_load_at_50_hz_within_the_joint_limits_with_the_feet_on_the_floor():
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    data = mujoco.MjData(model)
    limits = np.array([model.jnt_range[model.joint(j).id] for j in JOINTS])
    durations = {}
    for name in MOTIONS:
        qpos = load_motion(name).qpos
        durations[name] = len(qpos) / RATE
        assert qpos.shape[1] == 7 + 26
        joints = qpos[:, 7:]
        assert (joints >= limits[:, 0] - 1e-6).all() and (joints <= limits[:, 1] + 1e-6).all(), name
        np.testing.assert_allclose(np.linalg.norm(qpos[:, 3:7], axis=1), 1.0, atol=1e-5)
        lowest = [_soles(model, data, row)[:, :, 2].min() for row in qpos]  # the soles' 16 corners
        np.testing.assert_allclose(lowest, 0.0, atol=1e-6, err_msg=name)
    assert durations == {"stand": 1.0, "arms": 4.0, "squat": 4.0, "walk": 1.1}
    assert not load_motion("stand").qpos[:, 7:].any()
    squat = load_motion("squat").qpos
    assert np.degrees(squat[:, 7 + JOINTS.index("knee_r")].max()) == pytest.approx(80.0, abs=0.1)
    with pytest.raises(ValueError, match="known motions"):
        load_motion("dance")


def test_reward_terms_and_quaternion_angles_against_hand_computed_values():
    terms = reward_terms(np.array([0.5]), np.array([2.0]), np.array([0.01]), np.array([0.005]),
                         np.array([0.25]), SCALES)
    # k = 2, 0.1, 10, 40, 2: exp(-1), exp(-0.2), exp(-0.1), exp(-0.2), exp(-0.5)
    np.testing.assert_allclose(terms[0], [0.367879, 0.818731, 0.904837, 0.818731, 0.606531], atol=1e-6)
    half = math.radians(45)
    about_x = np.array([math.cos(half), math.sin(half), 0.0, 0.0])  # 90 degrees about x
    assert quat_angle(about_x, np.array([1.0, 0, 0, 0])) == pytest.approx(math.pi / 2)
    assert quat_angle(about_x, -about_x) == pytest.approx(0.0, abs=1e-6)  # q and -q: one rotation


def test_quaternion_product_and_cross_product_match_mujoco_and_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(3, 13, 4)), rng.normal(size=(3, 13, 4))
    product = quat_mul(a, b)
    for index in np.ndindex(3, 13):
        expected = np.zeros(4)
        mujoco.mju_mulQuat(expected, a[index], b[index])
        np.testing.assert_allclose(product[index], expected, atol=1e-12)
    np.testing.assert_allclose(cross(a[..., :3], b[..., 1:]), np.cross(a[..., :3], b[..., 1:]), atol=1e-12)


def test_reward_is_the_weighted_sum_with_the_mimic_thesis_or_the_deepmimic_weights():
    for preset, motion, weights in ((0, 2, (0.65, 0.1, 0.1, 0.15, 0.0)), (0, 0, (0.7, 0.15, 0.15, 0, 0)),
                                    (0, 3, (0.56, 0.07, 0.07, 0.1, 0.2)), (1, 0, (0.65, 0.1, 0.1, 0.15, 0))):
        task = _task(motion=motion, reward_weights=preset, residual=1.0)
        np.testing.assert_allclose(task.weights, np.tile(weights, (N, 1)))
        result = task.step(ZERO, NO_DISCRETE)
        np.testing.assert_allclose(result.rewards, (task.last_terms * np.array(weights)).sum(axis=1), rtol=1e-5)
    overridden = _task(w_r=1.0, k_e=5.0)
    assert overridden.weights[0, 0] == 1.0 and overridden.scales[0, 3] == 5.0 and overridden.scales[0, 0] == 2.0


@pytest.mark.parametrize("motion", [0, 1, 2, 3])
def test_rsi_puts_the_ragdoll_at_the_reference_pose_and_velocity(motion):
    task = _task(seed=3, motion=motion)
    ref = task.ref
    assert len(set(task.frame.tolist())) > 1 or ref.frames[motion] == 1  # random frames
    rows = task.ref_rows()
    qpos = task.data.qpos[task.agent_qpos]
    np.testing.assert_allclose(qpos[:, 7:], ref.joints[rows], atol=1e-12)
    np.testing.assert_allclose(qpos[:, 3:7], ref.qpos[rows, 3:7], atol=1e-12)
    np.testing.assert_allclose(qpos[:, 2], ref.qpos[rows, 2], atol=1e-12)
    np.testing.assert_allclose(task.data.qvel[task.agent_dof], ref.qvel[rows], atol=1e-12)
    terms, drift = task.compare(rows)  # the pose, velocities, CoM and end effectors all match
    np.testing.assert_allclose(terms[:, :4], 1.0, atol=1e-9)
    assert (drift < 1e-9).all()
    obs = task.observe()[0]
    assert obs.shape == (N, 170) and obs.dtype == np.float32
    phase = obs[:, -1]
    expected = 0.0 if motion == 0 else task.frame / ref.frames[motion]
    np.testing.assert_allclose(phase, expected, atol=1e-6)
    assert ((phase >= 0) & (phase < 1)).all()
    np.testing.assert_allclose(obs[:, 12], ref.qpos[rows, 2], atol=1e-5)  # pelvis height slot
    no_rsi = _task(seed=3, motion=motion, rsi=0)
    assert (no_rsi.frame == 0).all()


def test_the_pd_controllers_alone_hold_the_reference_and_zero_actions_hold_the_neutral_pose():
    tracking = run_trials(lambda obs: np.zeros((len(obs), 26)), motion=2, trials=N, seed=0, residual=1.0)
    assert tracking["balance_kept"] == 1.0 and tracking["r_r"] > 0.9
    # absolute targets: zero actions aim every axis at 0 rad, the standing pose, which the PD holds;
    # the squat's reference moves away from it (measured r_r 0.29)
    neutral = run_trials(lambda obs: np.zeros((len(obs), 26)), motion=0, trials=N, seed=0)
    assert neutral["balance_kept"] == 1.0 and neutral["r_r"] > 0.99
    squat = run_trials(lambda obs: np.zeros((len(obs), 26)), motion=2, trials=N, seed=0)
    assert squat["balance_kept"] == 1.0 and squat["r_r"] < 0.5


def test_actions_map_onto_the_limits_or_around_the_reference():
    task = _task(motion=1, rsi=0)
    action = np.tile(np.linspace(-1, 1, 26), (N, 1))
    action[:, :3] = (-1.0, 0.0, 1.0)
    action[:, 3:6] = (-0.5, 0.5, 0.25)
    action[:, JOINTS.index("knee_r")] = -0.7
    task.step(action, NO_DISCRETE)
    ctrl = task.data.ctrl[task.actuator]
    np.testing.assert_allclose(ctrl[:, 0], math.radians(-30))  # waist_x low
    np.testing.assert_allclose(ctrl[:, 1], 0.0, atol=1e-12)  # waist_y: 0 -> the neutral 0 rad
    np.testing.assert_allclose(ctrl[:, 2], math.radians(45))  # waist_z high
    # piecewise linear about 0 rad: neck_x -60..50 at -0.5 -> -30 deg, neck_y -45..45 at 0.5 -> 22.5,
    # neck_z -80..80 at 0.25 -> 20; the knee 0..150 has no negative half: -0.7 -> 0 deg
    np.testing.assert_allclose(np.degrees(ctrl[:, 3:6]), np.tile([-30.0, 22.5, 20.0], (N, 1)))
    np.testing.assert_allclose(ctrl[:, JOINTS.index("knee_r")], 0.0, atol=1e-12)
    residual = _task(motion=1, rsi=0, residual=0.5)
    residual.step(np.zeros((N, 26)), NO_DISCRETE)
    np.testing.assert_allclose(residual.data.ctrl[residual.actuator], np.tile(residual.ref.joints[residual.ref.offset[1] + 1], (N, 1)))
    bent = np.zeros((N, 26))
    bent[:, JOINTS.index("elbow_r")] = 0.4
    residual.step(bent, NO_DISCRETE)  # elbow reference 10 deg + 0.4 * 0.5 * 150 / 2 = 10 + 15 deg
    assert np.degrees(residual.data.ctrl[residual.actuator[:, JOINTS.index("elbow_r")]]) == pytest.approx(25.0)


def test_early_termination_on_a_fall_and_on_drifting_away():
    task = _task(motion=0, rsi=0, residual=1.0)
    for _ in range(50):  # the PD holds the stand: no termination
        result = task.step(ZERO, NO_DISCRETE)
        assert not result.done.any()
    # lay agent 0 on its back on the floor: a non-foot contact
    adr = task.agent_qpos[0]
    task.data.qpos[adr[:3]] = task.base[0] + (0, 0, 0.1)
    task.data.qpos[adr[3:7]] = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0)
    # lift agent 1 by 0.8 m: no contact at all, but 0.8 m from the reference's CoM (> 0.5)
    task.data.qpos[task.agent_qpos[1][2]] += 0.8
    mujoco.mj_forward(task.model, task.data)
    result = task.step(ZERO, NO_DISCRETE)
    assert result.done[:2].all() and not result.interrupted[:2].any() and not result.done[2:].any()
    fell = [value for key, value, _ in result.stats if key == "Mimic/Fell"]
    assert fell == [1.0, 1.0]
    assert {key for key, _, _ in result.stats} == {"Mimic/r_r", "Mimic/r_v", "Mimic/r_m", "Mimic/r_e", "Mimic/Fell"}


def test_pushes_apply_the_impulse_at_their_interval():
    pushed = _task(seed=1, motion=0, rsi=0, residual=1.0, push_impulse=12.0, push_interval=0.1)
    still = _task(seed=1, motion=0, rsi=0, residual=1.0)
    total_mass = 70.0
    for step in range(1, 11):
        momentum = []
        for task in (pushed, still):
            task.step(ZERO, NO_DISCRETE)
            mujoco.mj_forward(task.model, task.data)
            mujoco.mj_subtreeVel(task.model, task.data)
            momentum.append(total_mass * task.data.subtree_linvel[task.pelvis].copy())
        if step in (5, 10):  # 0.1 s and 0.2 s into the episode
            impulse = pushed.last_push
            np.testing.assert_allclose(np.linalg.norm(impulse, axis=1), 12.0)
            assert (impulse[:, 2] == 0).all() and len({tuple(row) for row in impulse}) == N  # random directions
            if step == 5:  # the first push, on identical bodies: the momentum gained is the impulse
                gained = momentum[0] - momentum[1]
                np.testing.assert_allclose(gained[:, :2], impulse[:, :2], atol=0.15 * 12.0)
        else:
            assert not pushed.last_push.any()
    assert (pushed.data.xfrc_applied == 0).all()  # the force lasts one decision


def _balance_obs(velocity, yaw: float = 0.0) -> np.ndarray:
    """One observation: pelvis turned by yaw about z, feet 0.09 m either side 0.9 m below, every other
    part at the pelvis, every part moving at ``velocity`` (pelvis frame)."""
    obs = np.zeros((1, 170), np.float32)
    parts = obs[0, :169].reshape(13, 13)
    parts[:, 0] = 1.0  # identity local rotations
    parts[0, 0:4] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    parts[:, 4:7] = velocity
    parts[OBSERVED.index("foot_r"), 10:13] = (0.09, 0.0, -0.9)
    parts[OBSERVED.index("foot_l"), 10:13] = (-0.09, 0.0, -0.9)
    parts[0, 10:13] = (0.0, 0.0, 0.95)  # the pelvis' slot: its height
    return obs


def test_balance_expert_presses_the_soles_towards_the_capture_point_by_hand():
    np.testing.assert_allclose(quat_matrix(np.array([[math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)]])),
                               [[[0, -1, 0], [1, 0, 0], [0, 0, 1]]], atol=1e-12)  # 90 deg about z
    expert = BalanceExpert()
    ankle_x, ankle_y = JOINTS.index("ankle_x_r"), JOINTS.index("ankle_y_r")
    ankle_xl, ankle_yl = JOINTS.index("ankle_x_l"), JOINTS.index("ankle_y_l")
    omega = math.sqrt(9.81 / 0.93)  # 3.2478 /s
    # moving forward at 0.3 m/s over the feet' midpoint: xi_y = 0.3 / 3.2478 = 0.09237 m, both ankles
    # plantar-flex to -1.5 * 0.09237 = -0.13856 rad, action -0.13856 / 50 deg (0.87266 rad) = -0.15878;
    # the same whatever the heading (the velocity is in the pelvis frame)
    for yaw in (0.0, 1.2):
        xi = expert.capture_point(_balance_obs((0.0, 0.3, 0.0), yaw))
        np.testing.assert_allclose(xi, [[0.0, 0.3 / omega]], atol=1e-6)
        action = expert(_balance_obs((0.0, 0.3, 0.0), yaw))
        np.testing.assert_allclose(action[0, [ankle_x, ankle_xl]], -0.15878, atol=1e-4)
        assert np.abs(np.delete(action[0], [ankle_x, ankle_xl])).max() == 0.0
    # moving right at 0.2 m/s: xi_x = 0.06158 m; the right soles' edges go down: ankle_y_r to -0.09237 rad
    # (action -0.09237 / 25 deg (0.43633 rad) = -0.21170), ankle_y_l to +0.09237 (+0.21170)
    action = expert(_balance_obs((0.2, 0.0, 0.0)))
    np.testing.assert_allclose(action[0, [ankle_y, ankle_yl]], [-0.21170, 0.21170], atol=1e-4)
    # at rest, every part but the pelvis (9.94 kg) and the feet (0.931 kg each) 0.05 m forward:
    # the CoM is 0.05 * (70 - 9.94 - 1.862) / 70 = 0.041570 m ahead of the feet (the pelvis' slot is its height)
    obs = _balance_obs((0.0, 0.0, 0.0))
    parts = obs[0, :169].reshape(13, 13)
    others = [i for i, name in enumerate(OBSERVED) if name not in ("pelvis", "foot_r", "foot_l")]
    parts[others, 11] = 0.05
    np.testing.assert_allclose(expert.capture_point(obs), [[0.0, 0.041570]], atol=1e-6)
    # the neutral standing pose at rest, as the task observes it: no correction
    task = _task(motion=0, rsi=0)
    assert np.abs(expert.capture_point(task.observe()[0])).max() < 2e-3
    assert np.abs(expert(task.observe()[0])).max() < 0.01


def test_balance_expert_keeps_standing_under_pushes_that_topple_zero_actions():
    # 15 N s every 2 s, 8 trials (seed 0): zero actions (the stand pose) keep 3 of 8 (measured), the
    # ankle strategy all 8 (bench/RESULTS.md, 2026-11-27)
    expert = run_trials(BalanceExpert(), motion=0, trials=N, seed=0, push_impulse=15.0)
    zero = run_trials(lambda obs: np.zeros((len(obs), 26)), motion=0, trials=N, seed=0, push_impulse=15.0)
    assert expert["balance_kept"] == 1.0 and expert["r_r"] > 0.98
    assert zero["balance_kept"] <= 0.5


def test_spec_list_and_bad_motion():
    task = _task()
    assert "mimic" in TASKS and task.behavior_name == "Mimic" and task.num_agents == N
    assert task.observation_specs[0].shape == (170,) and task.action_spec.continuous_size == 26
    assert make_task("mimic", num_areas=2, seed=0).num_agents == 16
    assert CONTROL_DT == 0.02 and task.max_step == 500
    with pytest.raises(ValueError, match="motion must be 0..3"):
        _task(motion=7)


def test_cli_list_shows_mimic(capsys):
    assert main(["--list"]) == 0
    line = [row for row in capsys.readouterr().out.splitlines() if row.startswith("mimic:")][0]
    assert "[170]" in line and "continuous=26" in line


def test_decision_hz_250_steps_once_per_mujoco_step_on_the_resampled_reference():
    slow, fast = _task(), _task(decision_hz=250, rsi=0, motion=1)
    assert (slow.decision_hz, slow.substeps, slow.max_step) == (50, 5, 500)
    assert (fast.decision_hz, fast.substeps, fast.max_step, fast.control_dt) == (250, 1, 2500, 0.004)
    np.testing.assert_array_equal(fast.ref.frames, 5 * slow.ref.frames)
    # every fifth frame is a clip frame; between two, the joints move a fifth of the way each step
    arms = slice(fast.ref.offset[1], fast.ref.offset[1] + fast.ref.frames[1])
    clip = load_motion("arms").qpos
    np.testing.assert_allclose(fast.ref.qpos[arms][::5], clip, atol=1e-12)
    np.testing.assert_allclose(fast.ref.qpos[arms][2, 7:], clip[0, 7:] + 0.4 * (clip[1, 7:] - clip[0, 7:]), atol=1e-12)
    # the walk's last frames lead into the next stride, not back to the start
    walk, steps = fast.ref.qpos[fast.ref.offset[3]:fast.ref.offset[3] + fast.ref.frames[3], 1], load_motion("walk").qpos[:, 1]
    stride = fast.ref.stride[3]
    assert stride > 0 and walk[-1] == pytest.approx(steps[-1] + 0.8 * (steps[0] + stride - steps[-1]), abs=1e-12)
    np.testing.assert_allclose(fast.ref.speed, slow.ref.speed, rtol=1e-12)
    before = fast.data.time
    fast.step(np.zeros((N, 26)), np.zeros((N, 0)))
    assert fast.data.time - before == pytest.approx(0.004) and (fast.frame == 1).all()


def test_decision_hz_must_fit_the_physics_and_the_clips_and_change_only_at_a_reset():
    for bad in (30, 100, 0):
        with pytest.raises(ValueError, match="decision_hz must divide 250"):
            _task(decision_hz=bad)
    env = EnvironmentParameters()
    task = MimicTask(1, 0, env)
    env.set("decision_hz", lambda: 250)
    with pytest.raises(ValueError, match="changed from 50 to 250"):
        task.reset(np.arange(N) == 0)
    task.reset()  # a RESET: every agent restarts, the rate may change
    assert task.decision_hz == 250 and task.substeps == 1


def test_effort_weight_scales_the_reward_by_the_mean_relative_actuator_force():
    plain = _task(decision_hz=250, rsi=0, motion=2)
    tired = _task(decision_hz=250, rsi=0, motion=2, effort_weight=0.5)
    action = np.full((N, 26), 0.3)
    a = plain.step(action, np.zeros((N, 0)))
    b = tired.step(action, np.zeros((N, 0)))
    # one MuJoCo step per decision at 250 Hz: the factor comes from this step's actuator forces
    force = np.abs(tired.data.actuator_force[tired.actuator]) / np.array([400.0] * 3 + [60.0] * 3 + [100.0] * 3
                                                                        + [60.0] + [100.0] * 3 + [60.0]
                                                                        + [400.0] * 4 + [250.0] * 2 + [400.0] * 4
                                                                        + [250.0] * 2)
    np.testing.assert_allclose(tired.last_effort, force.mean(axis=1), rtol=1e-12)
    assert 0.0 < tired.last_effort.min() and tired.last_effort.max() < 1.0
    np.testing.assert_allclose(b.rewards, a.rewards * (1.0 - 0.5 * force.mean(axis=1)), rtol=1e-5)


def test_percent_of_max_reward_counts_the_decisions_after_a_fall_as_zero():
    zero = lambda obs: np.zeros((len(obs), 26))  # noqa: E731
    stand = run_trials(zero, motion=0, trials=N, seed=0)
    assert stand["balance_kept"] == 1.0 and stand["percent_of_max"] == pytest.approx(100.0, abs=0.1)
    walk = run_trials(zero, motion=3, trials=N, seed=0)  # falls within a second
    assert walk["balance_kept"] == 0.0
    # reward per decision while up x the share of the 10 s it stayed up
    assert walk["percent_of_max"] == pytest.approx(100.0 * walk["mean_reward"] * walk["mean_seconds"] / 10.0, rel=1e-6)
