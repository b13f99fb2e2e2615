"""The ``creature`` task (docs/stub-tasks.md): specs, Walker's reward terms, targets, terrain, episode ends."""
from __future__ import annotations

import numpy as np
import pytest

from unity_stub_env.creatures import generate
from unity_stub_env.tasks import EnvironmentParameters, make_task
from unity_stub_env.tasks.creature import (
    HFIELD_SIZE,
    MAX_TERRAIN_HEIGHT,
    REACH_DISTANCE,
    TARGET_MIN_DISTANCE,
    look_reward,
    match_speed_reward,
    perlin,
)


def _params(**values) -> EnvironmentParameters:
    params = EnvironmentParameters()
    for key, value in values.items():
        params.set(key, lambda value=value: value)
    return params


def _zeros(task) -> np.ndarray:
    return np.zeros((task.num_agents, task.action_spec.continuous_size), dtype=np.float32)


def test_specs_follow_the_creature():
    for kind, index in (("quadruped", 0), ("biped", 1), ("lsystem", 2)):
        task = make_task("creature", num_areas=3, seed=0, env_params=_params(creature_kind=index, creature_seed=7))
        skeleton = generate(kind, 7)
        bones, hinges = len(skeleton.bones), skeleton.num_hinges()
        assert task.num_agents == 3 and task.skeleton.kind == kind
        assert task.observation_specs[0].shape == (14 + 10 * bones + hinges,)
        assert task.action_spec.continuous_size == hinges and task.action_spec.discrete_branches == ()
        obs = task.observe()[0]
        assert obs.shape == (3, 14 + 10 * bones + hinges) and np.isfinite(obs).all()
        assert np.allclose(obs[:, 3:6], [1.0, 0.0, 0.0])  # goal velocity in the cube frame
        # the rest pose: every hinge at 0, mapped from [min, max] to [-1, 1]
        rest = -2.0 * task.hinge_low / (task.hinge_high - task.hinge_low) - 1.0
        assert np.allclose(obs[:, 14 + 10 * bones:], rest, atol=1e-6)
    with pytest.raises(ValueError, match="creature_kind"):
        make_task("creature", env_params=_params(creature_kind=5))


def test_reward_terms_against_hand_computed_values():
    speed = np.array([1.0, 1.0, 2.0])
    goal = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 2.0, 0]])
    velocity = np.array([[0.5, 0, 0], [-1.0, 0, 0], [0, 1.0, 0]])
    # |delta| = 0.5 -> (1 - 0.25)^2; 2 clipped to 1 -> 0; 1 of 2 -> (1 - 0.25)^2
    assert match_speed_reward(goal, velocity, speed) == pytest.approx([0.5625, 0.0, 0.5625])
    forward = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    facing = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0]])
    assert look_reward(forward, facing) == pytest.approx([1.0, 0.5, 0.0])


def _floating(task, velocity):
    """Every creature 1 m up in the air, gravity off, moving as one rigid body at ``velocity``."""
    task.model.opt.gravity[:] = 0.0
    data = task.data
    data.qpos[task.root_qpos[:, 2]] += 1.0
    data.qpos[task.root_qpos[:, 3:]] = [1.0, 0.0, 0.0, 0.0]  # yaw 0: the root's +x is world +x
    data.qvel[task.root_dof] = 0.0
    data.qvel[task.root_dof[:, :3]] = velocity


def test_reward_in_the_task_is_speed_match_times_look():
    """A creature gliding at 0.5 m/s along +y, facing +x: target ahead along +x gives
    match 0 (|(1,0,0) - (0,.5,0)| = 1.118 clipped to 1) x look 1; target along +y gives
    (1 - 0.5^2)^2 = 0.5625 x look 0.5 = 0.28125."""
    import mujoco

    task = make_task("creature", num_areas=2, seed=0)
    _floating(task, [0.0, 0.5, 0.0])
    mujoco.mj_forward(task.model, task.data)
    com = task.data.subtree_com[task.root]
    task.target[0] = com[0] + [6.0, 0.0, 0.0]
    task.target[1] = com[1] + [0.0, 6.0, 0.0]
    result = task.step(_zeros(task), np.zeros((2, 0)))
    speed_term, look_term = task.last_reward_terms
    assert np.allclose(task.velocity.mean(axis=1), [0.0, 0.5, 0.0], atol=1e-6)
    assert speed_term == pytest.approx([0.0, 0.5625], abs=1e-5)
    assert look_term == pytest.approx([1.0, 0.5], abs=1e-5)
    assert result.rewards == pytest.approx([0.0, 0.28125], abs=1e-5)
    assert not result.done.any()
    obs = task.observe()[0]
    assert obs[1, 0:3] == pytest.approx([0.5, 0.0, 0.0], abs=1e-5)  # velocity in the cube frame
    # agent 0 moved 2.5 cm sideways: its cube turned by atan(0.025 / 6) towards the target
    assert obs[0, 0:3] == pytest.approx([-0.5 * np.sin(np.arctan(0.025 / 6)), 0.5, 0.0], abs=1e-5)


def test_target_moves_when_reached():
    import mujoco

    task = make_task("creature", num_areas=2, seed=3)
    _floating(task, [0.0, 0.0, 0.0])
    mujoco.mj_forward(task.model, task.data)
    com = task.data.subtree_com[task.root]
    task.target[0, :2] = com[0, :2] + [0.9 * REACH_DISTANCE, 0.0]
    task.target[1, :2] = com[1, :2] + [1.1 * REACH_DISTANCE, 0.0]
    before = task.target.copy()
    task.step(_zeros(task), np.zeros((2, 0)))
    assert task.targets_reached.tolist() == [1, 0]
    assert np.array_equal(task.target[1], before[1])
    assert np.linalg.norm(task.target[0, :2] - com[0, :2]) >= TARGET_MIN_DISTANCE
    assert np.abs(task.target[0, :2] - task.centre[0, :2]).max() <= 8.0
    assert task.model.geom_pos[task.target_geom[0]] == pytest.approx(task.target[0])


def test_roughness_parameter_rewrites_the_heightfield_at_reset():
    roughness = {"value": 0.0}
    params = EnvironmentParameters()
    params.set("terrain_roughness", lambda: roughness["value"])
    task = make_task("creature", num_areas=2, seed=0, env_params=params)
    assert task.heights(0).max() == 0.0 and task.heights(1).max() == 0.0
    roughness["value"] = 0.5  # a curriculum lesson changes the parameter: no rebuild
    task.reset(np.array([True, False]))
    assert task.heights(0).max() == pytest.approx(0.5 * MAX_TERRAIN_HEIGHT)
    assert task.heights(0).min() == 0.0 and task.heights(0).std() > 0.02
    assert task.heights(1).max() == 0.0
    # the creature was lifted above the new terrain near the centre
    z = task.data.qpos[task.root_qpos[0, 2]]
    assert z > generate("quadruped", 0).bones[0].proximal[2]


def test_perlin_noise_is_seeded_and_spans_zero_to_one():
    a = perlin((HFIELD_SIZE, HFIELD_SIZE), 16.0, np.random.default_rng(4))
    b = perlin((HFIELD_SIZE, HFIELD_SIZE), 16.0, np.random.default_rng(4))
    c = perlin((HFIELD_SIZE, HFIELD_SIZE), 16.0, np.random.default_rng(5))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.min() == 0.0 and a.max() == 1.0
    # one octave: the noise is 0 on the lattice points (every 16th sample), before the rescaling
    one = perlin((33, 33), 16.0, np.random.default_rng(0), octaves=1)
    lattice = one[::16, ::16]
    assert np.allclose(lattice, lattice[0, 0])
    assert np.abs(np.diff(one, axis=0)).max() < 0.2  # smooth: neighbouring samples differ little


def test_obstacles_appear_and_vital_contact_ends_the_episode():
    task = make_task("creature", num_areas=1, seed=0, env_params=_params(obstacles=3))
    below = task.model.geom_pos[task.obstacle_geom[0], 2] < -5
    assert below.tolist() == [False] * 3 + [True] * 3
    # drop the creature so its torso lies on the ground: the episode ends, not interrupted
    task.data.qpos[task.root_qpos[0, 2]] = 0.05
    result = task.step(_zeros(task), np.zeros((1, 0)))
    assert result.done.tolist() == [True] and result.interrupted.tolist() == [False]
    assert {name for name, _, _ in result.stats} == {"Creature/Targets Reached", "Creature/Distance"}


def test_fall_penalty_sets_the_reward_of_the_falling_step_only():
    # two arenas: agent 0's torso is dropped onto the ground, agent 1 stands
    rewards = {}
    for penalty in (0.0, 1.5):
        task = make_task("creature", num_areas=2, seed=0, env_params=_params(fall_penalty=penalty))
        task.data.qpos[task.root_qpos[0, 2]] = 0.05
        result = task.step(_zeros(task), np.zeros((2, 0)))
        assert result.done.tolist() == [True, False]
        rewards[penalty] = result.rewards.tolist()
    assert rewards[1.5][0] == -1.5  # the falling step's reward is replaced by the penalty
    assert rewards[0.0][0] >= 0.0  # the default: no penalty, the Walker product as it was
    assert rewards[1.5][1] == rewards[0.0][1]  # a standing agent is not touched
    with pytest.raises(ValueError, match="fall_penalty must be >= 0"):
        make_task("creature", num_areas=1, seed=0, env_params=_params(fall_penalty=-1.0))


def test_gait_clock_adds_sin_and_cos_of_the_episode_time():
    # default: no clock, the observation as before; 1.25 Hz: two more values, the phase
    # 2 pi 1.25 Hz x (k x 0.05 s) = k pi / 8 after k control steps
    bones_hinges = 14 + 10 * 23 + 30  # quadruped seed 7: 23 bones, 30 hinges
    plain = make_task("creature", num_areas=2, seed=0, env_params=_params(creature_seed=7))
    assert plain.observation_specs[0].shape == (bones_hinges,)
    task = make_task("creature", num_areas=2, seed=0, env_params=_params(creature_seed=7, gait_clock_hz=1.25))
    assert task.observation_specs[0].shape == (bones_hinges + 2,)
    s, c = np.sqrt(0.5), np.sqrt(0.5)
    expected = {0: (0.0, 1.0), 2: (s, c), 4: (1.0, 0.0), 8: (0.0, -1.0), 12: (-1.0, 0.0)}
    for k in range(13):
        obs = task.observe()[0]
        assert obs.shape == (2, bones_hinges + 2)
        if k in expected:
            assert obs[:, -2:] == pytest.approx(np.tile(expected[k], (2, 1)), abs=1e-6)
        # the rest of the observation is the clock-free task's
        assert np.array_equal(obs[:, :-2], plain.observe()[0])
        task.step(_zeros(task), np.zeros((2, 0)))
        plain.step(_zeros(plain), np.zeros((2, 0)))
    # an episode start restarts the clock of that agent only
    task.reset(np.array([True, False]))
    # agent 1 after 13 steps: 13 pi / 8, sin = -sin(3 pi / 8) = -0.92388, cos = cos(3 pi / 8) = 0.38268
    assert task.observe()[0][:, -2:] == pytest.approx(np.array([[0.0, 1.0], [-0.92388, 0.38268]]), abs=1e-5)
    with pytest.raises(ValueError, match="gait_clock_hz must be >= 0"):
        make_task("creature", num_areas=1, seed=0, env_params=_params(gait_clock_hz=-1.0))


def test_a_standing_creature_is_interrupted_at_max_step():
    task = make_task("creature", num_areas=1, seed=0)
    task.max_step = 30
    for step in range(30):
        result = task.step(_zeros(task), np.zeros((1, 0)))
        assert bool(result.done[0]) == (step == 29)
    assert result.interrupted.tolist() == [True]
    assert result.rewards[0] < 0.05  # standing still earns (almost) nothing: the speed term is ~0


def test_the_task_is_deterministic_for_a_seed():
    params = dict(terrain_roughness=0.4, obstacles=2)
    actions = np.random.default_rng(1).uniform(-1, 1, (40, 2, generate("quadruped", 0).num_hinges()))
    runs = []
    for seed in (5, 5, 6):
        task = make_task("creature", num_areas=2, seed=seed, env_params=_params(**params))
        trace = [task.observe()[0].copy()]
        for action in actions:
            result = task.step(action, np.zeros((2, 0)))
            task.reset(result.done)
            trace.append(task.observe()[0].copy())
        runs.append(np.stack(trace))
    assert np.array_equal(runs[0], runs[1]) and not np.array_equal(runs[0], runs[2])


def test_shipped_config_names_only_parameters_the_task_reads():
    import os

    from tests.stub.conftest import REPO
    from trainer.config.cli_args import parse_run_options
    from unity_stub_env.tasks.creature import DEFAULTS

    for name in ("creature.yaml", "creature_walk.yaml"):
        options = parse_run_options([os.path.join(REPO, "configs", name), "--env", "stub:creature"])
        assert list(options.behaviors) == ["Creature"]
        assert set(options.environment_parameters) <= set(DEFAULTS)


def test_run_policy_counts_per_simulated_minute():
    from unity_stub_env.tasks.creature import run_policy

    task = make_task("creature", num_areas=2, seed=0)
    out = run_policy(task, lambda obs: np.zeros((len(obs), task.action_spec.continuous_size), np.float32), 60)
    assert out["agent_minutes"] == pytest.approx(2 * 60 * 0.05 / 60)
    assert out["targets_per_minute"] == 0.0 and out["falls_per_minute"] == 0.0  # holding the rest pose
    assert abs(out["progress_per_minute"]) < 1.0 and out["distance_per_minute"] < 2.0
    # a reached target counts once: put agent 0's target under its CoM
    task.target[0, :2] = task.data.subtree_com[task.root[0], :2]
    out = run_policy(task, lambda obs: np.zeros((len(obs), task.action_spec.continuous_size), np.float32), 1)
    assert out["targets_per_minute"] == pytest.approx(1 / (2 * 0.05 / 60))
