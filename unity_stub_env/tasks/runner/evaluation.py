"""The ``runner`` task's evaluation: drive a policy once along each of a list of seeded tracks."""
from __future__ import annotations

import numpy as np

from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.runner.task import PLATFORM_LENGTH, RunnerTask


def runner_on_tracks(seeds: list[int], **track_settings) -> RunnerTask:
    """A runner with one agent per seed, agent i on the track of ``seeds[i]`` (the episode's only
    track: reset it again and it would ask for more seeds)."""
    params = EnvironmentParameters()
    for key, value in track_settings.items():
        params.set(key, lambda value=value: float(value))
    iterator = iter(seeds)
    params.set("track_seed", lambda: float(next(iterator)))
    batch = type("RunnerBatch", (RunnerTask,), {"agents_per_area": len(seeds)})
    return batch(num_areas=1, seed=0, env_params=params)


def evaluate_tracks(act, seeds, batch_size: int = 50, **track_settings) -> dict:
    """Drive ``act`` (float32 [n, 29] -> [n, 1]) once along each track of ``seeds``; an episode
    ends on falling, finishing or max_step. Returns the completion rate, mean platforms passed,
    mean obstacles hit and mean return."""
    seeds = [int(seed) for seed in seeds]
    completed, passed, hits, returns = [], [], [], []
    for start in range(0, len(seeds), batch_size):
        batch = seeds[start:start + batch_size]
        task, n = runner_on_tracks(batch, **track_settings), len(batch)
        total, active = np.zeros(n), np.ones(n, dtype=bool)
        finished, reached, hit = np.zeros(n, dtype=bool), np.zeros(n), np.zeros(n)
        while active.any():
            actions = np.asarray(act(task.observe()[0]), dtype=np.float32).reshape(n, -1)
            result = task.step(actions, np.zeros((n, 0)))
            total += np.where(active, result.rewards, 0.0)
            ended = result.done & active
            finished[ended] = task.s[ended] >= task.num_platforms[ended] * PLATFORM_LENGTH
            reached[ended] = task.platforms_passed()[ended]
            hit[ended] = task.obstacles_hit[ended]
            active &= ~ended
        completed += finished.tolist()
        passed += reached.tolist()
        hits += hit.tolist()
        returns += total.tolist()
    return {"tracks": len(seeds), "completion_rate": float(np.mean(completed)),
            "mean_platforms_passed": float(np.mean(passed)), "mean_obstacles_hit": float(np.mean(hits)),
            "mean_return": float(np.mean(returns))}
