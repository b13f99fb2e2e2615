"""A mimic run's learning curve as a markdown table, read back from its TensorBoard files.

    .venv/bin/python bench/mimic/curve.py RESULTS/RUN_ID/Mimic [--every 50000] [--decision-hz 50]

Works for our trainer's and mlagents-learn's results alike (the same summaries). Per summary step
kept (every ``--every`` agent steps, and the last): wall time since the first summary, mean episode
return, mean episode length (decisions), the return as a percentage of the maximum (one per
decision over a full 10 s episode: 10 x decision_hz), r_r, the pose term's episode mean, and the
policy's std before the clip (exp(entropy - 0.5 ln(2 pi e)), from the last Policy/Entropy summary at
or before that step: the entropy is the mean over the action axes, 1.419 at std 1).
"""
from __future__ import annotations

import argparse
import bisect
import math
import sys
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

TAGS = {"return": "Environment/Cumulative Reward", "length": "Environment/Episode Length", "r_r": "Mimic/r_r",
        "entropy": "Policy/Entropy"}
UNIT_ENTROPY = 0.5 * math.log(2 * math.pi * math.e)  # a Gaussian's entropy per axis at std 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("behavior_dir", type=Path)
    parser.add_argument("--every", type=int, default=50000)
    parser.add_argument("--decision-hz", type=float, default=50.0)
    args = parser.parse_args()
    events = EventAccumulator(str(args.behavior_dir), size_guidance={"scalars": 0})
    events.Reload()
    have = events.Tags().get("scalars", [])
    if TAGS["return"] not in have:
        print(f"{args.behavior_dir}: no summaries yet", file=sys.stderr)
        return 2
    series = {key: {e.step: e for e in events.Scalars(tag)} for key, tag in TAGS.items() if tag in have}
    steps = sorted(series["return"])
    start = series["return"][steps[0]].wall_time
    kept = [s for s in steps if s % args.every == 0 or s == steps[-1] or s == steps[0]]
    maximum = 10.0 * args.decision_hz
    entropy_steps = sorted(series.get("entropy", {}))
    print("| agent steps | wall h | mean return | episode length | % of max | r_r | policy std |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for s in kept:
        ret = series["return"][s].value
        length = series.get("length", {}).get(s)
        r_r = series.get("r_r", {}).get(s)
        before = bisect.bisect_right(entropy_steps, s)
        std = math.exp(series["entropy"][entropy_steps[before - 1]].value - UNIT_ENTROPY) if before else float("nan")
        print(f"| {s} | {(series['return'][s].wall_time - start) / 3600:.2f} | {ret:.2f} | "
              f"{length.value if length else float('nan'):.1f} | {100 * ret / maximum:.2f} | "
              f"{r_r.value if r_r else float('nan'):.3f} | {std:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
