"""MA-POCA vs independent PPO on the cooperative stub task ``pushblock`` at equal steps (run by hand).

    nice -n 10 .venv/bin/python bench/poca_vs_ppo.py [--max-steps 60000] [--seeds 1 2 3] [--num-areas 8]
        [--env-param block_friction=12 ...]

configs/pushblock_poca.yaml is run as shipped (``trainer_type: poca``) and with ``trainer_type: ppo``
and nothing else changed (the same hyperparameters, network, seeds, areas and steps). Independent
PPO gets the same group rewards (the rollout adds them to each agent's reward) but its critic sees
one agent only and its advantages carry no counterfactual baseline. Reported per trainer and seed,
read back from TensorBoard: ``PushBlock/Success`` (the fraction of group episodes that brought the
block home) and ``Policy/Extrinsic Reward`` (each agent's episode return, group rewards included) at
every summary; the table gives the first summary step with a success rate >= 0.9 and the mean of
the last 3 summaries. ``--env-param KEY=VALUE`` adds a constant environment parameter of the task
(``block_friction``, ``progress_reward``: unity_stub_env/tasks/pushblock.py) to both configs. JSON to ``<out>/poca_vs_ppo.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

ROOT = Path(__file__).resolve().parent.parent
TAGS = ("PushBlock/Success", "Policy/Extrinsic Reward")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def run(trainer_type: str, seed: int, max_steps: int, areas: int, work: Path,
        env_params: dict[str, float]) -> dict[str, list[tuple[int, float]]]:
    text = (ROOT / "configs" / "pushblock_poca.yaml").read_text()
    text = text.replace("trainer_type: poca", f"trainer_type: {trainer_type}").replace(
        "max_steps: 60000", f"max_steps: {max_steps}")
    if env_params:
        text += "environment_parameters:\n" + "".join(f"  {k}: {v}\n" for k, v in env_params.items())
    config = work / f"{trainer_type}.yaml"
    config.write_text(text)
    run_id = f"{trainer_type}-{seed}"
    cmd = [str(ROOT / ".venv" / "bin" / "mlagents-like-learn"), str(config), "--env", "stub:pushblock",
           "--num-areas", str(areas), "--seed", str(seed), "--run-id", run_id, "--results-dir", str(work),
           "--base-port", str(free_port())]
    done = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    if done.returncode != 0:
        sys.exit(f"{run_id} failed:\n{done.stderr[-3000:]}")
    acc = EventAccumulator(str(work / run_id / "PushBlock"), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [(e.step, round(e.value, 4)) for e in acc.Scalars(tag)] for tag in TAGS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-steps", type=int, default=60000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--num-areas", type=int, default=8)
    parser.add_argument("--out", default=str(ROOT / "bench" / "out"))
    parser.add_argument("--env-param", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    try:
        env_params = {k: float(v) for k, v in (item.split("=", 1) for item in args.env_param)}
    except ValueError:
        sys.exit(f"--env-param takes KEY=NUMBER, got {args.env_param}")
    results: dict[str, dict[int, dict]] = {"poca": {}, "ppo": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for trainer_type in results:
                results[trainer_type][seed] = run(trainer_type, seed, args.max_steps, args.num_areas, Path(tmp),
                                                     env_params)
                print(trainer_type, seed, results[trainer_type][seed], flush=True)
    print(f"pushblock {env_params}, {args.max_steps} steps, {args.num_areas} areas; mean of the last 3 summaries")
    print("| trainer | seed | first step with success >= 0.9 | PushBlock/Success | Policy/Extrinsic Reward |")
    print("|---|---|---|---|---|")
    for trainer_type, by_seed in results.items():
        for seed, curves in by_seed.items():
            last = [statistics.mean(v for _, v in curves[tag][-3:]) for tag in TAGS]
            first = next((step for step, v in curves[TAGS[0]] if v >= 0.9), None)
            print(f"| {trainer_type} | {seed} | {first or 'never'} | {last[0]:.3f} | {last[1]:.3f} |", flush=True)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "poca_vs_ppo.json"), "w") as stream:
        json.dump({"args": vars(args), "results": results}, stream, indent=1)


if __name__ == "__main__":
    main()
