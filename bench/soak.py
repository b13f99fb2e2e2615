"""Soak: one training run for a long time while simulators (and, less often, the trainer) are killed.

    .venv/bin/python bench/soak.py --minutes 30                      # the full soak (docs/reliability.md)
    nice .venv/bin/python bench/soak.py --minutes 4 --sim-kill 15 40 --trainer-kill 90 150   # short

``mlagents-like-learn`` trains ``stub:basic`` with ``--num-envs`` simulators, unlimited restarts,
and a max_steps it never reaches. Every U(a, b) seconds (``--sim-kill``) a random simulator gets
SIGKILL; every U(c, d) seconds (``--trainer-kill``; 0 0 turns it off) the trainer and its
simulators get SIGKILL (a node failure) and the run continues with ``--resume``. At the end the
trainer gets SIGTERM (a graceful stop, exit 75). Reported:

* RSS of the trainer process (and of all simulators) sampled every ``--sample`` seconds, as a
  per-minute table and, per trainer process, the least-squares slope in MB per hour over the
  second half of its life (at least its first minute left out: buffers and allocator pools fill
  first; the trend, target: none beyond noise);
* kills of simulators and of the trainer, and the restarts the trainer logged (each simulator
  kill must be followed by one restart, except one the trainer's own kill or stop overtook);
* TensorBoard summary labels, read back from the event files with TensorBoard's purge rule (a
  SessionLog START at step s drops what earlier files wrote at steps >= s, which a resumed run
  writes): **counted twice** = labels present more than once, **lost** = multiples of
  summary_freq up to the last label that are missing (target 0 and 0);
* the steps each resume went back to (work redone since the last checkpoint; by design).

A JSON record goes to bench/out/soak-<date>.json. Not a test: it asserts nothing.
"""
from __future__ import annotations

import argparse
import collections
import datetime as dt
import json
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = """
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {{batch_size: 64, buffer_size: 1024, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 3}}
    network_settings: {{normalize: false, hidden_units: 32, num_layers: 2}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    keep_checkpoints: 5
    checkpoint_interval: {checkpoint}
    max_steps: 1000000000
    time_horizon: 16
    summary_freq: {summary}
"""


def free_base_port(n: int) -> int:
    for _ in range(100):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            base = s.getsockname()[1]
        if base + n < 65000:
            return base
    raise RuntimeError("no free port")


def rss_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def simulator_pids(ports: range) -> dict[int, int]:
    """{port: pid} of the stub simulators listening to the trainer on ``ports``."""
    found = {}
    wanted = {str(p).encode(): p for p in ports}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            argv = open(f"/proc/{entry}/cmdline", "rb").read().split(b"\0")
        except OSError:
            continue
        if b"unity_stub_env.cli" in argv and b"--mlagents-port" in argv:
            port = argv[argv.index(b"--mlagents-port") + 1]
            if port in wanted:
                found[wanted[port]] = int(entry)
    return found


def summary_labels(brain_dir: Path) -> collections.Counter:
    """Steps of the scalar summaries TensorBoard shows for ``brain_dir``, with its purge rule."""
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
    from tensorboard.compat.proto import event_pb2

    labels: collections.Counter = collections.Counter()
    files = sorted(brain_dir.glob("events.out.tfevents.*"), key=lambda p: int(p.name.split(".")[3]))
    for path in files:
        for event in EventFileLoader(str(path)).Load():
            if event.HasField("session_log") and event.session_log.status == event_pb2.SessionLog.START:
                for step in [s for s in labels if s >= event.step]:
                    del labels[step]
            elif event.HasField("summary") and any(v.HasField("simple_value") or v.HasField("tensor")
                                                   for v in event.summary.value):
                if any(v.tag == "Environment/Cumulative Reward" for v in event.summary.value):
                    labels[event.step] += 1
    return labels


def slope_mb_per_hour(samples: list[tuple[float, float]]) -> float | None:
    if len(samples) < 3:
        return None
    n = len(samples)
    mt = sum(t for t, _ in samples) / n
    mv = sum(v for _, v in samples) / n
    var = sum((t - mt) ** 2 for t, _ in samples)
    return None if var == 0 else sum((t - mt) * (v - mv) for t, v in samples) / var * 3600


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--num-envs", type=int, default=3)
    ap.add_argument("--sim-kill", type=float, nargs=2, default=(20.0, 60.0), metavar=("MIN_S", "MAX_S"))
    ap.add_argument("--trainer-kill", type=float, nargs=2, default=(240.0, 480.0), metavar=("MIN_S", "MAX_S"))
    ap.add_argument("--sample", type=float, default=5.0, help="seconds between RSS samples")
    ap.add_argument("--summary-freq", type=int, default=2000)
    ap.add_argument("--checkpoint-interval", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--keep", action="store_true", help="keep the results folder")
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)

    work = Path(tempfile.mkdtemp(prefix="soak-"))
    config = work / "soak.yaml"
    config.write_text(CONFIG.format(checkpoint=args.checkpoint_interval, summary=args.summary_freq))
    base_port = free_base_port(args.num_envs)
    ports = range(base_port, base_port + args.num_envs)
    env = {k: v for k, v in os.environ.items() if not k.lower().endswith("_proxy")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    cmd = [sys.executable, "-m", "trainer.cli", str(config), "--env", "stub:basic", "--num-envs", str(args.num_envs),
           "--run-id", "soak", "--results-dir", str(work / "results"), "--base-port", str(base_port),
           "--seed", str(args.seed), "--max-lifetime-restarts", "-1", "--restarts-rate-limit-n", "-1",
           "--timeout-wait", "30"]
    logs: list[Path] = []

    def start(resume: bool) -> subprocess.Popen:
        log = work / f"trainer-{len(logs)}.log"
        logs.append(log)
        return subprocess.Popen(cmd + (["--resume"] if resume else []), stdout=open(log, "w"),
                                stderr=subprocess.STDOUT, env=env, cwd=work)

    t0 = time.monotonic()
    end = t0 + args.minutes * 60
    trainer = start(resume=False)
    segments: list[dict] = [{"pid": trainer.pid, "samples": []}]
    sim_samples: list[tuple[float, float]] = []
    next_sim_kill = t0 + rng.uniform(*args.sim_kill)
    trainer_kill_on = args.trainer_kill[1] > 0
    next_trainer_kill = t0 + rng.uniform(*args.trainer_kill) if trainer_kill_on else float("inf")
    sim_kills = trainer_kills = 0
    sim_kill_times: list[float] = []
    trainer_end_times: list[float] = []  # kills of the trainer, and the final stop
    early_exits = []
    while time.monotonic() < end:
        now = time.monotonic()
        if trainer.poll() is not None:  # it should never end by itself
            early_exits.append(trainer.returncode)
            trainer = start(resume=True)
            segments.append({"pid": trainer.pid, "samples": []})
        rss = rss_mb(trainer.pid)
        if rss is not None:
            segments[-1]["samples"].append((now - t0, rss))
        sims = simulator_pids(ports)
        sim_samples.append((now - t0, sum(rss_mb(p) or 0.0 for p in sims.values())))
        if now >= next_sim_kill and sims:
            os.kill(rng.choice(sorted(sims.values())), signal.SIGKILL)
            sim_kills += 1
            sim_kill_times.append(now)
            next_sim_kill = now + rng.uniform(*args.sim_kill)
        if now >= next_trainer_kill:
            trainer.kill()  # SIGKILL, and its simulators with it: a node failure
            trainer.wait()
            for pid in simulator_pids(ports).values():
                os.kill(pid, signal.SIGKILL)
            trainer_kills += 1
            trainer_end_times.append(now)
            time.sleep(1.0)
            trainer = start(resume=True)
            segments.append({"pid": trainer.pid, "samples": []})
            next_trainer_kill = time.monotonic() + rng.uniform(*args.trainer_kill)
        time.sleep(args.sample)
    trainer_end_times.append(time.monotonic())
    trainer.send_signal(signal.SIGTERM)
    try:
        final_code = trainer.wait(timeout=120)
    except subprocess.TimeoutExpired:
        trainer.kill()
        final_code = None

    text = "\n".join(log.read_text(errors="replace") for log in logs)
    restarts = len(re.findall(r"restarting it and resetting all environments|failed before its first message", text))
    resumed_at = [int(s) for s in re.findall(r"for behavior Basic at step (\d+)\.", text)]
    labels = summary_labels(work / "results" / "soak" / "Basic")
    twice = sum(count - 1 for count in labels.values() if count > 1)
    top = max(labels) if labels else 0
    lost = [s for s in range(args.summary_freq, top + 1, args.summary_freq) if s not in labels]
    final_steps = None
    status_path = work / "results" / "soak" / "run_logs" / "training_status.json"
    if status_path.is_file():
        final = json.loads(status_path.read_text()).get("Basic", {}).get("final_checkpoint")
        final_steps = final and final["steps"]
    tracebacks = text.count("Traceback")
    # a simulator killed shortly before the trainer is killed or stopped may never be noticed
    overtaken = sum(any(0 <= e - k < 10.0 for e in trainer_end_times) for k in sim_kill_times)

    slopes = []
    for seg in segments:  # the second half of each process's life, and not its first minute
        samples = seg["samples"]
        if not samples:
            slopes.append(None)
            continue
        start = max(samples[0][0] + 60, (samples[0][0] + samples[-1][0]) / 2)
        slopes.append(slope_mb_per_hour([(t, v) for t, v in samples if t >= start]))
    print(f"# soak {dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M} UTC: {args.minutes:g} min, "
          f"{args.num_envs} simulators, stub:basic")
    print("\n| minute | trainer RSS MB | simulators RSS MB (sum) |\n|---|---|---|")
    per_minute: dict[int, list] = collections.defaultdict(lambda: [[], []])
    for seg in segments:
        for t, v in seg["samples"]:
            per_minute[int(t // 60)][0].append(v)
    for t, v in sim_samples:
        per_minute[int(t // 60)][1].append(v)
    for minute in sorted(per_minute):
        tr, si = per_minute[minute]
        print(f"| {minute} | {sum(tr) / len(tr) if tr else float('nan'):.1f} | "
              f"{sum(si) / len(si) if si else float('nan'):.1f} |")
    print()
    print(f"* trainer processes: {len(segments)}; RSS slope over the second half of each, MB/h: "
          + ", ".join("n/a" if s is None else f"{s:+.1f}" for s in slopes))
    print(f"* simulator kills: {sim_kills} ({overtaken} within 10 s before a trainer kill or the final stop); "
          f"restarts logged: {restarts}; trainer kills: {trainer_kills}; "
          f"unexpected trainer exits: {early_exits or 'none'}; final exit code: {final_code}")
    print(f"* resumed at steps: {resumed_at or 'none'}; final checkpoint step: {final_steps}")
    print(f"* summary labels: {len(labels)} (every {args.summary_freq} up to {top}); counted twice: {twice}; "
          f"lost: {len(lost)}{' ' + str(lost[:10]) if lost else ''}; tracebacks in the logs: {tracebacks}")
    record = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "args": vars(args),
        "segments": [{"pid": s["pid"], "samples": s["samples"]} for s in segments], "sim_rss": sim_samples,
        "slopes_mb_per_h": slopes, "sim_kills": sim_kills, "overtaken": overtaken, "restarts": restarts, "trainer_kills": trainer_kills,
        "early_exits": early_exits, "final_exit": final_code, "resumed_at": resumed_at,
        "final_steps": final_steps, "labels": len(labels), "twice": twice, "lost": lost, "tracebacks": tracebacks,
    }
    out = ROOT / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / f"soak-{dt.datetime.now(dt.timezone.utc):%Y%m%d-%H%M}.json").write_text(json.dumps(record))
    if args.keep:
        print(f"* results kept in {work}")
    else:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
