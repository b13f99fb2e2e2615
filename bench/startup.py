"""Start-up benchmark (run by hand, not a test): where the time before the first step goes.

    .venv/bin/python bench/startup.py [--runs 3] [--out bench/out]

Two jobs, each run --runs times by our trainer and by the client-only floor, alternating:
  basic     ``--env stub:basic``, configs/basic.yaml with max_steps 2,000
  2x20k     ``--env stub:mirror=bench/startup/two_behaviors.json``: two behaviors (Reach: 12 floats,
            3 continuous; Seek: 8 floats, branches 3 and 2) of 8 agents each, 20,000 steps each,
            bench/startup/two_behaviors.yaml (the shape of the held-out client of docs/cluster.md's
            start-up note; bench/train.py runs the same job against mlagents-learn)

The timeline of one run, in seconds since the process started (the bench's clock just before
``Popen``; every mark is wall-clock time, the trainer's from its ``--debug`` log lines, the
simulator's from its own log, Player-0.log):
  imports    torch and the trainer's modules imported ("Start-up: ... imported")
  launch     the simulator started ("Launching ...")
  connected  the simulator's handshake answered ("Connected to Unity environment ...")
  first step the first actions sent ("Start-up: first actions sent")
  first upd  the first PPO update done ("Start-up: first update done")
  exit       the process exited
and the simulator's own connect time: from its launch to its "Connected to trainer" line.

The client-only floor (``floor``, run here as a subprocess): the same simulator driven by the
smallest trainer side we can write with our own transport (trainer/envs/pool.py: listen, launch,
handshake, reset, then zero actions for every agent until every behavior has its steps, close;
no torch, no networks, no files). Its simulator connect time is the simulator's own (the driver
waits for nothing else); its wall time is the floor of the whole job; ``ours`` reaches
floor ÷ ours of it.

Reported (medians over the runs): the timelines; the trainer's part of the time to the first
step, ``first step - the floor's simulator connect time`` (target: at most 0.3 s); the share of
the floor, ``floor wall ÷ our wall``. Writes JSON to <out>/startup.json.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent / "startup"
JOBS = {
    "basic": {"env": "stub:basic", "config": "configs/basic.yaml", "max_steps": 2000},
    "2x20k": {"env": f"stub:mirror={HERE / 'two_behaviors.json'}", "config": "bench/startup/two_behaviors.yaml",
              "max_steps": 20000},
}
# the trainer's --debug lines that mark the timeline (trainer/run.py, trainer/envs/launcher.py, pool.py)
MARKS = {
    "imports": "Start-up: torch and the trainer's modules imported",
    "launch": "Launching ",
    "connected": "Connected to Unity environment",
    "first_step": "Start-up: first actions sent",
    "first_update": "Start-up: first update done",
}
STAMP = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) ")


def stamp(line: str) -> float | None:
    """The wall-clock time of a log line written with logging's asctime (local time, ms)."""
    found = STAMP.match(line)
    return datetime.strptime(found.group(1), "%Y-%m-%d %H:%M:%S,%f").timestamp() if found else None


def first_marks(text: str, marks: dict[str, str]) -> dict[str, float]:
    found: dict[str, float] = {}
    for line in text.splitlines():
        for key, needle in marks.items():
            if key not in found and needle in line:
                when = stamp(line)
                if when is not None:
                    found[key] = when
    return found


def env_for_children() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.lower().endswith("_proxy")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    return env


def free_port() -> int:
    from tests.integration.conftest import free_port_block

    return free_port_block(2)


def job_config(job: str, folder: Path) -> Path:
    import yaml

    spec = JOBS[job]
    config = yaml.safe_load((ROOT / spec["config"]).read_text())
    for section in [config.get("default_settings"), *config["behaviors"].values()]:
        if section:
            section["max_steps"] = spec["max_steps"]
            section["checkpoint_interval"] = 100 * spec["max_steps"]
    path = folder / f"{job}.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def simulator_connect(run_logs: Path, launched: float | None) -> float | None:
    """The simulator's own time from its launch to its "Connected to trainer" line."""
    log = run_logs / "Player-0.log"
    if launched is None or not log.exists():
        return None
    connected = first_marks(log.read_text(errors="replace"), {"c": "Connected to trainer"}).get("c")
    return None if connected is None else connected - launched


def run_ours(job: str, folder: Path, label: str) -> dict:
    config = job_config(job, folder)
    results = folder / "results"
    command = [sys.executable, "-m", "trainer.cli", str(config), "--env", JOBS[job]["env"], "--run-id", label,
               "--results-dir", str(results), "--base-port", str(free_port()), "--seed", "1", "--debug"]
    started = time.time()
    done = subprocess.run(command, cwd=folder, env=env_for_children(), capture_output=True, text=True, timeout=1800)
    ended = time.time()
    text = done.stdout + done.stderr
    marks = {key: when - started for key, when in first_marks(text, MARKS).items()}
    marks["exit"] = ended - started
    sim = simulator_connect(results / label / "run_logs", started + marks["launch"] if "launch" in marks else None)
    return {"who": "ours", "job": job, "code": done.returncode, "marks": marks, "simulator_connect_s": sim,
            "tail": text[-1500:] if done.returncode else ""}


def run_floor(job: str, folder: Path, label: str) -> dict:
    run_logs = folder / label / "run_logs"
    command = [sys.executable, str(Path(__file__).resolve()), "floor", "--env", JOBS[job]["env"],
               "--steps", str(JOBS[job]["max_steps"]), "--base-port", str(free_port()), "--log-folder", str(run_logs)]
    started = time.time()
    done = subprocess.run(command, cwd=folder, env=env_for_children(), capture_output=True, text=True, timeout=1800)
    ended = time.time()
    if done.returncode:
        return {"who": "floor", "job": job, "code": done.returncode, "marks": {"exit": ended - started},
                "simulator_connect_s": None, "tail": (done.stdout + done.stderr)[-1500:]}
    reported = json.loads(done.stdout.strip().splitlines()[-1])
    marks = {key: when - started for key, when in reported["marks"].items()}
    marks["exit"] = ended - started
    sim = simulator_connect(run_logs, reported["marks"].get("launch"))
    return {"who": "floor", "job": job, "code": 0, "marks": marks, "simulator_connect_s": sim,
            "steps": reported["steps"]}


# --------------------------------------------------------------------------------- the floor
def floor(args) -> int:
    """The client-only floor: our transport and the simulator, zero actions, nothing else."""
    started = time.time()
    import numpy as np

    from protos.types import ActionTuple
    from trainer.envs.pool import EnvPool, PoolSettings

    task = args.env.split(":", 1)[1]
    os.makedirs(args.log_folder, exist_ok=True)
    settings = PoolSettings(env_path=f"stub:{task}", env_args=(), base_port=args.base_port, num_envs=1, num_areas=1,
                            seed=1, timeout_wait=60, bind="127.0.0.1", no_graphics=True, no_graphics_monitor=False,
                            log_folder=args.log_folder)
    pool = EnvPool(settings, initial_side_channel=lambda: b"")
    marks = {"start": started, "imports": time.time()}
    steps: dict[str, int] = {}
    try:
        pool.launch()
        marks["launch"] = time.time()
        pool.connect()
        marks["connected"] = time.time()
        results = pool.reset(b"")
        specs = pool.behavior_specs()
        while True:
            actions = []
            for result in results:
                chosen = {}
                for name, (decisions, _terminal) in result.steps.items():
                    n = len(decisions)
                    steps[name] = steps.get(name, 0) + n
                    spec = specs[name].action_spec
                    chosen[name] = ActionTuple(np.zeros((n, spec.continuous_size), np.float32),
                                               np.zeros((n, len(spec.discrete_branches)), np.int32))
                actions.append(chosen)
            if steps and min(steps.values()) >= args.steps:
                break
            pool.send_step(actions, b"")
            marks.setdefault("first_step", time.time())
            results = pool.receive().results
    finally:
        pool.close()
    print(json.dumps({"marks": marks, "steps": steps}))
    return 0


# --------------------------------------------------------------------------------- report
def median(values: list) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def fmt(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def report(runs: list[dict]) -> tuple[str, dict]:
    keys = ["imports", "launch", "connected", "first_step", "first_update", "exit"]
    lines = ["| job | who | runs | " + " | ".join(keys) + " | simulator's own connect |",
             "|---|---|---:|" + "---:|" * (len(keys) + 1)]
    summary: dict = {}
    for job in JOBS:
        for who in ("ours", "floor"):
            mine = [r for r in runs if r["job"] == job and r["who"] == who and r["code"] == 0]
            if not mine:
                continue
            row = {k: median([r["marks"].get(k) for r in mine]) for k in keys}
            row["simulator_connect_s"] = median([r["simulator_connect_s"] for r in mine])
            summary.setdefault(job, {})[who] = row
            lines.append(f"| {job} | {who} | {len(mine)} | " + " | ".join(fmt(row[k]) for k in keys)
                         + f" | {fmt(row['simulator_connect_s'])} |")
    lines.append("")
    for job, both in summary.items():
        ours, floor_row = both.get("ours"), both.get("floor")
        if not ours or not floor_row:
            continue
        own = floor_row["simulator_connect_s"]
        part = None if ours["first_step"] is None or own is None else ours["first_step"] - own
        share = floor_row["exit"] / ours["exit"]
        both["trainer_part_to_first_step_s"], both["floor_share"] = part, share
        lines.append(f"- {job}: the trainer's part of the time to the first step (first step {fmt(ours['first_step'])} s "
                     f"- the simulator's own connect {fmt(own)} s): **{fmt(part)} s** (target <= 0.3 s); "
                     f"the floor's wall ÷ ours: **{share * 100:.0f} %** ({fmt(floor_row['exit'])} s of "
                     f"{fmt(ours['exit'])} s)")
    return "\n".join(lines), summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="mode")
    inner = sub.add_parser("floor", help="(internal) the client-only floor driver")
    inner.add_argument("--env", required=True)
    inner.add_argument("--steps", type=int, required=True)
    inner.add_argument("--base-port", type=int, required=True)
    inner.add_argument("--log-folder", required=True)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--jobs", nargs="+", default=list(JOBS), choices=list(JOBS))
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out")
    args = parser.parse_args(argv)
    if args.mode == "floor":
        return floor(args)
    sys.path.insert(0, str(ROOT))
    folder = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    runs = []
    for i in range(args.runs):
        for job in args.jobs:
            order = (run_ours, run_floor) if i % 2 == 0 else (run_floor, run_ours)
            for run in order:
                result = run(job, folder, f"{job}_{run.__name__}_{i}")
                runs.append(result)
                print(f"[{job} {result['who']} {i}] exit {result['code']}: "
                      + ", ".join(f"{k} {v:.2f}" for k, v in result["marks"].items() if k != "start"), flush=True)
                if result["code"]:
                    print(result["tail"], flush=True)
    markdown, summary = report(runs)
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(markdown)
    print(f"\n{when}, load average {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} CPUs")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "startup.json").write_text(json.dumps({"date": when, "runs": runs, "summary": summary,
                                                       "load_1min": os.getloadavg()[0]}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
