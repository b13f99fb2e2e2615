"""The stub's tasks in-process, without sockets: Gymnasium and PettingZoo forms.

``import unity_stub_env.gym`` registers one Gymnasium id per task, ``unity_stub_env/<Task>-v0``
(``ENV_IDS``)::

    import gymnasium as gym
    import unity_stub_env.gym

    env = gym.make("unity_stub_env/Ball3D-v0", mass=2.0)        # one agent; kwargs: env parameters
    vec = gym.make_vec("unity_stub_env/Ball3D-v0", num_envs=12)  # a scene's agents as one batch
    pz = unity_stub_env.gym.parallel_env("pushblock")            # PettingZoo ParallelEnv

Ids of tasks whose agents play together (PushBlock, Dungeon, Soccer, SoccerTwos) have no
single-agent form: ``gym.make_vec`` and ``parallel_env`` serve them. docs/python-api.md, "The
stub's tasks in-process", lists the ids with their spaces. Needs the ``gym`` extra (gymnasium,
pettingzoo); the rest of the stub does not.
"""
from __future__ import annotations

import gymnasium

from unity_stub_env.task_names import TASK_NAMES

# the id's name of each task: Unity's CamelCase (ball3d -> Ball3D, as the stub's "builds" are named)
ID_NAMES = {"basic": "Basic", "ball3d": "Ball3D", "dodge": "Dodge", "creature": "Creature", "mimic": "Mimic",
            "runner": "Runner", "soccer": "Soccer", "soccer_twos": "SoccerTwos", "pushblock": "PushBlock",
            "dungeon": "Dungeon"}
ENV_IDS = {task: f"unity_stub_env/{ID_NAMES[task]}-v0" for task in TASK_NAMES}


def parallel_env(task: str, **kwargs):
    """A PettingZoo ``ParallelEnv`` of ``task`` (a task name or its id); kwargs as ``StubParallelEnv``."""
    from unity_stub_env.gym.parallel import StubParallelEnv

    by_id = {env_id: name for name, env_id in ENV_IDS.items()}
    return StubParallelEnv(by_id.get(task, task), **kwargs)


def _register() -> None:
    for task, env_id in ENV_IDS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(id=env_id, entry_point="unity_stub_env.gym.env:StubEnv",
                           vector_entry_point="unity_stub_env.gym.vector:StubVectorEnv",
                           kwargs={"task": task}, disable_env_checker=False)


_register()

__all__ = ["ENV_IDS", "ID_NAMES", "parallel_env"]
