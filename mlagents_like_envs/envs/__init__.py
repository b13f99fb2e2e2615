"""Wrappers of a ``BaseEnv`` for other RL libraries, at mlagents_envs' module paths:
``unity_gym_env.UnityToGymWrapper`` (Gymnasium 1.x), ``unity_parallel_env.UnityParallelEnv`` and
``unity_aec_env.UnityAECEnv`` (PettingZoo). They need the ``gym`` extra (gymnasium, pettingzoo)."""
