"""Benchmarks of the stub task ``creature`` (docs/stub-tasks.md; run by hand, not a test).

    .venv/bin/python bench/creature.py steps [--areas 1 8] [--steps 200] [--repeats 5] [--kind quadruped]
    .venv/bin/python bench/creature.py noise [--sigmas 0 0.1 0.3 1] [--areas 4] [--minutes 1]
    .venv/bin/python bench/creature.py evaluate POLICY [POLICY ...] [--kind quadruped --creature-seed 7]
                     [--roughness 0] [--target-speed 1] [--gait-clock-hz 0] [--areas 8] [--minutes 2] [--seed 0]

``steps``: per area count, three rows on the same MjModel (one creature per arena):
  * ``stub creature`` ``CreatureTask.step`` + ``reset`` of the finished agents, random actions in [-1, 1]
  * ``academy``       the stub's ``Academy``: ``advance`` + ``collect_encoded`` (the per-decision work
                      of the stub process, the observation encoding included)
  * ``raw MuJoCo``    ``mujoco.mj_step`` alone on the same model: the states (controls included) the
                      first loop started its control steps from are restored (``mj_setState``) and
                      each gets its 10 mj_steps
  agent-steps/s (one agent-step = one 0.05 s control step of one creature), mj_step/s, and the
  physics share = raw time per control step / the row's. Best of ``--repeats`` blocks.

``evaluate``: each POLICY (a trained ``.onnx``, ``zero`` or ``random``) drives every arena for
``--minutes`` of simulated time per agent (episodes restart when they end): targets reached,
distance covered by the centre of mass (path length, and progress towards the target) per minute
of simulated time, falls per minute, mean reward per step (``unity_stub_env.tasks.creature.run_policy``). An ``.onnx`` policy acts with its mean
action, or with ``--sample`` with its sampled actions (as while training; the ONNX graph draws the noise).
``noise``: how lethal exploration is: zero-mean Gaussian joint targets of each std ``--sigmas``
(clipped to [-1, 1], drawn anew at every decision, as a policy with mean 0 samples them), falls
and distance per simulated minute (``run_policy``).

All print markdown tables and write JSON to bench/out/creature_<command>.json.
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
from unity_stub_env.evaluate import load_policy
from unity_stub_env.tasks import EnvironmentParameters, make_task
from unity_stub_env.tasks.creature import KINDS, SUBSTEPS, run_policy

from dodge_steps import best_of  # noqa: E402  (bench/ is the script's folder on sys.path)

OUT = Path(__file__).resolve().parent / "out"


def _params(kind: str, creature_seed: int, roughness: float = 0.0, target_speed: float = 1.0,
            gait_clock_hz: float = 0.0) -> EnvironmentParameters:
    params = EnvironmentParameters()
    params.set("gait_clock_hz", lambda: gait_clock_hz)
    params.set("creature_kind", lambda: float(KINDS.index(kind)))
    params.set("creature_seed", lambda: float(creature_seed))
    params.set("terrain_roughness", lambda: roughness)
    params.set("target_speed", lambda: target_speed)
    return params


def measure_steps(areas: int, steps: int, repeats: int, kind: str, creature_seed: int) -> dict:
    task = make_task("creature", num_areas=areas, seed=0, env_params=_params(kind, creature_seed))
    n, size = task.num_agents, task.action_spec.continuous_size
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, size))
    no_discrete = np.zeros((n, 0))

    def task_block():
        for action in actions:
            result = task.step(action, no_discrete)
            task.reset(result.done)

    task_s = best_of(task_block, repeats) / steps
    model, data = task.model, task.data
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    states = np.empty((steps, mujoco.mj_stateSize(model, spec)))
    for i, action in enumerate(actions):  # the state each control step starts from, its controls included
        data.ctrl[task.actuator] = np.where(action >= 0, action * task.hinge_high, -action * task.hinge_low)
        mujoco.mj_getState(model, data, states[i], spec)
        result = task.step(action, no_discrete)
        task.reset(result.done)
    academy = Academy(make_task("creature", num_areas=areas, seed=0, env_params=_params(kind, creature_seed)))

    def academy_block():
        for action in actions:
            academy.continuous[:] = action
            academy.advance()
            academy.collect_encoded()

    academy_s = best_of(academy_block, repeats) / steps
    def raw_block():
        for state in states:
            mujoco.mj_setState(model, data, state, spec)
            for _ in range(SUBSTEPS):
                mujoco.mj_step(model, data)

    raw_s = best_of(raw_block, repeats) / steps
    row = lambda seconds: {"agent_steps_per_s": n / seconds, "mj_steps_per_s": SUBSTEPS / seconds,  # noqa: E731
                           "ms_per_control_step": 1e3 * seconds, "physics_share": raw_s / seconds}
    return {"areas": areas, "agents": n, "bodies": int(model.nbody), "actuators": int(model.nu),
            "stub creature": row(task_s), "academy": row(academy_s), "raw MuJoCo": row(raw_s)}


def steps_command(args) -> dict:
    results = [measure_steps(a, args.steps, args.repeats, args.kind, args.creature_seed) for a in args.areas]
    print(f"{args.kind} seed {args.creature_seed}")
    print("| areas | agents | row | agent-steps/s | mj_step/s | ms per control step | physics share |")
    print("|---|---|---|---|---|---|---|")
    for result in results:
        for name in ("stub creature", "academy", "raw MuJoCo"):
            r = result[name]
            print(f"| {result['areas']} | {result['agents']} | {name} | {r['agent_steps_per_s']:,.0f} | "
                  f"{r['mj_steps_per_s']:,.0f} | {r['ms_per_control_step']:.2f} | {r['physics_share']:.0%} |")
    return {"results": results}


def _sampling(path: str):
    """The ONNX model's sampled actions (its ``continuous_actions`` output: the mean plus its own
    Gaussian noise), as the policy acts while it trains; ``load_policy`` takes the mean."""
    import onnxruntime

    session = onnxruntime.InferenceSession(path, providers=["CPUExecutionProvider"])
    return lambda obs: session.run(["continuous_actions"], {"obs_0": np.asarray(obs, np.float32)})[0]


def evaluate_command(args) -> dict:
    params = lambda: _params(args.kind, args.creature_seed, args.roughness, args.target_speed,  # noqa: E731
                             args.gait_clock_hz)
    task = make_task("creature", num_areas=args.areas, seed=args.seed, env_params=params())
    size, actions = task.observation_specs[0].shape[0], task.action_spec.continuous_size
    control_steps = int(round(args.minutes * 60.0 / task.control_dt))
    results = {}
    for policy in dict.fromkeys([*args.policies, "zero", "random"]):
        task = make_task("creature", num_areas=args.areas, seed=args.seed, env_params=params())
        act = load_policy(policy, size, actions, args.seed)
        if args.sample and policy.endswith(".onnx"):
            act = _sampling(policy)
        results[policy] = run_policy(task, act, control_steps)
    print(f"{args.kind} seed {args.creature_seed}, roughness {args.roughness}, target speed {args.target_speed} m/s, "
          f"gait clock {args.gait_clock_hz} Hz, {args.areas} arenas x "
          f"{args.minutes} simulated min, {'sampled' if args.sample else 'mean'} actions")
    print("| policy | targets / min | distance m / min | towards target m / min | falls / min | mean reward / step |")
    print("|---|---|---|---|---|---|")
    for policy, r in results.items():
        print(f"| {policy} | {r['targets_per_minute']:.2f} | {r['distance_per_minute']:.1f} | "
              f"{r['progress_per_minute']:.1f} | {r['falls_per_minute']:.1f} | {r['mean_reward']:.3f} |")
    return {"results": results}


def noise_command(args) -> dict:
    results = {}
    for sigma in args.sigmas:
        task = make_task("creature", num_areas=args.areas, seed=args.seed,
                         env_params=_params(args.kind, args.creature_seed, args.roughness))
        rng, size = np.random.default_rng(args.seed), task.action_spec.continuous_size
        act = lambda obs, sigma=sigma: np.clip(rng.normal(0.0, sigma, (len(obs), size)), -1.0, 1.0)  # noqa: E731
        results[str(sigma)] = run_policy(task, act, int(round(args.minutes * 60.0 / task.control_dt)))
    print(f"{args.kind} seed {args.creature_seed}, roughness {args.roughness}, {args.areas} arenas x {args.minutes} "
          "simulated min, zero-mean Gaussian joint targets")
    print("| std | falls / min | distance m / min |")
    print("|---|---|---|")
    for sigma, r in results.items():
        print(f"| {sigma} | {r['falls_per_minute']:.1f} | {r['distance_per_minute']:.1f} |")
    return {"results": results}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    steps = sub.add_parser("steps")
    steps.add_argument("--areas", type=int, nargs="+", default=[1, 8])
    steps.add_argument("--steps", type=int, default=200)
    steps.add_argument("--repeats", type=int, default=5)
    evaluate = sub.add_parser("evaluate")
    evaluate.add_argument("policies", nargs="*", default=[])
    evaluate.add_argument("--roughness", type=float, default=0.0)
    evaluate.add_argument("--areas", type=int, default=8)
    evaluate.add_argument("--minutes", type=float, default=2.0)
    evaluate.add_argument("--seed", type=int, default=0)
    evaluate.add_argument("--target-speed", type=float, default=1.0,
                          help="the environment parameter target_speed (m/s) the policies were trained with: "
                               "it is in their observation and sets the reward")
    evaluate.add_argument("--gait-clock-hz", type=float, default=0.0,
                          help="the environment parameter gait_clock_hz the policies were trained with (0: none; "
                               "it sets the observation's size)")
    evaluate.add_argument("--sample", action="store_true",
                          help="act with the .onnx policies' sampled actions (as in training) instead of their mean")
    noise = sub.add_parser("noise")
    noise.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 0.1, 0.3, 1.0])
    for p in (noise,):
        p.add_argument("--roughness", type=float, default=0.0)
        p.add_argument("--areas", type=int, default=4)
        p.add_argument("--minutes", type=float, default=1.0)
        p.add_argument("--seed", type=int, default=0)
    for p in (steps, evaluate, noise):
        p.add_argument("--kind", choices=KINDS, default="quadruped")
        p.add_argument("--creature-seed", type=int, default=7)
    args = parser.parse_args()
    record = {"steps": steps_command, "evaluate": evaluate_command, "noise": noise_command}[args.command](args)
    OUT.mkdir(exist_ok=True)
    record.update({"mujoco": mujoco.__version__, "python": platform.python_version(), "args": vars(args),
                   "time": time.strftime("%Y-%m-%d %H:%M:%S")})
    (OUT / f"creature_{args.command}.json").write_text(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
