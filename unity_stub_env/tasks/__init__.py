"""The task registry: ``TASKS`` maps a task name to its class; ``make_task`` builds one.

Usable without any protocol (e.g. by bench/ to time raw physics)::

    task = make_task("ball3d", num_areas=1, seed=0)
    task.reset()
    result = task.step(np.random.uniform(-1, 1, (task.num_agents, 2)), np.zeros((task.num_agents, 0)))
"""
from __future__ import annotations

from unity_stub_env.tasks.ball3d import Ball3DTask
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep
from unity_stub_env.tasks.basic import BasicTask
from unity_stub_env.tasks.creature import CreatureTask
from unity_stub_env.tasks.dodge import DodgeTask
from unity_stub_env.tasks.dungeon import DungeonTask
from unity_stub_env.tasks.mimic import MimicTask
from unity_stub_env.tasks.pushblock import PushBlockTask
from unity_stub_env.tasks.runner import RunnerTask
from unity_stub_env.tasks.soccer import SoccerTask, SoccerTwosTask

TASKS: dict[str, type[Task]] = {
    BasicTask.name: BasicTask,
    Ball3DTask.name: Ball3DTask,
    DodgeTask.name: DodgeTask,
    CreatureTask.name: CreatureTask,
    MimicTask.name: MimicTask,
    RunnerTask.name: RunnerTask,
    SoccerTask.name: SoccerTask,
    SoccerTwosTask.name: SoccerTwosTask,
    PushBlockTask.name: PushBlockTask,
    DungeonTask.name: DungeonTask,
}


def make_task(name: str, num_areas: int = 1, seed: int = 0,
              env_params: EnvironmentParameters | None = None, agents_per_area: int | None = None) -> Task:
    """Build the task ``name`` with ``num_areas`` areas; KeyError names the known tasks.

    ``agents_per_area`` changes how many agents one area holds, for tasks whose agents never
    interact (``Task.agents_interact`` False): ``ball3d`` with 1 is a single plate, the form a
    single-agent Gymnasium env or a one-agent "build" needs. ValueError for the others."""
    if name not in TASKS:
        raise KeyError(f"Unknown task {name!r}; known tasks: {', '.join(sorted(TASKS))}")
    cls = TASKS[name]
    if agents_per_area is not None and agents_per_area != cls.agents_per_area:
        if cls.agents_interact:
            raise ValueError(f"Task {name!r} has {cls.agents_per_area} agents per area that play together; "
                             "its number of agents per area cannot change (change num_areas instead)")
        if agents_per_area < 1:
            raise ValueError(f"agents_per_area must be >= 1, got {agents_per_area}")
        cls = type(cls.__name__, (cls,), {"agents_per_area": int(agents_per_area)})
    return cls(num_areas=num_areas, seed=seed, env_params=env_params)


__all__ = ["TASKS", "make_task", "Task", "TaskStep", "EnvironmentParameters", "BasicTask", "Ball3DTask", "DodgeTask", "CreatureTask",
           "MimicTask", "RunnerTask", "SoccerTask", "SoccerTwosTask", "PushBlockTask", "DungeonTask"]
