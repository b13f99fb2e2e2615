"""Steps/s of the stub's tasks in-process as Gymnasium envs, against the socket path and against
raw MuJoCo (run by hand, not a test).

    nice -n 10 .venv/bin/python bench/gym_envs.py [--tasks ball3d dodge] [--decisions 300] [--repeats 3]

Per task, two agent counts: one agent (the single-agent forms) and one area of the task (ball3d 12
plates, dodge 14 characters: the batched forms). Every row drives the same task with uniform
random actions (pre-drawn) and counts agent-decisions/s (one agent-decision = one agent's action
and the task's decision period of control steps: ball3d 5 x 0.02 s, dodge 1 x 0.02 s):

  * ``raw MuJoCo``        ``mujoco.mj_step`` alone on the task's model and data, ``decision period
                          x substeps`` per decision: the physics floor (no rewards, no resets)
  * ``task``              ``Task.step`` (+ ``reset`` of finished agents), no Academy: physics plus
                          the task's own observations and rewards
  * ``gym (in-process)``  one agent: ``gymnasium.make("unity_stub_env/<Task>-v0")`` ``step`` (reset
                          at episode ends); one area: ``gymnasium.make_vec(..., num_envs=n)``
  * ``socket``            the stub as its own process behind real gRPC: one agent:
                          ``UnityToGymWrapper`` over a one-agent build (``--agents-per-area 1``),
                          via ``gymnasium.make("mlagents_like_envs/Unity-v0")``; one area:
                          ``UnityEnvironment`` ``set_actions`` + ``step`` + ``get_steps``

Two rates per row: per wall-clock second (the best of ``--repeats`` blocks of ``--decisions``
decisions) and per CPU-second (the same block's CPU time: this process, plus the stub process's
for the socket rows, read from /proc). On a loaded machine the CPU-second rate is the fair one: the
socket path runs two processes and so gets two shares of a contended CPU. "ratio" = the row's rate
/ the socket row's at the same agent count. Prints a markdown table; JSON to bench/out/gym_envs.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np

import unity_stub_env.gym  # noqa: F401  (registers the ids)
from mlagents_like_envs.environment import UnityEnvironment
from mlagents_like_envs.envs.unity_gym_env import ENV_ID
from unity_stub_env import write_player_launcher
from unity_stub_env.gym import ENV_IDS
from unity_stub_env.tasks import ball3d, dodge, make_task

OUT = Path(__file__).resolve().parent / "out"
SUBSTEPS = {"ball3d": ball3d.SUBSTEPS, "dodge": dodge.SUBSTEPS}  # MuJoCo steps per control step


def child_cpu_seconds(pid: int | None) -> float:
    """utime + stime of process ``pid`` (0 for None)."""
    if pid is None:
        return 0.0
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def best_rate(block, count, repeats: int, pid: int | None = None) -> tuple[float, float]:
    """(count / the fastest wall time, count / that block's CPU seconds) over ``repeats`` runs of
    ``block``; ``count`` a number or a callable giving the last block's count; ``pid``: a second
    process whose CPU time counts too."""
    runs = []
    for _ in range(repeats):
        wall, cpu, other = time.perf_counter(), time.process_time(), child_cpu_seconds(pid)
        block()
        wall = time.perf_counter() - wall
        cpu = time.process_time() - cpu + child_cpu_seconds(pid) - other
        n = count() if callable(count) else count
        runs.append((wall, n / wall, n / cpu))
    _, per_wall, per_cpu = min(runs)
    return per_wall, per_cpu


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def rows_for(task_name: str, agents: int | None, decisions: int, repeats: int, build_dir: Path) -> dict:
    """agent-decisions/s of each form of ``task_name`` with one agent (agents=1) or one area (None)."""
    task = make_task(task_name, seed=0, agents_per_area=agents)
    n, period, size = task.num_agents, task.decision_period, task.action_spec.continuous_size
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (decisions, n, size)).astype(np.float32)
    no_discrete = np.zeros((n, 0), np.int32)
    rates = {}

    physics_steps = period * SUBSTEPS[task_name]

    def raw_block():
        for _ in range(decisions):
            mujoco.mj_step(task.model, task.data, nstep=physics_steps)
    rates["raw MuJoCo"] = best_rate(raw_block, decisions * n, repeats)
    task.reset()

    def task_block():
        for d in range(decisions):
            for _ in range(period):
                result = task.step(actions[d], no_discrete)
                if result.done.any():
                    task.reset(result.done)
    rates["task"] = best_rate(task_block, decisions * n, repeats)

    if agents == 1:
        env = gym.make(ENV_IDS[task_name])
        env.reset(seed=0)

        def gym_block():
            for d in range(decisions):
                _, _, terminated, truncated, _ = env.step(actions[d, 0])
                if terminated or truncated:
                    env.reset()
        rates["gym (in-process)"] = best_rate(gym_block, decisions, repeats)
        env.close()
        build = write_player_launcher(build_dir, [task_name], extra_args=["--agents-per-area", "1"])
        wrapped = gym.make(ENV_ID, file_name=str(build.with_suffix("")), seed=0, timeout_wait=60)
        wrapped.reset()

        def socket_block():
            for d in range(decisions):
                _, _, terminated, truncated, _ = wrapped.step(actions[d, 0])
                if terminated or truncated:
                    wrapped.reset()
        rates["socket"] = best_rate(socket_block, decisions, repeats, wrapped.unwrapped._env._process.pid)
        wrapped.close()
    else:
        vec = gym.make_vec(ENV_IDS[task_name], num_envs=n)
        vec.reset(seed=0)

        def vec_block():
            for d in range(decisions):
                vec.step(actions[d])
        rates["gym (in-process)"] = best_rate(vec_block, decisions * n, repeats)
        vec.close()
        env = UnityEnvironment(f"stub:{task_name}", base_port=free_port(), seed=0, timeout_wait=60)
        env.reset()
        behavior = next(iter(env.behavior_specs))
        spec = env.behavior_specs[behavior].action_spec
        state = {"count": 0}

        def unity_block():
            for d in range(decisions):
                deciding, _ = env.get_steps(behavior)
                action = spec.empty_action(len(deciding))
                action.continuous[:] = actions[d, :len(deciding)]
                env.set_actions(behavior, action)
                env.step()
                state["count"] += len(deciding)
        def counted_block():
            state["count"] = 0
            unity_block()
        rates["socket"] = best_rate(counted_block, lambda: state["count"], repeats, env._process.pid)
        env.close()
    return {"agents": n, "decision_period": period, "rates": rates}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", nargs="+", default=["ball3d", "dodge"], choices=sorted(SUBSTEPS))
    parser.add_argument("--decisions", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    record = {"python": platform.python_version(), "load_average": list(os.getloadavg()), "decisions": args.decisions, "repeats": args.repeats, "runs": []}
    print("| task | agents | form | agent-decisions/s | ratio to socket | per CPU-second | ratio to socket |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as build_dir:
        for task_name in args.tasks:
            for agents in (1, None):
                row = rows_for(task_name, agents, args.decisions, args.repeats, Path(build_dir))
                record["runs"].append({"task": task_name, **row})
                wall0, cpu0 = row["rates"]["socket"]
                for form, (wall, cpu) in row["rates"].items():
                    print(f"| {task_name} | {row['agents']} | {form} | {wall:,.0f} | {wall / wall0:.1f}x | "
                          f"{cpu:,.0f} | {cpu / cpu0:.1f}x |", flush=True)
    print(f"load average at the start: {' '.join(f'{x:.1f}' for x in record['load_average'])}")
    OUT.mkdir(exist_ok=True)
    (OUT / "gym_envs.json").write_text(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
