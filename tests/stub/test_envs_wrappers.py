"""The wrappers of mlagents_like_envs.envs over UnityEnvironment and the stub in its own process
(real gRPC): Gymnasium's ``check_env`` and PettingZoo's ``parallel_api_test`` / ``api_test`` pass,
and what they report is checked by hand (basic's corridor) and against the in-process env."""
from __future__ import annotations

import socket

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import api_test, parallel_api_test

import unity_stub_env.gym  # noqa: F401  (the in-process ids)
from mlagents_like_envs.environment import UnityEnvironment
from mlagents_like_envs.envs.unity_aec_env import UnityAECEnv
from mlagents_like_envs.envs.unity_gym_env import ENV_ID, ActionFlattener, UnityGymException, UnityToGymWrapper
from mlagents_like_envs.envs.unity_parallel_env import UnityParallelEnv
from unity_stub_env import write_player_launcher


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def unity(task: str, seed: int = 1) -> UnityEnvironment:
    return UnityEnvironment(f"stub:{task}", base_port=free_port(), seed=seed, timeout_wait=30)


@pytest.fixture(scope="module")
def one_plate_build(tmp_path_factory):
    """The stub as a Unity build of 3DBall with one plate (single-agent wrappers need one agent)."""
    folder = tmp_path_factory.mktemp("build")
    return str(write_player_launcher(folder, ["ball3d"], extra_args=["--agents-per-area", "1"]).with_suffix(""))


def test_gymnasium_checker_passes_on_a_launched_build(one_plate_build):
    env = gym.make(ENV_ID, file_name=one_plate_build, seed=3, timeout_wait=30)
    try:
        assert env.unwrapped.spec.nondeterministic  # a build takes its seed at launch only
        assert env.observation_space == gym.spaces.Box(-np.inf, np.inf, (8,), np.float32)
        assert env.action_space == gym.spaces.Box(-1, 1, (2,), np.float32)
        check_env(env.unwrapped)
    finally:
        env.close()


def test_the_wrapper_and_the_in_process_env_play_the_same_episode(one_plate_build):
    """Same seed, same actions: the socket path behind UnityToGymWrapper and unity_stub_env's
    in-process Ball3D-v0 report the same observations, rewards and ends."""
    wrapped = gym.make(ENV_ID, file_name=one_plate_build, seed=7, timeout_wait=30)
    local = gym.make("unity_stub_env/Ball3D-v0", seed=7)
    try:
        a, _ = wrapped.reset()
        local.reset()  # the wrapper's constructor reset the build once already (as mlagents_envs' does)
        b, _ = local.reset()
        np.testing.assert_allclose(a, b, atol=1e-6)
        rng = np.random.default_rng(0)
        ends = 0
        for _ in range(120):
            action = rng.uniform(-1, 1, 2).astype(np.float32)
            a, ra, ta, ua, info = wrapped.step(action)
            b, rb, tb, ub, _ = local.step(action)
            np.testing.assert_allclose(a, b, atol=1e-5)
            assert (ra, ta, ua) == pytest.approx((rb, tb, ub), abs=1e-6)
            if ta or ua:
                ends += 1
                with pytest.raises(UnityGymException, match="reset"):
                    wrapped.step(action)  # as mlagents_envs: stepping past the end is refused
                wrapped.reset()
                local.reset()
        assert ends >= 2
    finally:
        wrapped.close()


def test_basic_by_hand_through_the_wrapper():
    """basic: -0.01 a step; seven steps right reach the large goal (+1.0, terminated); staying
    put is interrupted at max_step 100 (truncated)."""
    env = UnityToGymWrapper(unity("basic"))
    try:
        assert env.action_space == gym.spaces.Discrete(3)
        obs, info = env.reset()
        assert obs.argmax() == 10 and info["step"].agent_id.shape == (1,)
        rewards = []
        for _ in range(7):
            obs, reward, terminated, truncated, _ = env.step(2)
            rewards.append(reward)
        assert rewards == pytest.approx([-0.01] * 6 + [0.99])
        assert terminated and not truncated and obs.argmax() == 17
        env.reset()
        for step in range(1, 101):
            _, reward, terminated, truncated, _ = env.step(0)
            assert reward == pytest.approx(-0.01)
            if terminated or truncated:
                break
        assert (step, terminated, truncated) == (100, False, True)
    finally:
        env.close()


def test_more_than_one_agent_or_behavior_is_refused_with_the_reason():
    with pytest.raises(UnityGymException, match="one Agent in the environment but 12 were detected"):
        UnityToGymWrapper(unity("ball3d"))
    with pytest.raises(UnityGymException, match="one behavior"):
        UnityToGymWrapper(unity("soccer"))


def test_flattened_branches_enumerate_every_combination():
    flattener = ActionFlattener((2, 3))
    assert flattener.action_space == gym.spaces.Discrete(6)
    assert [flattener.lookup_action(i) for i in range(6)] == [[0, 0], [0, 1], [0, 2], [1, 0], [1, 1], [1, 2]]


@pytest.mark.parametrize("task", ["pushblock", "soccer_twos", "basic"])
def test_pettingzoo_wrappers_pass_pettingzoos_api_tests(task):
    parallel = UnityParallelEnv(unity(task), seed=0)
    try:
        parallel_api_test(parallel, num_cycles=200)
    finally:
        parallel.close()
    aec = UnityAECEnv(unity(task), seed=0)
    try:
        api_test(aec, num_cycles=200)
    finally:
        aec.close()


def test_parallel_wrapper_names_rewards_and_group_rewards():
    """soccer_twos (2 v 2, each team a group, goals as group rewards): two behaviors' agents under
    ML-Agents' names; an ended agent leaves and its next episode joins under a new id."""
    env = UnityParallelEnv(unity("soccer_twos", seed=2), seed=0)
    try:
        obs, infos = env.reset()
        assert len(env.agents) == 4
        assert sorted({name.split("?agent_id=")[0] for name in env.agents}) == ["SoccerTwos?team=0", "SoccerTwos?team=1"]
        assert env.action_space(env.agents[0]) == gym.spaces.MultiDiscrete([3, 3])
        assert {infos[a]["group_id"] for a in env.agents if "team=0" in a} != {0}  # teams are groups
        rng = np.random.default_rng(0)
        first = set(env.agents)
        for _ in range(2000):
            actions = {agent: rng.integers(0, 3, 2) for agent in env.agents}
            obs, rewards, terminated, truncated, infos = env.step(actions)
            ended = [a for a in rewards if terminated[a] or truncated[a]]
            if ended:
                break
        assert ended and not (set(ended) & set(env.agents))
        assert len(env.agents) == 4 and not (set(env.agents) & first)  # the next episode's agents
        assert all(a in env.possible_agents for a in first | set(env.agents))
        group = [infos[a]["group_reward"] for a in ended]
        assert any(g != 0 for g in group) or all(truncated[a] for a in ended)  # a goal, or a draw at max_step
    finally:
        env.close()
