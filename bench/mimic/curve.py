"""A mimic run's learning curve as a markdown table, read back from its TensorBoard files.

    .venv/bin/python bench/mimic/curve.py RESULTS/RUN_ID/Mimic [--every 50000] [--decision-hz 50]

Works for our trainer's and mlagents-learn's results alike (the same summaries). Per summary step
kept (every ``--every`` agent steps, and the last): wall time since the first summary, mean episode
return, mean episode length (decisions), the return as a percentage of the maximum (one per
decision over a full 10 s episode: 10 x decision_hz), and r_r, the pose term's episode mean.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

TAGS = {"return": "Environment/Cumulative Reward", "length": "Environment/Episode Length", "r_r": "Mimic/r_r"}


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
    print("| agent steps | wall h | mean return | episode length | % of max | r_r |")
    print("|---:|---:|---:|---:|---:|---:|")
    for s in kept:
        ret = series["return"][s].value
        length = series.get("length", {}).get(s)
        r_r = series.get("r_r", {}).get(s)
        print(f"| {s} | {(series['return'][s].wall_time - start) / 3600:.2f} | {ret:.2f} | "
              f"{length.value if length else float('nan'):.1f} | {100 * ret / maximum:.2f} | "
              f"{r_r.value if r_r else float('nan'):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
