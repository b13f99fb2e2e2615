"""The stub's tasks in-process (``unity_stub_env.gym``): the registered Gymnasium ids pass
Gymnasium's own checker, the vector form and PettingZoo form pass theirs, and every form steps a
scene exactly as the socket path's Academy does (same observations, rewards and ends per decision)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import unity_stub_env.gym as stub_gym
from protos.communicator_objects import agent_action_pb2
from unity_stub_env.academy import Academy
from unity_stub_env.gym.scene import Scene
from unity_stub_env.task_names import TASK_NAMES
from unity_stub_env.tasks import TASKS, make_task

REPO = str(Path(__file__).resolve().parents[2])
SINGLE = [task for task in TASK_NAMES if not TASKS[task].agents_interact]
MULTI = [task for task in TASK_NAMES if TASKS[task].agents_interact]


def test_every_task_has_an_id():
    assert sorted(stub_gym.ENV_IDS) == sorted(TASK_NAMES)
    assert stub_gym.ENV_IDS["ball3d"] == "unity_stub_env/Ball3D-v0"
    assert stub_gym.ENV_IDS["pushblock"] == "unity_stub_env/PushBlock-v0"
    for env_id in stub_gym.ENV_IDS.values():
        assert env_id in gym.registry


@pytest.mark.parametrize("task", SINGLE)
def test_single_agent_ids_pass_gymnasiums_checker(task):
    env = gym.make(stub_gym.ENV_IDS[task])
    check_env(env.unwrapped, skip_render_check=True)
    spec = TASKS[task].action_spec if task != "creature" else env.unwrapped.scene.action_spec
    if spec.continuous_size:
        assert env.action_space == gym.spaces.Box(-1, 1, (spec.continuous_size,), np.float32)
    else:
        assert env.action_space == gym.spaces.Discrete(spec.discrete_branches[0])
    assert env.unwrapped.scene.num_agents == 1
    env.close()


@pytest.mark.parametrize("task", MULTI)
def test_tasks_whose_agents_play_together_have_no_single_agent_form(task):
    with pytest.raises(ValueError, match="PettingZoo form"):
        gym.make(stub_gym.ENV_IDS[task])


def _academy_by_protos(task: str, seed: int, actions: list[np.ndarray], **task_args):
    """The socket path's Academy (messages encoded and decoded, no socket): per decision the
    observations, rewards and done flags the trainer would read, decision requests only."""
    academy = Academy(make_task(task, seed=seed, **task_args))
    spec = academy.task.action_spec
    out = []
    for action in actions:
        protos = [agent_action_pb2.AgentActionProto(continuous_actions=row[:spec.continuous_size],
                                                    discrete_actions=row[spec.continuous_size:].astype(int))
                  for row in action]
        academy.apply_actions(protos)
        academy.advance()
        infos = academy.collect_infos()
        out.append(infos)
    return out


@pytest.mark.parametrize("task, areas", [("ball3d", None), ("pushblock", None), ("basic", None)])
def test_the_scene_steps_as_the_socket_paths_academy(task, areas):
    """Same seed and actions: the Scene's arrays equal what the Academy encodes for the trainer,
    decision for decision (ball3d: SetReward and a decision period of 5; pushblock: group rewards)."""
    rng = np.random.default_rng(0)
    scene = Scene(task, seed=3)
    spec, n = scene.action_spec, scene.num_agents
    steps = 150
    if spec.continuous_size:
        actions = [rng.uniform(-1, 1, (n, spec.continuous_size)).astype(np.float32) for _ in range(steps)]
    else:
        actions = [rng.integers(0, spec.discrete_branches[0], (n, 1)).astype(np.float32) for _ in range(steps)]
    reference = _academy_by_protos(task, 3, actions)
    ends = 0
    for action, infos in zip(actions, reference):
        cont, disc = (action, np.zeros((n, 0), np.int32)) if spec.continuous_size else \
            (np.zeros((n, 0), np.float32), action.astype(np.int32))
        result = scene.step(cont, disc)
        done_infos = [info for info in infos if info.done]
        requests = [info for info in infos if not info.done]
        assert len(requests) == n
        ended = np.flatnonzero(result.ended)
        assert len(done_infos) == len(ended)
        # the terminal infos come in the order the agents ended; match them by their observation
        finals = {tuple(np.round(result.final_observations[0][i], 5)): i for i in ended}
        for info in done_infos:
            i = finals[tuple(np.round(np.array(info.observations[0].float_data.data, np.float32), 5))]
            assert result.rewards[i] == pytest.approx(info.reward, abs=1e-6)
            assert result.group_rewards[i] == pytest.approx(info.group_reward, abs=1e-6)
            assert bool(result.truncated[i]) == info.max_step_reached
        ends += len(ended)
        for i, info in enumerate(requests):
            np.testing.assert_allclose(result.observations[0][i], info.observations[0].float_data.data, atol=1e-6)
            if i not in ended:
                assert result.rewards[i] == pytest.approx(info.reward, abs=1e-6)
                assert result.group_rewards[i] == pytest.approx(info.group_reward, abs=1e-6)
    assert ends > 0  # the comparison covered episode ends


def test_environment_parameters_are_keyword_arguments():
    env = gym.make("unity_stub_env/Ball3D-v0", gravity=0.0, mass=2.0)
    task = env.unwrapped.scene.task
    env.reset(seed=0)
    assert task.model.body_mass[task.ball_body[0]] == 2.0
    assert task.model.opt.gravity[2] == 0.0
    obs, *_ = env.step(np.zeros(2, np.float32))
    # no gravity, no push: the ball hangs 4 m above the plate centre where the episode put it
    assert obs[4] == pytest.approx(4.0) and obs[7] == pytest.approx(0.0)
    obs, *_ = gym.make("unity_stub_env/Ball3D-v0").unwrapped.step(np.zeros(2, np.float32))
    assert obs[7] < -0.5  # with gravity it falls
    with pytest.raises(TypeError, match="'mass' must be a number"):
        gym.make("unity_stub_env/Ball3D-v0", mass="heavy")


def test_seeded_resets_repeat_episodes_and_seeds_differ():
    env = gym.make("unity_stub_env/Ball3D-v0")
    first, _ = env.reset(seed=5)
    again, _ = env.reset(seed=5)
    other, _ = env.reset(seed=6)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_vector_form_steps_the_scene_as_one_batch_and_resets_in_the_same_step():
    vec = gym.make_vec("unity_stub_env/Ball3D-v0", num_envs=12, decision_period=1)
    assert isinstance(vec.unwrapped, gym.vector.VectorEnv)
    assert vec.num_envs == 12 and vec.unwrapped.scene.num_agents == 12
    assert vec.single_observation_space.shape == (8,) and vec.action_space.shape == (12, 2)
    obs, _ = vec.reset(seed=1)
    assert obs.shape == (12, 8)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(200):
        obs, rewards, terminated, truncated, infos = vec.step(rng.uniform(-1, 1, (12, 2)).astype(np.float32))
        if terminated.any():
            rows = np.flatnonzero(infos["_final_obs"])
            np.testing.assert_array_equal(rows, np.flatnonzero(terminated | truncated))
            assert np.all(rewards[terminated] == -1.0)  # ball3d: -1 when the ball falls
            for i in rows:
                # the ball fell off this plate ...
                final = infos["final_obs"][i]
                assert final[4] < -2.0 or abs(final[2]) > 3.0 or abs(final[3]) > 3.0
                # ... and the new episode's ball is 4 m above the plate, at rest
                assert obs[i, 4] == pytest.approx(4.0) and np.all(obs[i, 5:8] == 0.0)
            ended += len(rows)
    assert ended > 12


def test_one_agent_vector_form_and_single_env_are_the_same_episode():
    env = gym.make("unity_stub_env/Dodge-v0")
    vec = gym.make_vec("unity_stub_env/Dodge-v0", num_envs=1)
    a, _ = env.reset(seed=2)
    b, _ = vec.reset(seed=2)
    np.testing.assert_array_equal(a, b[0])
    rng = np.random.default_rng(1)
    for _ in range(30):
        action = rng.uniform(-1, 1, 9).astype(np.float32)
        a, ra, *_ = env.step(action)
        b, rb, *_ = vec.step(action[None])
        np.testing.assert_array_equal(a, b[0])
        assert ra == rb[0]


def test_vector_form_of_a_team_task_counts_whole_areas():
    vec = gym.make_vec("unity_stub_env/PushBlock-v0", num_envs=2 * TASKS["pushblock"].agents_per_area)
    assert vec.unwrapped.scene.task.num_areas == 2
    with pytest.raises(ValueError, match="multiple of"):
        gym.make_vec("unity_stub_env/PushBlock-v0", num_envs=TASKS["pushblock"].agents_per_area + 1)


@pytest.mark.parametrize("task", MULTI + ["ball3d"])
def test_pettingzoo_parallel_form_passes_its_api_test(task):
    parallel_api_test(stub_gym.parallel_env(task), num_cycles=300)


def test_pettingzoo_rewards_and_group_rewards_as_ml_agents_wrappers_report_them():
    """pushblock, one area: each agent's reward is its own, its group's reward is in its infos,
    as the scene reports them."""
    env = stub_gym.parallel_env("unity_stub_env/PushBlock-v0")
    reference = Scene("pushblock", seed=4)
    env.reset(seed=4)
    rng = np.random.default_rng(0)
    group_seen = False
    for _ in range(400):
        if not env.agents:
            break
        action = rng.integers(0, 5, reference.num_agents)
        _, rewards, _, _, infos = env.step({name: action[row] for row, name in enumerate(env.agents)})
        result = reference.step(np.zeros((reference.num_agents, 0), np.float32), action[:, None].astype(np.int32))
        for row, name in enumerate(env.possible_agents):
            if name in rewards:
                assert rewards[name] == pytest.approx(result.rewards[row])
                assert infos[name]["group_reward"] == pytest.approx(result.group_rewards[row])
                assert infos[name]["group_id"] == reference.task.group_ids()[row]
        group_seen |= bool(np.any(result.group_rewards != 0))
    assert group_seen
    assert env.possible_agents[0] == "PushBlock?team=0?agent_id=0"


_RENDER_SCRIPT = """
import gymnasium as gym, numpy as np, pytest, unity_stub_env.gym
from gymnasium.utils.env_checker import check_env
env = gym.make("unity_stub_env/Ball3D-v0", render_mode="rgb_array")
check_env(env.unwrapped)
env.reset(seed=0)
first = env.render()
assert first.dtype == np.uint8 and first.shape == (480, 640, 3), (first.dtype, first.shape)
assert first.std() > 5, first.std()  # a plate and a ball on the background, not a blank frame
for _ in range(5):
    env.step(np.ones(2, np.float32))
change = np.abs(env.render().astype(int) - first).mean()
assert change > 0.5, change  # the plate tilted
env.close()
with pytest.raises(ValueError, match="not a MuJoCo scene"):
    gym.make("unity_stub_env/Basic-v0", render_mode="rgb_array")
print("frames ok")
"""


def test_rgb_array_frames_come_from_mujocos_renderer():
    """In a fresh process: MuJoCo reads MUJOCO_GL when first imported (this one has imported it)."""
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": REPO}
    done = subprocess.run([sys.executable, "-c", _RENDER_SCRIPT], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "frames ok" in done.stdout


def test_agents_per_area_makes_one_agent_scenes_of_independent_tasks_only(capsys):
    from unity_stub_env.cli import main

    assert make_task("ball3d", num_areas=2, agents_per_area=1).num_agents == 2
    with pytest.raises(ValueError, match="play together"):
        make_task("pushblock", agents_per_area=1)
    assert main(["--task", "soccer", "--agents-per-area", "1", "--mlagents-port", "5005"]) == 2
    assert "soccer cannot take it" in capsys.readouterr().err


def test_the_docs_table_of_ids_is_the_generated_one():
    from unity_stub_env.gym.__main__ import ids_table

    assert ids_table() in (Path(REPO) / "docs" / "python-api.md").read_text()


def test_the_cleanrl_example_runs():
    example = Path(REPO) / "docs" / "examples" / "cleanrl_envs.py"
    done = subprocess.run([sys.executable, str(example)], env={**os.environ, "PYTHONPATH": REPO},
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert lines[0].startswith("4 single-plate envs:") and lines[1].startswith("one area of 12 plates:")
    # random play drops the ball within a few dozen decisions: many episodes, returns of a few
    # tenths of the 100 possible (the batched form: unnormalised returns, +0.1 a decision, -1 at the fall)
    episodes = int(lines[1].split(": ")[1].split()[0])
    mean = float(lines[1].rsplit(" ", 1)[1])
    assert episodes >= 40 and 0.0 < mean < 5.0
