"""The pictures in docs/: a still of each seed task (docs/stub-tasks.md) and one frame of a clip.

    .venv/bin/python scripts/render_stills.py                       # docs/images/<task>.png, 640x480
    .venv/bin/python scripts/render_stills.py --from-clip CLIP.mp4 --at 4.0 -o docs/images/ball3d-trained.png

A still is the frame ``unity-stub-env --task T --play POLICY --video ...`` shows at the time given in
STILLS (same Player, camera and caption); --from-clip decodes a written clip (PyAV) instead.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# task, policy, environment parameters, seconds into the play, seed
STILLS = [("dodge", "zero", [], 0.5, 2), ("mimic", "scripted", ["motion=2"], 3.0, 0),
          ("creature", "random", [], 2.0, 0), ("runner", "zero", [], 1.0, 3)]


def still(task_name: str, policy: str, env_params: list[str], seconds: float, seed: int, out: Path) -> None:
    from PIL import Image

    from unity_stub_env.record_demo import parse_env_params
    from unity_stub_env.render.play import Player, make_policy
    from unity_stub_env.tasks import make_task

    task = make_task(task_name, 1, seed, parse_env_params(env_params))
    player = Player(task, make_policy(policy, task, seed), 0, 640, 480, f"{task_name} / {policy}")
    while player.time < seconds:
        player.step()
    for _ in range(20):  # let a following camera settle on where the agent is now
        player.view.frame()
    Image.fromarray(player.frame()).save(out, optimize=True)
    player.close()


def from_clip(clip: str, at: float, out: Path) -> None:
    import av

    with av.open(clip) as container:
        stream = container.streams.video[0]
        for frame in container.decode(stream):
            if frame.time is not None and frame.time >= at:
                frame.to_image().save(out, optimize=True)
                return
    raise SystemExit(f"{clip} is shorter than {at} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--from-clip", default=None)
    parser.add_argument("--at", type=float, default=0.0)
    parser.add_argument("-o", "--output", default=None)
    args = parser.parse_args()
    if args.from_clip:
        from_clip(args.from_clip, args.at, Path(args.output))
        return
    folder = ROOT / "docs" / "images"
    folder.mkdir(exist_ok=True)
    for task, policy, params, seconds, seed in STILLS:
        still(task, policy, params, seconds, seed, folder / f"{task}.png")
        print(folder / f"{task}.png")


if __name__ == "__main__":
    main()
