"""The runner task (docs/stub-tasks.md): completion rate on 100 held-out generated tracks, trained vs untrained.

    .venv/bin/python bench/runner.py --train                 # train configs/runner.yaml (200k steps), then evaluate
    .venv/bin/python bench/runner.py --onnx results/runner/Runner.onnx   # evaluate a run you already have

Training: ``mlagents-like-learn configs/runner.yaml --env stub:runner --num-areas 4 --seed S``
(16 agents; the tracks it trains on have seeds drawn in [0, 1e6) by the task's RNG). Evaluation:
the trained policy (its mean action, through onnxruntime), the zero action and uniform random
steering drive once along each of the tracks with seeds 1e6 .. 1e6 + 99, never used in training,
first with the default zones (3 zones of 4..8 platforms), then with longer zones (4..16). Prints a
markdown table and writes bench/out/runner.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from unity_stub_env.evaluate import load_policy  # noqa: E402
from unity_stub_env.tasks import runner  # noqa: E402

SETTINGS = {"default zones (4..8)": {}, "long zones (4..16)": {"zone_length_max": 16}}


def train(results: str, seed: int, run_id: str) -> str:
    command = [os.path.join(ROOT, ".venv", "bin", "mlagents-like-learn"), os.path.join(ROOT, "configs", "runner.yaml"),
               "--env", "stub:runner", "--num-areas", "4", "--seed", str(seed), "--run-id", run_id,
               "--results-dir", results, "--force"]
    start = time.time()
    subprocess.run(command, check=True, cwd=ROOT)
    print(f"trained in {time.time() - start:.0f} s wall: {' '.join(command)}")
    return os.path.join(results, run_id, "Runner.onnx")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--train", action="store_true", help="train configs/runner.yaml first")
    parser.add_argument("--onnx", default=None, help="evaluate this trained policy")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--results-dir", default=os.path.join(ROOT, "results"))
    parser.add_argument("--tracks", type=int, default=100)
    args = parser.parse_args()
    onnx = train(args.results_dir, args.seed, "runner-bench") if args.train else args.onnx
    policies = {"trained": onnx} if onnx else {}
    policies.update({"zero action": "zero", "random steering": "random"})
    seeds = range(runner.HELD_OUT_SEED_START, runner.HELD_OUT_SEED_START + args.tracks)
    rows = []
    print("| policy | tracks | completion rate | mean platforms passed | mean obstacles hit | mean return |")
    print("|---|---|---:|---:|---:|---:|")
    for name, spec in policies.items():
        act = load_policy(spec, runner.OBS_SIZE, 1, seed=0)
        for label, settings in SETTINGS.items():
            result = runner.evaluate_tracks(act, seeds, **settings)
            rows.append({"policy": name, "source": spec, "tracks": label, **result})
            print(f"| {name} | {args.tracks} held out, {label} | {result['completion_rate']:.2f} | "
                  f"{result['mean_platforms_passed']:.1f} | {result['mean_obstacles_hit']:.2f} | "
                  f"{result['mean_return']:.2f} |", flush=True)
    out = os.path.join(ROOT, "bench", "out")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "runner.json"), "w") as handle:
        json.dump({"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "rows": rows}, handle, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
