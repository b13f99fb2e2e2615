"""The ``creature`` task's evaluation: targets, distance, progress and falls per simulated minute."""
from __future__ import annotations

import numpy as np

from unity_stub_env.tasks.creature.task import CreatureTask


def run_policy(task: CreatureTask, act, control_steps: int) -> dict:
    """Run ``act`` (float32 obs [n, size] -> actions [n, J]) on every agent for ``control_steps``,
    restarting finished episodes. Per minute of simulated time per agent: targets reached, the
    CoM's horizontal path length (``distance``), its progress towards the target (the decrease of
    its horizontal distance to the target of that step; a walker covers it, a faller only lunges)
    and falls (episodes ended by a vital contact); and the mean reward per step."""
    n = task.num_agents
    reached = distance = progress = falls = reward = 0.0
    for _ in range(control_steps):
        before_reached, before_distance = task.targets_reached.copy(), task.distance.copy()
        target, com = task.target[:, :2].copy(), task.data.subtree_com[task.root, :2].copy()
        result = task.step(act(task.observe()[0]), np.zeros((n, 0)))
        after = task.data.subtree_com[task.root, :2]
        progress += float((np.linalg.norm(target - com, axis=1) - np.linalg.norm(target - after, axis=1)).sum())
        reached += float((task.targets_reached - before_reached).sum())
        distance += float((task.distance - before_distance).sum())
        falls += float((result.done & ~result.interrupted).sum())
        reward += float(result.rewards.sum())
        task.reset(result.done)
    minutes = control_steps * task.control_dt / 60.0 * n
    return {"agent_minutes": minutes, "targets_per_minute": reached / minutes, "distance_per_minute": distance / minutes,
            "progress_per_minute": progress / minutes, "falls_per_minute": falls / minutes,
            "mean_reward": reward / (control_steps * n)}
