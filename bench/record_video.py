"""What --record-video costs training: the same run with and without it, in alternating pairs.

    nice -n 10 .venv/bin/python bench/record_video.py [--task ball3d] [--config configs/ball3d.yaml]
        [--steps 48000] [--checkpoint-interval 6000] [--pairs 3]

Each pair trains --config on stub:TASK for --steps steps (checkpoint_interval overridden so the
run writes a checkpoint, hence starts a clip, every --checkpoint-interval steps), once plain and
once with --record-video, in alternating order. Throughput = steps / the trainer's wall time
(process start to exit, the wait for the last clip at the end excluded: the time of the
"Exported <final>.onnx" log line). Prints each pair, the median slowdown, and how many clips each
run wrote; writes bench/out/record_video.json.
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
    for line in process.stdout:
        lines.append(line)
        if re.search(r"Copied .*\.onnx to ", line) and trained is None:  # the final model is written
            trained = time.perf_counter() - start
    process.wait()
    if process.returncode != 0:
        raise SystemExit("".join(lines[-40:]))
    clips = sorted(p.name for p in results.glob("r/*/*-*.mp4"))
    return {"video": video, "seconds": trained, "clips": clips}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="ball3d")
    parser.add_argument("--config", default=str(ROOT / "configs" / "ball3d.yaml"))
    parser.add_argument("--steps", type=int, default=48000)
    parser.add_argument("--checkpoint-interval", type=int, default=6000)
    parser.add_argument("--pairs", type=int, default=3)
    args = parser.parse_args()
    config = yaml.safe_load(Path(args.config).read_text())
    for settings in config["behaviors"].values():
        settings["max_steps"], settings["checkpoint_interval"] = args.steps, args.checkpoint_interval
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "config.yaml"
        path.write_text(yaml.safe_dump(config))
        for pair in range(args.pairs):
            order = (False, True) if pair % 2 == 0 else (True, False)
            runs = {}
            for video in order:
                folder = Path(tmp) / f"p{pair}-{int(video)}"
                folder.mkdir()
                runs[video] = train(path, args.task, folder, video, seed=pair + 1)
            slowdown = runs[True]["seconds"] / runs[False]["seconds"] - 1
            rows.append({"pair": pair, "plain_s": runs[False]["seconds"], "video_s": runs[True]["seconds"],
                         "slowdown": slowdown, "clips": runs[True]["clips"]})
            print(f"pair {pair}: plain {runs[False]['seconds']:.1f} s, --record-video {runs[True]['seconds']:.1f} s "
                  f"({100 * slowdown:+.1f} %), {len(runs[True]['clips'])} clips", flush=True)
    median = statistics.median(r["slowdown"] for r in rows)
    print(f"median slowdown {100 * median:+.1f} % over {len(rows)} pairs ({args.task}, {args.steps} steps, "
          f"a checkpoint every {args.checkpoint_interval})")
    out = ROOT / "bench" / "out"
    out.mkdir(exist_ok=True)
    (out / "record_video.json").write_text(json.dumps({"args": vars(args), "rows": rows, "median": median}, indent=1))


if __name__ == "__main__":
    main()
