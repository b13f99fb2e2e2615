"""Seed and hyperparameter sweeps as one Slurm job array of docker/slurm/train.sbatch.

    docker/slurm/sweep.sh CONFIG --seeds 1-5 [--set behaviors.X.hyperparameters.lambd=0.9,0.95 ...]
                          [--name NAME] [--results-dir results] [--sbatch "--time=4:00:00 ..."]
                          [--dry-run] [-- mlagents-like-learn arguments]
    docker/slurm/sweep.sh summary results/sweeps/NAME

Every combination of the --set values with every seed is one array element (seeds x values of
each --set). For element i the sweep writes results/sweeps/NAME/element-i.yaml (CONFIG with the
overrides and env_settings.seed) and plan.tsv (what each element is); train.sbatch runs element i
as run NAME_i (results/NAME_i). ``summary`` prints a table of the final mean reward of each
element (the last "Environment/Cumulative Reward" TensorBoard summary of each behavior).
docs/cluster.md explains it with examples.
"""
from __future__ import annotations

import argparse
import copy
import csv
import itertools
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import yaml

TEMPLATE = Path(__file__).resolve().parent / "train.sbatch"


class SweepError(Exception):
    pass


def parse_seeds(text: str) -> list[int]:
    """"1-5" -> [1..5]; "1,4,9" and "1-3,10" work too."""
    seeds: list[int] = []
    for part in text.split(","):
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not m:
            raise SweepError(f"--seeds {text!r}: use a range like 1-5 or a list like 1,4,9")
        low, high = int(m.group(1)), int(m.group(2) or m.group(1))
        if high < low:
            raise SweepError(f"--seeds {text!r}: {low}-{high} is an empty range")
        seeds.extend(range(low, high + 1))
    if len(set(seeds)) != len(seeds):
        raise SweepError(f"--seeds {text!r} names a seed twice")
    return seeds


def parse_set(text: str) -> tuple[str, list]:
    """"behaviors.X.hyperparameters.lambd=0.9,0.95" -> (key, [0.9, 0.95]) (values as YAML)."""
    key, sep, values = text.partition("=")
    if not sep or not key or not values:
        raise SweepError(f"--set {text!r}: use --set dotted.key=VALUE1,VALUE2")
    return key, [yaml.safe_load(v) for v in values.split(",")]


def apply_override(config: dict, key: str, value) -> None:
    parts = key.split(".")
    if parts[0] == "behaviors" and len(parts) > 1 and parts[1] not in (config.get("behaviors") or {}):
        raise SweepError(f"--set {key}: the config has no behavior {parts[1]!r}")
    node = config
    for i, part in enumerate(parts[:-1]):
        child = node.get(part)
        if child is None:
            child = node[part] = {}
        if not isinstance(child, dict):
            raise SweepError(f"--set {key}: {'.'.join(parts[:i + 1])} is not a mapping in the config")
        node = child
    node[parts[-1]] = value


def plan(config: dict, seeds: list[int], sets: list[tuple[str, list]]) -> list[tuple[int, dict, dict]]:
    """[(seed, {key: value}, element config)] in array order: overrides outer, seeds inner."""
    elements = []
    for values in itertools.product(*[v for _, v in sets]):
        overrides = dict(zip([k for k, _ in sets], values))
        for seed in seeds:
            element = copy.deepcopy(config)
            for key, value in overrides.items():
                apply_override(element, key, value)
            element.setdefault("env_settings", {})
            element["env_settings"]["seed"] = seed
            elements.append((seed, overrides, element))
    return elements


def submit(args: argparse.Namespace, learn_args: list[str]) -> int:
    config_path = Path(args.config)
    if not config_path.is_file():
        raise SweepError(f"config {args.config} not found")
    config = yaml.safe_load(config_path.read_text()) or {}
    if any(a == "--seed" or a.startswith("--seed=") or a == "--run-id" or a.startswith("--run-id=")
           for a in learn_args):
        raise SweepError("the sweep sets the seed and the run id of each element: leave --seed and --run-id out")
    seeds = parse_seeds(args.seeds)
    sets = [parse_set(s) for s in args.set]
    elements = plan(config, seeds, sets)
    name = args.name or f"{config_path.stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    folder = Path(args.results_dir) / "sweeps" / name
    if folder.exists():
        raise SweepError(f"{folder} exists already: pick another --name")
    folder.mkdir(parents=True)
    with open(folder / "plan.tsv", "w", newline="") as f:
        out = csv.writer(f, delimiter="\t")
        out.writerow(["element", "run_id", "seed", *[k for k, _ in sets]])
        for i, (seed, overrides, element) in enumerate(elements):
            (folder / f"element-{i}.yaml").write_text(yaml.safe_dump(element, sort_keys=False))
            out.writerow([i, f"{name}_{i}", seed, *[overrides[k] for k, _ in sets]])
    cmd = ["sbatch", f"--array=0-{len(elements) - 1}", f"--job-name={name}", *shlex.split(args.sbatch or ""),
           str(TEMPLATE),
           str(folder / "element-%a.yaml"), "--run-id", name, "--results-dir", args.results_dir, *learn_args]
    print(f"sweep {name}: {len(elements)} elements ({len(seeds)} seeds x "
          f"{len(elements) // len(seeds)} settings), plan in {folder / 'plan.tsv'}")
    print(" ".join(shlex.quote(c) for c in cmd))
    if args.dry_run:
        return 0
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SweepError(f"sbatch failed: {done.stderr.strip()}")
    job = done.stdout.strip().split()[-1].split(";")[0]
    (folder / "job_id").write_text(job + "\n")
    print(f"submitted job array {job}; when it ends: docker/slurm/sweep.sh summary {folder}")
    return 0


def final_rewards(run_dir: Path) -> dict[str, tuple[int, float | None]]:
    """{behavior: (last summary step, last mean reward)} from the run's TensorBoard files (read as
    mlagents-like-plot reads them)."""
    from trainer.plot import DEFAULT_TAG, read_scalars

    out = {}
    if not run_dir.is_dir():
        return out
    for child in sorted(run_dir.iterdir()):
        if not child.is_dir() or not any(n.startswith("events.out.tfevents") for n in os.listdir(child)):
            continue
        scalars = read_scalars(child, DEFAULT_TAG)
        out[child.name] = (0, None) if scalars is None or not len(scalars[0]) else \
            (int(scalars[0][-1]), float(scalars[2][-1]))
    return out


def summary(folder: Path) -> int:
    plan_file = folder / "plan.tsv"
    if not plan_file.is_file():
        raise SweepError(f"{plan_file} not found: give the sweep's folder (results/sweeps/NAME)")
    with open(plan_file, newline="") as f:
        rows = list(csv.reader(f, delimiter="\t"))
    header, rows = rows[0], rows[1:]
    results_dir = folder.parent.parent
    table = [header + ["behavior", "step", "final reward"]]
    for row in rows:
        rewards = final_rewards(results_dir / row[1])
        if not rewards:
            table.append(row + ["-", "-", "no results yet"])
        for behavior, (step, reward) in rewards.items():
            table.append(row + [behavior, str(step), "-" if reward is None else f"{reward:.4f}"])
    _print_table(table)
    grouped = _seed_means(folder)
    if grouped:
        print("\nmean over seeds at the last step every seed reached (mlagents-like-plot's aggregation: "
              "mlagents-like-plot FOLDER -o curves.png draws these curves)")
        _print_table([["setting/behavior", "seeds", "step", "mean reward", "95% CI"]] + grouped)
    return 0


def _print_table(table: list[list[str]]) -> None:
    widths = [max(len(str(r[i])) for r in table) for i in range(len(table[0]))]
    for r in table:
        print("  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip())


def _seed_means(folder: Path) -> list[list[str]]:
    """Per setting and behavior, the last point of mlagents-like-plot's curve of the sweep: the mean
    of its seeds' rewards and the 95 % band (trainer.plot.aggregate), so table and plot agree."""
    from trainer.plot import PlotError, curves

    try:
        drawn = curves([str(folder)])
    except PlotError:
        return []
    rows = []
    for c in drawn:
        band = "-" if c.low is None else f"{c.low[-1]:.4f} .. {c.high[-1]:.4f}"
        rows.append([c.name, str(c.runs), f"{c.x[-1]:g}", f"{c.y[-1]:.4f}", band])
    return rows


def main(argv: list[str]) -> int:
    if argv[:1] == ["summary"]:
        if len(argv) != 2:
            raise SweepError("usage: sweep.sh summary results/sweeps/NAME")
        return summary(Path(argv[1]))
    learn_args: list[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, learn_args = argv[:cut], argv[cut + 1:]
    parser = argparse.ArgumentParser(prog="sweep.sh", description=__doc__.split("\n\n")[0])
    parser.add_argument("config")
    parser.add_argument("--seeds", required=True, help="1-5, or 1,4,9")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2",
                        help="a dotted config key and its values (repeatable)")
    parser.add_argument("--name", help="sweep name (default: CONFIG stem and the time)")
    parser.add_argument("--results-dir", default="results")
    parser.add_argument("--sbatch", default="", help="extra sbatch options, one string")
    parser.add_argument("--dry-run", action="store_true", help="write the plan, print the sbatch command")
    return submit(parser.parse_args(argv), learn_args)


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except SweepError as error:
        print(f"sweep.sh: error: {error}", file=sys.stderr)
        sys.exit(2)
