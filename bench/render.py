"""Render speed of the stub's videos: frames per second at 640x480 (unity_stub_env.render).

    nice -n 10 .venv/bin/python bench/render.py [--tasks dodge mimic creature] [--frames 60] [--size 640 480]

Per task and antialiasing (MuJoCo offscreen multisampling 4, the --play default, and 0): the
camera frame alone (``MujocoView.frame``: scene update, cues, OpenGL render and read-back on
Mesa's llvmpipe) and a whole filmed frame (the physics between frames at 30 fps, the caption, H.264
encoding through imageio-ffmpeg into a throw-away .mp4). Reported as frames per CPU-second of
this process (llvmpipe's render threads included) and per wall second. Prints a markdown table;
writes bench/out/render.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from unity_stub_env.render.play import Player, film, make_policy  # noqa: E402
from unity_stub_env.render.video import VideoWriter  # noqa: E402
from unity_stub_env.tasks import make_task  # noqa: E402


def clocks() -> tuple[float, float]:
    return time.process_time(), time.perf_counter()


def measure(task_name: str, samples: int, frames: int, size: tuple[int, int]) -> dict:
    task = make_task(task_name, 1, 0)
    player = Player(task, make_policy("random", task, 0), 0, *size, task_name, samples)
    for _ in range(5):  # warm-up: first frames compile shaders and upload meshes
        player.view.frame()
    cpu, wall = clocks()
    for _ in range(frames):
        player.view.frame()
    cpu_r, wall_r = clocks()
    with tempfile.TemporaryDirectory() as folder:
        writer = VideoWriter(os.path.join(folder, "clip.mp4"), 30.0)
        film(player, writer, 30.0, seconds=1.0 / 30)  # the encoder's start
        cpu_f, wall_f = clocks()
        film(player, writer, 30.0, seconds=frames / 30.0)
        cpu_e, wall_e = clocks()
        writer.close()
    player.close()
    return {"task": task_name, "samples": samples, "frames": frames,
            "render_fps_cpu": frames / (cpu_r - cpu), "render_fps_wall": frames / (wall_r - wall),
            "filmed_fps_cpu": frames / (cpu_e - cpu_f), "filmed_fps_wall": frames / (wall_e - wall_f)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=["dodge", "mimic", "creature"])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--size", type=int, nargs=2, default=(640, 480))
    args = parser.parse_args()
    rows = [measure(t, s, args.frames, tuple(args.size)) for t in args.tasks for s in (4, 0)]
    print(f"| task | antialias | render fps (CPU s) | render fps (wall) | filmed fps (CPU s) | filmed fps (wall) |\n"
          f"|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['task']} | {r['samples']} | {r['render_fps_cpu']:.1f} | {r['render_fps_wall']:.1f} | "
              f"{r['filmed_fps_cpu']:.1f} | {r['filmed_fps_wall']:.1f} |")
    out = Path(__file__).resolve().parent / "out"
    out.mkdir(exist_ok=True)
    (out / "render.json").write_text(json.dumps({"size": args.size, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
