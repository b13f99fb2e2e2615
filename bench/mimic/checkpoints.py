"""Every ONNX checkpoint of a mimic run through ``--evaluate``'s trials on one motion, oldest first.

    .venv/bin/python bench/mimic/checkpoints.py /tmp/mimic/results/squat_dom_s2 --motion 2
    .venv/bin/python bench/mimic/checkpoints.py /tmp/mimic/results/stand_push_s1 --motion 0 --push 15

Why: a squat clone's deterministic policy flips between tracking the clip (r_r ~0.9) and standing
still (r_r 0.28, the zero-action value) from one 20k-step checkpoint to the next, whatever the seed
(bench/RESULTS.md, 2026-11-27 "mimic: squat seeds"), so a run's last checkpoint is a coin toss; this
lists them all (balance kept, mean seconds, r_r, r_v, r_m, r_e; 16 trials from the clip's first
frame, seed 0: the numbers ``unity-stub-env --task mimic --evaluate`` prints for that motion).
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

from unity_stub_env.evaluate import load_policy
from unity_stub_env.tasks.mimic import OBSERVATION_SIZE, PUSH_EVAL_INTERVAL, MimicTask, run_trials


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", help="a run's results folder (holding Mimic/Mimic-STEP.onnx)")
    parser.add_argument("--motion", type=int, default=2, help="0 stand, 1 arms, 2 squat, 3 walk (default 2)")
    parser.add_argument("--push", type=float, default=0.0, help="push impulse, N s (default 0: none)")
    parser.add_argument("--interval", type=float, default=PUSH_EVAL_INTERVAL, help="s between pushes (default 2)")
    parser.add_argument("--trials", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    step = lambda path: int(re.search(r"-(\d+)\.onnx$", path.name).group(1))  # noqa: E731
    files = sorted(Path(args.run).glob("Mimic/Mimic-*.onnx"), key=step)
    if not files:
        parser.exit(2, f"checkpoints.py: no Mimic/Mimic-STEP.onnx under {args.run}: pass a run's results folder\n")
    print("| step | balance kept | mean s | r_r | r_v | r_m | r_e |\n|---:|---:|---:|---:|---:|---:|---:|")
    for path in files:
        act = load_policy(str(path), OBSERVATION_SIZE, MimicTask.action_spec.continuous_size, args.seed)
        r = run_trials(act, args.motion, args.trials, args.seed, args.push, args.interval)
        print(f"| {step(path)} | {r['balance_kept']:.3f} | {r['mean_seconds']:.2f} | "
              + " | ".join(f"{r[k]:.3f}" for k in ("r_r", "r_v", "r_m", "r_e")) + " |", flush=True)


if __name__ == "__main__":
    main()
