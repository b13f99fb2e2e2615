"""The real ``mlagents_envs.UnityEnvironment`` 1.1.0 drives every stub task like a Unity build.

Each test runs ``peer_scripts/random_rollout.py`` in .venv-interop: it launches the
``Stub<Task>.x86_64`` launcher through UnityEnvironment (which adds -nographics -batchmode
--mlagents-port), resets, reads behavior_specs, steps with random actions and closes.
"""
from __future__ import annotations

import numpy as np
import pytest

from unity_stub_env import TASKS

# The documented specs (README "Stub tasks" / docs/protocol.md, "Behavior spec"), written out by hand.
# dimension_property 1 = NONE; observation_type 0 = DEFAULT.
DOCUMENTED_SPECS = {
    "basic": {"Basic?team=0": {
        "observation_specs": [{"shape": [20], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size20"}],
        "action_spec": {"continuous_size": 0, "discrete_branches": [3]},
    }},
    "ball3d": {"3DBall?team=0": {
        "observation_specs": [{"shape": [8], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size8"}],
        "action_spec": {"continuous_size": 2, "discrete_branches": []},
    }},
    "dodge": {"Dodge?team=0": {
        "observation_specs": [{"shape": [17], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size17"}],
        "action_spec": {"continuous_size": 9, "discrete_branches": []},
    }},
    "mimic": {"Mimic?team=0": {
        "observation_specs": [{"shape": [170], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size170"}],
        "action_spec": {"continuous_size": 26, "discrete_branches": []},
    }},
    "runner": {"Runner?team=0": {
        "observation_specs": [{"shape": [29], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size29"}],
        "action_spec": {"continuous_size": 1, "discrete_branches": []},
    }},
    "creature": {"Creature?team=0": {  # the default creature: quadruped, creature_seed 0
        "observation_specs": [{"shape": [298], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size298"}],
        "action_spec": {"continuous_size": 34, "discrete_branches": []},
    }},
    "soccer": {f"Soccer?team={team}": {  # one behavior per team, identical specs
        "observation_specs": [{"shape": [12], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size12"}],
        "action_spec": {"continuous_size": 0, "discrete_branches": [3, 3]},
    } for team in (0, 1)},
    "soccer_twos": {f"SoccerTwos?team={team}": {  # two players per team, each team one group
        "observation_specs": [{"shape": [16], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size16"}],
        "action_spec": {"continuous_size": 0, "discrete_branches": [3, 3]},
    } for team in (0, 1)},
    "pushblock": {"PushBlock?team=0": {
        "observation_specs": [{"shape": [11], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size11"}],
        "action_spec": {"continuous_size": 0, "discrete_branches": [5]},
    }},
    "dungeon": {"Dungeon?team=0": {
        "observation_specs": [{"shape": [18], "dimension_property": [1], "observation_type": 0,
                               "name": "VectorSensor_size18"}],
        "action_spec": {"continuous_size": 0, "discrete_branches": [5]},
    }},
}
AGENTS = {"basic": 1, "ball3d": 12, "dodge": 14, "mimic": 8, "runner": 4, "creature": 1,
          "soccer": 2, "soccer_twos": 4, "pushblock": 2, "dungeon": 3}  # agents per area over all its behaviors; one area by default
STEPS = 500


def _rollout(run_peer, stub_executable, free_port, task: str, **options):
    exe = stub_executable(task)
    options = {"file_name": str(exe.with_suffix("")), "base_port": free_port(), "steps": STEPS,
               "seed": 1, "timeout_wait": 60, **options}
    completed, result = run_peer("random_rollout.py", options, timeout=150)
    assert completed.returncode == 0, completed.stderr[-3000:]
    return result


def test_every_task_has_a_documented_spec():
    assert set(TASKS) == set(DOCUMENTED_SPECS)


@pytest.mark.parametrize("task", sorted(DOCUMENTED_SPECS))
def test_unity_environment_runs_stub_task(task, run_peer, stub_executable, free_port, is_gone):
    result = _rollout(run_peer, stub_executable, free_port, task)

    assert result["behavior_specs"] == DOCUMENTED_SPECS[task]
    assert result["id_errors"] == []
    behavior = next(iter(DOCUMENTED_SPECS[task]))
    per_behavior = AGENTS[task] // len(DOCUMENTED_SPECS[task])
    # Every agent decides at every env.step() (decision_period steps of physics in between),
    # and an agent that finished also shows up once as a terminal step.
    assert result["decision_steps"] == (STEPS + 1) * AGENTS[task]  # the reset + every step
    assert result["terminal_steps"] > 0
    assert result["returncode"] == 0, "the stub must exit cleanly on the trainer's 400"
    assert is_gone(result["pid"])
    first_obs = np.asarray(result["first_obs"][behavior])
    assert first_obs.shape == (per_behavior, DOCUMENTED_SPECS[task][behavior]["observation_specs"][0]["shape"][0])
    if task == "basic":
        # one-hot positions: exactly one 1.0 per row
        np.testing.assert_array_equal(first_obs.sum(axis=1), np.ones(AGENTS[task]))
        # random walk from 10 in a corridor with goals at 7 and 17 and max_step 100: every
        # episode ends at a goal or by interruption, and episodes are short (< 100 steps)
        assert result["terminal_steps"] >= STEPS // 100
        outcomes = result["stats"]["Basic/Large Goal Reached"]
        assert len(outcomes) == result["terminal_steps"]  # one stat per finished episode
        assert {value for value, _ in outcomes} <= {0.0, 1.0}
        assert {agg for _, agg in outcomes} == {0}  # AVERAGE
    if task == "dodge":
        # start pose: no crouch, torso and neck quaternions at identity (w, x, y, z)
        np.testing.assert_allclose(first_obs[:, :9], np.tile([0, 1, 0, 0, 0, 1, 0, 0, 0], (14, 1)), atol=0.2)
        # every throw ends within 0.4-1.4 s (20-70 decisions): 500 steps give >= 14 * 500 / 70 episodes
        assert result["terminal_steps"] >= 14 * STEPS // 70
        hits, passes = result["stats"]["Dodge/Hit"], result["stats"]["Dodge/Passed"]
        assert len(hits) == len(passes) == result["terminal_steps"]
        assert sum(value for value, _ in hits) + sum(value for value, _ in passes) >= result["terminal_steps"]
    if task == "mimic":
        # uniform random PD targets over the whole ranges topple the ragdoll within ~1 s (50 decisions)
        assert result["terminal_steps"] >= 8 * STEPS // 50
        fell = result["stats"]["Mimic/Fell"]
        assert len(fell) == result["terminal_steps"] and {value for value, _ in fell} == {1.0}
        assert 0.0 < np.mean([value for value, _ in result["stats"]["Mimic/r_r"]]) < 0.2
        np.testing.assert_allclose(np.linalg.norm(first_obs[:, :4], axis=1), 1.0, atol=1e-4)  # pelvis quaternion


def test_environment_parameters_pick_the_mimic_motion_and_its_controller(run_peer, stub_executable, free_port):
    """motion=2 (squat) with residual=1: zero actions leave the PD controllers on the reference,
    which squat for the whole 200 decisions (4 s) without falling; the phase advances 1/200 per step."""
    result = _rollout(run_peer, stub_executable, free_port, "mimic", steps=200, zero_actions=True,
                      env_float_parameters={"motion": 2.0, "residual": 1.0})
    assert result["terminal_steps"] == 0 and result["id_errors"] == []
    phase = np.asarray(result["first_obs"]["Mimic?team=0"])[:, -1]
    assert ((phase > 0) & (phase < 1)).all()


def test_side_channels_reach_the_stub_and_back(run_peer, stub_executable, free_port, tmp_path, is_gone):
    """EnvironmentParametersChannel gravity=0 freezes the falling balls; stats come back."""
    log = tmp_path / "ball3d.log"
    result = _rollout(
        run_peer, stub_executable, free_port, "ball3d", steps=40,
        env_float_parameters={"gravity": 0.0},
        engine_config={"width": 64, "height": 48, "quality_level": 1, "time_scale": 7.0,
                       "target_frame_rate": 30, "capture_frame_rate": 30},
        additional_args=["-logFile", str(log)],
    )
    first_obs = np.asarray(result["first_obs"]["3DBall?team=0"])  # [12, 8] after one decision
    # The balls are dropped 4 units above the plates with zero velocity; without gravity they
    # hover, so their velocity (obs 5..7) is exactly 0 and height above the plate stays 4.
    np.testing.assert_array_equal(first_obs[:, 5:8], np.zeros((12, 3)))
    np.testing.assert_allclose(first_obs[:, 4], np.full(12, 4.0), atol=1e-6)
    assert result["returncode"] == 0 and is_gone(result["pid"])
    log_text = log.read_text()
    assert "Unknown side channel" not in log_text and "ERROR" not in log_text
    # No ball can fall without gravity: no terminal steps, so no 3DBall stats either.
    assert result["terminal_steps"] == 0


def test_stats_side_channel_values_read_by_mlagents(run_peer, stub_executable, free_port):
    """With gravity the balls fall; the stub's stats arrive in mlagents' StatsSideChannel."""
    result = _rollout(run_peer, stub_executable, free_port, "ball3d", steps=200)
    fell = result["stats"]["3DBall/Ball Fell"]
    assert len(fell) == result["terminal_steps"] > 0
    assert {agg for _, agg in fell} == {0}  # AVERAGE
    lengths = result["stats"]["3DBall/Last Episode Length"]
    assert {agg for _, agg in lengths} == {1}  # MOST_RECENT
    assert all(value >= 1 for value, _ in lengths)
