"""How a CleanRL script (e.g. ppo_continuous_action.py) gets its envs from the stub, in-process.

Two ways; the rest of the script is unchanged either way (it reads ``envs.single_observation_space``
/ ``single_action_space``, calls ``envs.reset(seed=...)`` and ``envs.step(actions)``, and finds
finished episodes in ``infos["episode"]``):

1. the script's own ``make_env`` with ``--env-id unity_stub_env/Ball3D-v0``: one plate per env
   and the per-env wrappers the script applies (here the same chain of Gymnasium wrappers);
2. one 3DBall area of 12 plates stepped as one batch: ``gymnasium.make_vec``. It resets finished
   agents in the same step, as Unity does, and Gymnasium's vector *observation* wrappers (such as
   ``wrappers.vector.NormalizeObservation``) accept only next-step resets: normalise inside the
   agent instead, or use way 1.

This file plays random actions for ``STEPS`` vector steps each way and prints the episodes' mean
return (tests/stub/test_stub_gym.py runs it).
"""
import gymnasium as gym
import numpy as np

import unity_stub_env.gym  # noqa: F401  (registers unity_stub_env/<Task>-v0)

STEPS = 200
SEED = 1
GAMMA = 0.99


def make_env(env_id: str):
    def thunk():
        env = gym.make(env_id)
        env = gym.wrappers.FlattenObservation(env)
        env = gym.wrappers.RecordEpisodeStatistics(env)
        env = gym.wrappers.ClipAction(env)
        env = gym.wrappers.NormalizeObservation(env)
        env = gym.wrappers.TransformObservation(env, lambda obs: np.clip(obs, -10, 10), env.observation_space)
        env = gym.wrappers.NormalizeReward(env, gamma=GAMMA)
        return gym.wrappers.TransformReward(env, lambda reward: float(np.clip(reward, -10, 10)))
    return thunk


def play(envs, label: str) -> None:
    assert isinstance(envs.single_action_space, gym.spaces.Box), "only continuous action space is supported"
    envs.reset(seed=SEED)
    envs.action_space.seed(SEED)
    returns = []
    for _ in range(STEPS):
        actions = envs.action_space.sample()  # the script's agent.get_action_and_value(next_obs) goes here
        _, _, _, _, infos = envs.step(actions)
        if "episode" in infos:
            returns += infos["episode"]["r"][infos["_episode"]].tolist()
    envs.close()
    print(f"{label}: {len(returns)} episodes, mean return {np.mean(returns):.3f}")


play(gym.vector.SyncVectorEnv([make_env("unity_stub_env/Ball3D-v0") for _ in range(4)]), "4 single-plate envs")

batched = gym.make_vec("unity_stub_env/Ball3D-v0", num_envs=12)  # all agents of one area, one batch
batched = gym.wrappers.vector.RecordEpisodeStatistics(batched)
batched = gym.wrappers.vector.ClipAction(batched)
play(batched, "one area of 12 plates")
