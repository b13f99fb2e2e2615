"""``mlagents-like-plot RESULTS... -o curves.png``: learning curves of runs from their TensorBoard files.

    mlagents-like-plot RESULTS... -o curves.png [--csv FILE] [--tag TAG] [--group REGEX]
                       [--smooth K] [--x steps|time]

RESULTS are run folders (results/RUN_ID) or a results folder holding many: every folder below them
that holds ``events.out.tfevents*`` files is one curve, named by its path relative to the argument
(``RUN_ID/Behavior``). A sweep's folder (results/sweeps/NAME, ``docker/slurm/sweep.sh``) gives its
runs named by their settings and seed, grouped by setting unless ``--group`` says otherwise. ``--tag`` (default ``Environment/Cumulative
Reward``) is the scalar drawn against the step or, with ``--x time``, the seconds since the run's
first summary. ``--smooth K``: each point is the mean of the last K summaries up to it (trailing;
fewer at the start). ``--group REGEX``: curves whose names give the same match (the first
parenthesised group if the pattern has one, else the whole match) are one group, drawn as its mean
with a 95 % confidence band (Student's t over the runs: mean +- t(0.975, n-1) s / sqrt(n)); a name
without a match is its own group. A group's runs are compared at the x values of its shortest run
inside the range all of them cover, linearly interpolated where a run has no summary there (runs
with the same summary_freq share their steps: no interpolation then).

``--csv FILE`` holds exactly the values drawn: curve, runs, x, y, y_low, y_high (the band; empty for a
single run). ``docker/slurm/sweep.sh summary`` aggregates its seeds with the same ``aggregate``.
Exit 2 with one message for no runs, an unknown tag or a bad pattern.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DEFAULT_TAG = "Environment/Cumulative Reward"
# Student's t at 0.975 for 1..30 degrees of freedom; beyond, the normal 1.96 is within 2 %
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145,
         2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048,
         2.045, 2.042)


class PlotError(ValueError):
    """Bad input: the message names it and what to do."""


@dataclass
class Curve:
    name: str
    x: np.ndarray
    y: np.ndarray
    low: np.ndarray | None = None  # the 95 % band of a group of runs
    high: np.ndarray | None = None
    runs: int = 1


def t975(dof: int) -> float:
    return _T975[dof - 1] if dof <= len(_T975) else 1.96


def _event_folders(root: Path) -> list[Path]:
    return sorted(Path(folder) for folder, _, files in os.walk(root)
                  if any(name.startswith("events.out.tfevents") for name in files))


def sweep_runs(folder: Path) -> dict[str, tuple[Path, str]]:
    """A sweep's runs (``docker/slurm/sweep.py``: plan.tsv beside, runs in results/NAME_i):
    {"<settings> seed <s>/<Behavior>": (event folder, "<settings>/<Behavior>")}: its seeds group."""
    import csv as _csv

    with open(folder / "plan.tsv", newline="") as f:
        rows = list(_csv.reader(f, delimiter="\t"))
    header, found = rows[0], {}
    results = folder.parent.parent
    for row in rows[1:]:
        settings = " ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(header[3:], row[3:])) or "default"
        run = results / row[1]
        for events in _event_folders(run) if run.is_dir() else []:
            behavior = str(events.relative_to(run))
            found[f"{settings} seed {row[2]}/{behavior}"] = (events, f"{settings}/{behavior}")
    return found


def find_runs(paths: list[str]) -> dict[str, tuple[Path, str]]:
    """{curve name: (folder holding event files, its default group)} below each of ``paths``,
    sorted by name. A run's default group is its own name; a sweep's runs group by setting."""
    found: dict[str, tuple[Path, str]] = {}
    for given in paths:
        root = Path(given)
        if not root.is_dir():
            raise PlotError(f"{given!r} is not a folder: give run folders (results/RUN_ID) or a results folder")
        if (root / "plan.tsv").is_file():
            found.update(sweep_runs(root))
            continue
        for folder in _event_folders(root):
            relative = folder.relative_to(root)
            name = str(Path(root.name) / relative) if str(relative) != "." else root.name
            found[name] = (folder, name)
    if not found:
        raise PlotError(f"no TensorBoard event files under {', '.join(paths)}: is it a run's folder "
                        "(results/RUN_ID) after its first summary?")
    return dict(sorted(found.items()))


def read_scalars(folder: Path, tag: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(steps, wall times, values) of ``tag`` in ``folder``'s event files, or None if it has none."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    accumulator = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    accumulator.Reload()
    if tag not in accumulator.Tags()["scalars"]:
        return None
    events = accumulator.Scalars(tag)
    return (np.array([e.step for e in events], np.float64), np.array([e.wall_time for e in events], np.float64),
            np.array([e.value for e in events], np.float64))


def smooth(values: np.ndarray, k: int) -> np.ndarray:
    """The trailing mean of the last ``k`` values at each point (fewer at the start)."""
    if k <= 1:
        return values.copy()
    sums = np.cumsum(np.concatenate([[0.0], values]))
    index = np.arange(1, len(values) + 1)
    start = np.maximum(index - k, 0)
    return (sums[index] - sums[start]) / (index - start)


def aggregate(name: str, runs: list[tuple[np.ndarray, np.ndarray]]) -> Curve:
    """The mean of the runs [(x, y)] with its 95 % band, at the x of the shortest run inside the
    range every run covers (np.interp where a run has no point there)."""
    if len(runs) == 1:
        x, y = runs[0]
        return Curve(name, x.copy(), y.copy())
    lo, hi = max(x[0] for x, _ in runs), min(x[-1] for x, _ in runs)
    shortest = min(runs, key=lambda run: len(run[0]))[0]
    grid = shortest[(shortest >= lo) & (shortest <= hi)]
    if len(grid) == 0:
        grid = np.array([hi])
    table = np.array([np.interp(grid, x, y) for x, y in runs])
    n = len(runs)
    mean = table.mean(axis=0)
    half = t975(n - 1) * table.std(axis=0, ddof=1) / math.sqrt(n)
    return Curve(name, grid, mean, mean - half, mean + half, n)


def group_key(name: str, pattern: re.Pattern | None, default: str) -> str:
    if pattern is None:
        return default
    match = pattern.search(name)
    if match is None:
        return name
    return match.group(1) if pattern.groups else match.group(0)


def curves(paths: list[str], tag: str = DEFAULT_TAG, group: str | None = None, k: int = 1,
           x_axis: str = "steps") -> list[Curve]:
    """The curves ``main`` draws: one per run, or one per group."""
    try:
        pattern = re.compile(group) if group else None
    except re.error as error:
        raise PlotError(f"--group {group!r} is not a regular expression ({error})") from None
    groups: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    tags_missing = []
    for name, (folder, default_group) in find_runs(paths).items():
        scalars = read_scalars(folder, tag)
        if scalars is None or len(scalars[0]) == 0:
            tags_missing.append(name)
            continue
        steps, wall, values = scalars
        x = steps if x_axis == "steps" else wall - wall[0]
        groups.setdefault(group_key(name, pattern, default_group), []).append((x, smooth(values, k)))
    if not groups:
        raise PlotError(f"no run has the scalar {tag!r} (runs: {', '.join(tags_missing)}); pick one with --tag")
    return [aggregate(key, runs) for key, runs in groups.items()]


def write_csv(path: str, drawn: list[Curve]) -> None:
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["curve", "runs", "x", "y", "y_low", "y_high"])
        for c in drawn:
            for i in range(len(c.x)):
                band = ["", ""] if c.low is None else [repr(float(c.low[i])), repr(float(c.high[i]))]
                out.writerow([c.name, c.runs, repr(float(c.x[i])), repr(float(c.y[i])), *band])


def draw(path: str, drawn: list[Curve], tag: str, x_axis: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 5), dpi=100)
    for c in drawn:
        label = c.name if c.runs == 1 else f"{c.name} (mean of {c.runs}, 95 % CI)"
        line, = axes.plot(c.x, c.y, label=label, linewidth=1.5)
        if c.low is not None:
            axes.fill_between(c.x, c.low, c.high, color=line.get_color(), alpha=0.2, linewidth=0)
    axes.set_xlabel("step" if x_axis == "steps" else "seconds since the first summary")
    axes.set_ylabel(tag)
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="mlagents-like-plot", description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", help="run folders, a results folder or a sweep's folder")
    parser.add_argument("-o", "--output", required=True, help="the picture to write (.png, .svg, .pdf)")
    parser.add_argument("--csv", default=None, metavar="FILE", help="also write the drawn values as CSV")
    parser.add_argument("--tag", default=DEFAULT_TAG, help=f"the scalar to draw (default {DEFAULT_TAG!r})")
    parser.add_argument("--group", default=None, metavar="REGEX",
                        help="runs matching alike are one curve, mean with a 95%% band, e.g. '(.*)-seed'")
    parser.add_argument("--smooth", type=int, default=1, metavar="K", help="trailing mean over K summaries")
    parser.add_argument("--x", dest="x_axis", choices=("steps", "time"), default="steps")
    args = parser.parse_args(argv)
    try:
        if args.smooth < 1:
            raise PlotError(f"--smooth must be 1 or more, got {args.smooth}")
        drawn = curves(args.results, args.tag, args.group, args.smooth, args.x_axis)
        for target in (args.output, args.csv):
            if target and not Path(target).resolve().parent.is_dir():
                raise PlotError(f"{target!r}: its folder does not exist")
        draw(args.output, drawn, args.tag, args.x_axis)
        if args.csv:
            write_csv(args.csv, drawn)
    except (PlotError, OSError) as error:
        print(f"mlagents-like-plot: {error}", file=sys.stderr)
        return 2
    print(f"Wrote {args.output}: {len(drawn)} curve(s)" + (f", values in {args.csv}" if args.csv else ""))
    return 0


def entry() -> None:
    sys.exit(main())


if __name__ == "__main__":
    entry()
