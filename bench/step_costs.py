"""Per-step costs of one training run of one source tree, as counts a loaded machine does not spoil.

    .venv/bin/python bench/step_costs.py --tree DIR [--task basic] [--config configs/basic.yaml]
                                         [--max-steps 20000] [--spin-ms 0] [--port 7305] [--out OUT.json]

Runs ``mlagents-like-learn CONFIG --env stub:TASK --seed 1`` with ``PYTHONPATH=DIR`` (so both the
trainer and the stub it launches are DIR's code: an older worktree works unchanged) and
``MLAGENTS_LIKE_SPIN_WAIT_MS=--spin-ms`` (0: no polling, so CPU time is work, not waiting), and
reports:

  * per process (trainer, stub, anything else that exits through Python): user and system CPU,
    minor page faults, voluntary / involuntary context switches, peak RSS, modules imported, and
    the trainer's forks (the PPO update's critic child); from ``getrusage(RUSAGE_SELF)`` at exit
    (a ``sitecustomize`` in a temporary folder on PYTHONPATH wraps ``os._exit``, which both
    processes end with);
  * per decision step of the trainer's main thread, the loop's four phases (``EnvPool.send_step``
    and ``EnvPool.receive`` wrapped): ``decide`` (receive returned -> send starts: the simulator
    waits for it), ``send``, ``off_path`` (send returned -> receive starts: experience, updates,
    summaries, while the simulator steps) and ``receive`` (with --spin-ms 0: blocking wait +
    decode; its CPU is the decode and the system calls); thread CPU (``time.thread_time_ns``)
    median and mean, and wall median, over the steps after the first 2,000 (or the first half of a shorter run).

Two trees compare best when both runs share the machine's state: start them at the same moment
(two ports), as bench/RESULTS.md's entries say. No wall time here is quotable on a loaded machine.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
LEARN = Path(sys.executable).with_name("mlagents-like-learn")
SKIP_STEPS = 2000  # the start-up and first updates; at most half of the run's steps

SITECUSTOMIZE = textwrap.dedent('''
    import os, sys, json, resource, threading
    _OUT = os.environ.get("STEP_COSTS_DIR")
    _forks, _PID = [0], os.getpid()
    def _dump():
        u = resource.getrusage(resource.RUSAGE_SELF)
        role = ("forked child" if os.getpid() != _PID else "stub" if any("unity_stub_env" in a for a in sys.argv)
                else "trainer" if any("mlagents-like-learn" in a or "step_costs" in a for a in sys.argv) else "other")
        record = {"role": role, "pid": os.getpid(), "user_s": u.ru_utime, "system_s": u.ru_stime,
                  "minflt": u.ru_minflt, "majflt": u.ru_majflt, "nvcsw": u.ru_nvcsw, "nivcsw": u.ru_nivcsw,
                  "maxrss_mb": u.ru_maxrss / 1024, "threads": threading.active_count(),
                  "modules": len(sys.modules), "forks": _forks[0]}
        with open(os.path.join(_OUT, f"{role}-{os.getpid()}.json"), "w") as f:
            json.dump(record, f)
    if _OUT:
        _exit, _fork, _done = os._exit, os.fork, []
        def _exit_after_dump(code):
            if not _done:
                _done.append(1)
                _dump()
            _exit(code)
        def _counted_fork():
            pid = _fork()
            _forks[0] = _forks[0] + 1 if pid > 0 else 0  # a child starts its own count
            return pid
        os._exit, os.fork = _exit_after_dump, _counted_fork
''')


def child(argv: list[str]) -> None:
    """The trainer: EnvPool's send_step and receive marked, then the CLI's entry point."""
    import time
    import trainer.envs.pool as pool
    wall, cpu, marks = time.perf_counter_ns, time.thread_time_ns, []

    def marked(method, before, after):
        def wrapper(self, *args, **kwargs):
            marks.append((before, wall(), cpu()))
            result = method(self, *args, **kwargs)
            marks.append((after, wall(), cpu()))
            return result
        return wrapper
    pool.EnvPool.send_step = marked(pool.EnvPool.send_step, 0, 1)
    pool.EnvPool.receive = marked(pool.EnvPool.receive, 2, 3)
    exit_now = os._exit  # the sitecustomize's: it writes the rusage record

    def write_marks(code: int) -> None:
        Path(os.environ["STEP_COSTS_MARKS"]).write_text(json.dumps(marks))
        exit_now(code)
    os._exit = write_marks
    from trainer.cli import entry
    sys.argv = ["mlagents-like-learn", *argv]
    try:
        entry()
    finally:
        write_marks(0)


PHASES = {(3, 0): "decide", (0, 1): "send", (1, 2): "off_path", (2, 3): "receive"}


def phases(marks: list) -> dict:
    found: dict[str, tuple[list, list]] = {name: ([], []) for name in PHASES.values()}
    skip = 4 * min(SKIP_STEPS, len(marks) // 8)  # four marks a step
    for (kind0, wall0, cpu0), (kind1, wall1, cpu1) in zip(marks[skip:], marks[skip + 1:]):
        name = PHASES.get((kind0, kind1))
        if name:
            found[name][0].append((wall1 - wall0) / 1e3)
            found[name][1].append((cpu1 - cpu0) / 1e3)
    return {name: {"steps": len(c), "cpu_us_median": statistics.median(c), "cpu_us_mean": statistics.mean(c),
                   "wall_us_median": statistics.median(w)} for name, (w, c) in found.items() if c}


def main() -> int:
    if sys.argv[1:2] == ["--child"]:
        child(sys.argv[2:])
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tree", type=Path, default=REPO)
    parser.add_argument("--task", default="basic")
    parser.add_argument("--config", default="configs/basic.yaml", help="relative to --tree")
    parser.add_argument("--max-steps", type=int, default=20000)
    parser.add_argument("--spin-ms", default="0")
    parser.add_argument("--port", type=int, default=7305)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    tree = args.tree.resolve()
    with tempfile.TemporaryDirectory(prefix="step_costs_") as tmp:
        folder = Path(tmp)
        (folder / "probe").mkdir()
        (folder / "probe" / "sitecustomize.py").write_text(SITECUSTOMIZE)
        config = yaml.safe_load((tree / args.config).read_text())
        for settings in [config.get("default_settings") or {}, *config["behaviors"].values()]:
            settings["max_steps"] = args.max_steps
            settings["checkpoint_interval"] = 100 * args.max_steps
        (folder / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
        env = {**os.environ, "PYTHONPATH": f"{tree}{os.pathsep}{folder / 'probe'}",
               "MLAGENTS_LIKE_SPIN_WAIT_MS": args.spin_ms, "STEP_COSTS_DIR": str(folder / "probe"),
               "STEP_COSTS_MARKS": str(folder / "marks.json")}
        command = [sys.executable, str(Path(__file__).resolve()), "--child", str(folder / "config.yaml"),
                   "--env", f"stub:{args.task}", "--seed", "1", "--no-graphics", "--base-port", str(args.port),
                   "--run-id", "run", "--results-dir", str(folder / "results")]
        with open(folder / "output.log", "w") as log:
            code = subprocess.run(command, cwd=folder, env=env, stdout=log, stderr=subprocess.STDOUT).returncode
        if code != 0:
            print((folder / "output.log").read_text()[-2000:], file=sys.stderr)
            return code
        processes = sorted((json.loads(p.read_text()) for p in (folder / "probe").glob("*.json")),
                           key=lambda r: r["role"])
        result = {"tree": str(tree), "task": args.task, "config": args.config, "max_steps": args.max_steps,
                  "spin_ms": args.spin_ms, "processes": processes,
                  "phases": phases(json.loads((folder / "marks.json").read_text()))}
    print(f"{tree} {args.task} {args.config} {args.max_steps} steps, spin {args.spin_ms} ms")
    print("| process | user s | system s | minflt | nvcsw | nivcsw | max RSS MB | threads at exit | modules | forks |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in processes:
        print(f"| {r['role']} | {r['user_s']:.2f} | {r['system_s']:.2f} | {r['minflt']} | {r['nvcsw']} | "
              f"{r['nivcsw']} | {r['maxrss_mb']:.0f} | {r['threads']} | {r['modules']} | {r['forks']} |")
    print("| phase | steps | CPU µs median | CPU µs mean | wall µs median |")
    print("|---|---:|---:|---:|---:|")
    for name, p in result["phases"].items():
        print(f"| {name} | {p['steps']} | {p['cpu_us_median']:.1f} | {p['cpu_us_mean']:.1f} | {p['wall_us_median']:.1f} |")
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
