"""Step-rate benchmark of the stub tasks ``dodge`` and ``mimic`` (run by hand, not a test).

    .venv/bin/python bench/dodge_steps.py [--task dodge|mimic] [--areas 1 4] [--steps 300] [--repeats 5]

Per area count, three rows on the same MjModel (dodge: 14 characters and spheres per area; mimic:
8 ragdolls per area):
  * ``stub TASK``    ``Task.step`` + ``reset`` of the finished agents with random actions in
                     [-1, 1]: agent-steps/s (one agent-step = one 0.02 s control step of one agent),
                     and the mj_step/s that loop achieved (dodge: 4 MuJoCo steps of 0.005 s per
                     control step; mimic: 5 of 0.004 s). Random PD targets topple a mimic ragdoll
                     in ~0.7 s, so its loop includes a reset (reference state + mj_forward) every
                     ~4 control steps, as early in training
  * ``academy``      the stub's ``Academy``: ``advance`` + ``collect_encoded`` (the AgentInfo bytes
                     the stub sends each decision), the per-decision work of the real stub process
  * ``raw MuJoCo``   ``mujoco.mj_step`` alone on the same model and data: the physics states the
                     ``stub dodge`` loop started its control steps from (recorded with
                     ``mj_getState``) are restored one by one and each gets its 4 mj_steps, so the
                     physics is the same mix of flying, bouncing and freshly thrown spheres (or
                     standing, falling and freshly reset ragdolls); mj_step/s, and the agent-steps/s
                     it would allow (mj_step/s / substeps * agents)
The "physics share" column = raw MuJoCo's time per control step / the row's time per control step.
Each figure is the best of ``--repeats`` blocks of ``--steps`` control steps (other processes on
the machine only ever slow a block down). Prints a markdown table; JSON to bench/out/TASK_steps.json.
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from unity_stub_env.academy import Academy
from unity_stub_env.tasks import dodge, make_task, mimic

SUBSTEPS = {"dodge": dodge.SUBSTEPS, "mimic": mimic.SUBSTEPS}

OUT = Path(__file__).resolve().parent / "out"


def best_of(block, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        block()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(task_name: str, areas: int, steps: int, repeats: int) -> dict:
    task = make_task(task_name, num_areas=areas, seed=0)
    n = task.num_agents
    substeps = SUBSTEPS[task_name]
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, task.action_spec.continuous_size))
    no_discrete = np.zeros((n, 0))

    def task_block():
        for action in actions:
            result = task.step(action, no_discrete)
            task.reset(result.done)

    task_s = best_of(task_block, repeats) / steps
    model, data = task.model, task.data
    spec = mujoco.mjtState.mjSTATE_PHYSICS
    states = np.empty((steps, mujoco.mj_stateSize(model, spec)))
    for i, action in enumerate(actions):  # the state after each control step (the next one starts there)
        result = task.step(action, no_discrete)
        task.reset(result.done)
        mujoco.mj_getState(model, data, states[i], spec)
    academy = Academy(make_task(task_name, num_areas=areas, seed=0))

    def academy_block():
        for action in actions:
            academy.continuous[:] = action
            academy.advance()
            academy.collect_encoded()

    academy_s = best_of(academy_block, repeats) / steps
    def raw_block():
        for state in states:
            mujoco.mj_setState(model, data, state, spec)
            for _ in range(substeps):
                mujoco.mj_step(model, data)

    raw_s = best_of(raw_block, repeats) / steps
    row = lambda seconds: {"agent_steps_per_s": n / seconds, "mj_steps_per_s": substeps / seconds,  # noqa: E731
                           "ms_per_control_step": 1e3 * seconds, "physics_share": raw_s / seconds}
    return {"areas": areas, "agents": n, f"stub {task_name}": row(task_s), "academy": row(academy_s),
            "raw MuJoCo": row(raw_s)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=sorted(SUBSTEPS), default="dodge")
    parser.add_argument("--areas", type=int, nargs="+", default=[1, 4])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    results = [measure(args.task, areas, args.steps, args.repeats) for areas in args.areas]
    print("| areas | agents | row | agent-steps/s | mj_step/s | ms per control step | physics share |")
    print("|---|---|---|---|---|---|---|")
    for result in results:
        for name in (f"stub {args.task}", "academy", "raw MuJoCo"):
            r = result[name]
            print(f"| {result['areas']} | {result['agents']} | {name} | {r['agent_steps_per_s']:,.0f} | "
                  f"{r['mj_steps_per_s']:,.0f} | {r['ms_per_control_step']:.3f} | {r['physics_share']:.0%} |")
    OUT.mkdir(exist_ok=True)
    record = {"mujoco": mujoco.__version__, "python": platform.python_version(), "args": vars(args),
              "results": results, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    (OUT / f"{args.task}_steps.json").write_text(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
