"""Our UnityEnvironment (mlagents_like_envs) against the real mlagents_envs 1.1.0's, exchanges/s.

    .venv/bin/python bench/envs_api.py [--rounds 3] [--exchanges 1000] [--warmup 100] [--areas 1 16 64]

Both run the very same user loop — get_steps, ``random_action`` for the deciding agents,
set_actions, step (bench/peers/mlagents_envs_rollout.py, imported under each package's name) —
each in its own process (mlagents_envs in .venv-interop), against the same stub build of
``basic`` with ``--areas`` agents. The two alternate, round after round, so a machine whose load
changes during the run slows both alike; the ratio of each round and their median are printed,
and the JSON goes to bench/out/envs_api-<time>.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from protocol import OUT, bench_mlagents_envs  # noqa: E402

PACKAGES = ("mlagents_like_envs", "mlagents_envs")


def run(args) -> dict:
    report = {"when": time.strftime("%Y-%m-%d %H:%M:%S"), "python": platform.python_version(),
              "cpu_count": os.cpu_count(), "load_average": os.getloadavg(), "args": vars(args), "areas": {}}
    for areas in args.areas:
        rounds = []
        for _ in range(args.rounds):
            rates = {}
            for package in PACKAGES:
                record = bench_mlagents_envs("basic", areas, args.warmup, args.exchanges, package=package)
                if record is None:
                    raise SystemExit("bench/envs_api.py needs .venv-interop (scripts/ensure_interop_venv.sh)")
                rates[package] = record["exchanges"] / record["seconds"]
            rounds.append(rates)
        ratios = [r["mlagents_like_envs"] / r["mlagents_envs"] for r in rounds]
        report["areas"][areas] = {"rounds": rounds, "ratios": ratios, "median_ratio": statistics.median(ratios)}
    report["load_average_after"] = os.getloadavg()
    return report


def markdown(report: dict) -> str:
    lines = ["| basic agents | mlagents_like_envs exchanges/s | mlagents_envs exchanges/s | ratio per round | median |",
             "|---:|---:|---:|---|---:|"]
    for areas, row in report["areas"].items():
        ours = statistics.median(r["mlagents_like_envs"] for r in row["rounds"])
        theirs = statistics.median(r["mlagents_envs"] for r in row["rounds"])
        per_round = ", ".join(f"{x:.2f}" for x in row["ratios"])
        lines.append(f"| {areas} | {ours:,.0f} | {theirs:,.0f} | {per_round} | **{row['median_ratio']:.2f}x** |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--exchanges", type=int, default=1000)
    parser.add_argument("--warmup", type=int, default=100)
    parser.add_argument("--areas", type=int, nargs="+", default=[1, 16, 64], help="basic agent counts")
    args = parser.parse_args()
    report = run(args)
    table = markdown(report)
    print(table)
    OUT.mkdir(exist_ok=True)
    path = OUT / f"envs_api-{time.strftime('%Y%m%d-%H%M%S')}.json"
    report["markdown"] = table
    path.write_text(json.dumps(report, indent=1, default=str))
    print(f"\nwrote {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
