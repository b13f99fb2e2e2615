"""MA-POCA vs independent PPO on a cooperative stub task at equal steps (run by hand).

    nice -n 10 .venv/bin/python bench/poca_vs_ppo.py [--task pushblock|dungeon] [--max-steps 60000]
        [--seeds 1 2 3] [--num-areas 8] [--trainers poca ppo] [--env-param block_friction=12 ...]

configs/<task>_poca.yaml is run as shipped (``trainer_type: poca``) and with ``trainer_type: ppo``
and nothing else changed (the same hyperparameters, network, seeds, areas and steps). Independent
PPO gets the same group rewards while an agent is in its episode (the rollout adds them to each
agent's reward, as the reference's PPO does) but its critic sees one agent only, its advantages
carry no counterfactual baseline, and an agent that left its group early sees nothing of what the
group earned afterwards. Reported per trainer and seed, read back from TensorBoard:
``<Behavior>/Success`` (the fraction of group episodes that succeeded: the block home, the door
opened) and ``Policy/Extrinsic Reward`` (each agent's episode return, group rewards included) at
every summary; the table gives the first summary step with a success rate >= 0.9 and the mean of
the last 3 summaries; for ``dungeon`` also a probe of the final policy (``probe_dungeon``: how
often the dragon ate somebody, how often the group escaped). ``--env-param KEY=VALUE`` adds a constant environment parameter of the task
(pushblock: ``block_friction``, ``progress_reward``; dungeon: ``time_penalty``; see the tasks'
docstrings in unity_stub_env/tasks/) to both configs. JSON to ``<out>/poca_vs_ppo_<task>.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

ROOT = Path(__file__).resolve().parent.parent
BEHAVIORS = {"pushblock": "PushBlock", "dungeon": "Dungeon"}  # task -> behavior name (its configs/<task>_poca.yaml)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def tags(task: str) -> tuple[str, str]:
    return f"{BEHAVIORS[task]}/Success", "Policy/Extrinsic Reward"


def run(task: str, trainer_type: str, seed: int, max_steps: int, areas: int, work: Path,
        env_params: dict[str, float]) -> dict[str, list[tuple[int, float]]]:
    text = (ROOT / "configs" / f"{task}_poca.yaml").read_text()
    text = re.sub(r"max_steps: \d+", f"max_steps: {max_steps}",
                  text.replace("trainer_type: poca", f"trainer_type: {trainer_type}"))
    if env_params:
        text += "environment_parameters:\n" + "".join(f"  {k}: {v}\n" for k, v in env_params.items())
    config = work / f"{trainer_type}.yaml"
    config.write_text(text)
    run_id = f"{trainer_type}-{seed}"
    cmd = [str(ROOT / ".venv" / "bin" / "mlagents-like-learn"), str(config), "--env", f"stub:{task}",
           "--num-areas", str(areas), "--seed", str(seed), "--run-id", run_id, "--results-dir", str(work),
           "--base-port", str(free_port())]
    done = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    if done.returncode != 0:
        sys.exit(f"{run_id} failed:\n{done.stderr[-3000:]}")
    acc = EventAccumulator(str(work / run_id / BEHAVIORS[task]), size_guidance={"scalars": 0})
    acc.Reload()
    curves = {tag: [(e.step, round(e.value, 4)) for e in acc.Scalars(tag)] for tag in tags(task)}
    if task == "dungeon":
        curves["probe"] = probe_dungeon(work / run_id / "Dungeon.onnx", env_params.get("time_penalty", 0.0))
    return curves


def probe_dungeon(onnx: Path, time_penalty: float, areas: int = 200, seed: int = 123) -> dict[str, float]:
    """The trained policy (its sampled ``discrete_actions``, onnxruntime) plays one group episode in
    each of ``areas`` areas of a fresh task: the fraction in which the dragon ate somebody and the
    fraction that escaped. Tells a group that avoids the dragon from one that cannot find the door."""
    import numpy as np
    import onnxruntime

    from unity_stub_env.tasks import EnvironmentParameters, make_task

    session = onnxruntime.InferenceSession(str(onnx), providers=["CPUExecutionProvider"])
    params = EnvironmentParameters()
    params.set("time_penalty", lambda: time_penalty)
    game = make_task("dungeon", num_areas=areas, seed=seed, env_params=params)
    running, eaten, escaped = (np.ones(areas, bool), np.zeros(areas, bool), np.zeros(areas, bool))
    while running.any():
        obs = game.observe()[0]
        (actions,) = session.run(["discrete_actions"], {"obs_0": obs, "action_masks": np.ones((len(obs), 5), np.float32)})
        result = game.step(None, np.asarray(actions, np.int32).reshape(-1, 1))
        eaten |= running & ~game.dragon_there
        ended = running & result.done.reshape(areas, 3).all(axis=1)
        escaped |= ended & ~result.interrupted.reshape(areas, 3)[:, 0]
        running &= ~ended
        game.reset(result.done & np.repeat(running, 3))  # eaten agents start over, finished areas stay
    return {"eaten": float(eaten.mean()), "escaped": float(escaped.mean())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", choices=sorted(BEHAVIORS), default="pushblock")
    parser.add_argument("--max-steps", type=int, default=60000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--num-areas", type=int, default=8)
    parser.add_argument("--trainers", nargs="+", choices=["poca", "ppo"], default=["poca", "ppo"],
                        help="run only these (e.g. one process per trainer side by side)")
    parser.add_argument("--out", default=str(ROOT / "bench" / "out"))
    parser.add_argument("--env-param", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    try:
        env_params = {k: float(v) for k, v in (item.split("=", 1) for item in args.env_param)}
    except ValueError:
        sys.exit(f"--env-param takes KEY=NUMBER, got {args.env_param}")
    results: dict[str, dict[int, dict]] = {trainer_type: {} for trainer_type in args.trainers}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for trainer_type in results:
                results[trainer_type][seed] = run(args.task, trainer_type, seed, args.max_steps, args.num_areas, Path(tmp),
                                                     env_params)
                print(trainer_type, seed, results[trainer_type][seed], flush=True)
    success_tag = tags(args.task)[0]
    print(f"{args.task} {env_params}, {args.max_steps} steps, {args.num_areas} areas; mean of the last 3 summaries")
    probe = " eaten / escaped (probe) |" if args.task == "dungeon" else ""
    print(f"| trainer | seed | first step with success >= 0.9 | {success_tag} | Policy/Extrinsic Reward |{probe}")
    print("|---|---|---|---|---|" + ("---|" if probe else ""))
    for trainer_type, by_seed in results.items():
        for seed, curves in by_seed.items():
            last = [statistics.mean(v for _, v in curves[tag][-3:]) for tag in tags(args.task)]
            first = next((step for step, v in curves[success_tag] if v >= 0.9), None)
            row = f"| {trainer_type} | {seed} | {first or 'never'} | {last[0]:.3f} | {last[1]:.3f} |"
            if "probe" in curves:
                row += f" {curves['probe']['eaten']:.3f} / {curves['probe']['escaped']:.3f} |"
            print(row, flush=True)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, f"poca_vs_ppo_{args.task}.json"), "w") as stream:
        json.dump({"args": vars(args), "results": results}, stream, indent=1)


if __name__ == "__main__":
    main()
