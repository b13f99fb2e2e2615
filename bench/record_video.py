"""What --record-video costs training: the same run with and without it, in alternating pairs, at
a frequent and at a realistic checkpoint interval.

    nice -n 10 .venv/bin/python bench/record_video.py [--task ball3d] [--config configs/ball3d.yaml]
        [--settings 300000:6000 40000:20000] [--pairs 3]

Each setting STEPS:INTERVAL trains --config on stub:TASK for STEPS steps with checkpoint_interval
INTERVAL, once plain and once with --record-video, in alternating order; --pairs pairs per
setting. The frequent setting runs long enough (about 75 s on the quiet machine) for the CPU
budget to allow clips while training (docs/video.md, "Clips while training": about a minute of
training on 2 cores pays for the first); the realistic one has a few checkpoints per run, as a
long run with ML-Agents' intervals has. Throughput = steps / the trainer's wall time (process start to the "Copied <final>.onnx"
log line: the wait for the final clip at the end excluded). Prints each pair (the slowdown, the
clips written, the checkpoints, and the renderer's CPU share while training as the trainer logs
it), the median slowdown per setting; writes bench/out/record_video.json. Target: each median
<= 5 %.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def train(config: Path, task: str, folder: Path, video: bool, seed: int) -> dict:
    results = folder / "results"
    command = [sys.executable, "-m", "trainer.cli", str(config), "--env", f"stub:{task}", "--run-id", "r",
               "--seed", str(seed), "--results-dir", str(results), "--base-port", str(free_port()), "--force"]
    if video:
        command.append("--record-video")
    start = time.perf_counter()
    process = subprocess.Popen(command, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
    trained = None
    lines = []
    share = filmed = asked = None
    for line in process.stdout:
        lines.append(line)
        if re.search(r"Copied .*\.onnx to ", line) and trained is None:  # the final model is written
            trained = time.perf_counter() - start
        used = re.search(r"--record-video: (\d+) of (\d+) checkpoints filmed; .* ([\d.]+) % of", line)
        if used:
            filmed, asked, share = int(used.group(1)), int(used.group(2)), float(used.group(3))
    process.wait()
    if process.returncode != 0:
        raise SystemExit("".join(lines[-40:]))
    clips = sorted(p.name for p in results.glob("r/*/*-*.mp4"))
    if video and filmed != len(clips):
        raise SystemExit(f"the trainer logged {filmed} clips; {len(clips)} were written:\n" + "".join(lines[-40:]))
    return {"video": video, "seconds": trained, "clips": clips, "checkpoints": asked, "cpu_share": share}


def setting(text: str) -> tuple[int, int]:
    steps, _, interval = text.partition(":")
    return int(steps), int(interval)


def pairs_of(config: dict, task: str, steps: int, interval: int, pairs: int, tmp: Path) -> list[dict]:
    config = json.loads(json.dumps(config))
    for settings in config["behaviors"].values():
        settings["max_steps"], settings["checkpoint_interval"] = steps, interval
    path = tmp / f"config-{steps}-{interval}.yaml"
    path.write_text(yaml.safe_dump(config))
    rows = []
    for pair in range(pairs):
        order = (False, True) if pair % 2 == 0 else (True, False)
        runs = {}
        for video in order:
            folder = tmp / f"s{steps}-{interval}-p{pair}-{int(video)}"
            folder.mkdir()
            runs[video] = train(path, task, folder, video, seed=pair + 1)
        slowdown = runs[True]["seconds"] / runs[False]["seconds"] - 1
        video_run = runs[True]
        rows.append({"pair": pair, "plain_s": runs[False]["seconds"], "video_s": video_run["seconds"],
                     "slowdown": slowdown, "clips": video_run["clips"], "checkpoints": video_run["checkpoints"],
                     "cpu_share": video_run["cpu_share"]})
        share = "?" if video_run["cpu_share"] is None else f"{video_run['cpu_share']:.1f} %"
        print(f"{steps}:{interval} pair {pair}: plain {runs[False]['seconds']:.1f} s, --record-video "
              f"{video_run['seconds']:.1f} s ({100 * slowdown:+.1f} %), {len(video_run['clips'])} clips of "
              f"{video_run['checkpoints']} checkpoints, renderer {share} of the CPUs while training", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="ball3d")
    parser.add_argument("--config", default=str(ROOT / "configs" / "ball3d.yaml"))
    parser.add_argument("--settings", nargs="+", type=setting, default=[(300000, 6000), (40000, 20000)],
                        metavar="STEPS:INTERVAL", help="max_steps and checkpoint_interval of each setting")
    parser.add_argument("--pairs", type=int, default=3)
    args = parser.parse_args()
    config = yaml.safe_load(Path(args.config).read_text())
    results = []
    began = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for steps, interval in args.settings:
            rows = pairs_of(config, args.task, steps, interval, args.pairs, Path(tmp))
            median = statistics.median(r["slowdown"] for r in rows)
            results.append({"steps": steps, "checkpoint_interval": interval, "rows": rows, "median": median})
    for result in results:
        print(f"median slowdown {100 * result['median']:+.1f} % over {len(result['rows'])} pairs ({args.task}, "
              f"{result['steps']} steps, a checkpoint every {result['checkpoint_interval']})")
    print(f"{(time.perf_counter() - began) / 60:.1f} minutes in all")
    out = ROOT / "bench" / "out"
    out.mkdir(exist_ok=True)
    (out / "record_video.json").write_text(json.dumps({"args": {**vars(args), "settings": args.settings},
                                                       "results": results}, indent=1))


if __name__ == "__main__":
    main()
