"""Self-play on the ``soccer`` (1 v 1) or ``soccer_twos`` (2 v 2) stub: the ELO curve and what the
checkpoints are worth in matches.

    nice -n 10 .venv/bin/python bench/selfplay.py [--task soccer|soccer_twos] [--steps N] [--seed 1] [--areas 16]
    .venv/bin/python bench/selfplay.py --results results/soccer       # only score an earlier run

Trains ``configs/<task>.yaml`` (``soccer``: PPO; ``soccer_twos``: MA-POCA; max_steps replaced by
--steps, default the config's) through mlagents-like-learn and the stub over gRPC, then prints:

* ``Self-play/ELO`` at every summary (TensorBoard, as the run wrote it), and for ``soccer_twos``
  ``Environment/Group Cumulative Reward`` beside it;
* every kept checkpoint (``<Behavior>-<step>.onnx``, deterministic) against a team choosing
  uniformly at random, and the final model against each checkpoint, with
  ``unity_stub_env.tasks.soccer.play_match`` (16 pitches, 1,000 decisions each; goals for : against,
  draws = episodes interrupted at max_step).

Writes bench/out/selfplay.json (bench/out/selfplay_twos.json for soccer_twos). Asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"


def onnx_player(path: Path):
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])

    def act(obs):
        masks = np.ones((len(obs), 6), np.float32)
        return session.run(["deterministic_discrete_actions"], {"obs_0": obs, "action_masks": masks})[0]

    return act


def random_player(seed: int):
    rng = np.random.default_rng(seed)
    return lambda obs: rng.integers(0, 3, size=(len(obs), 2))


def match(task: str, team0, team1, decisions: int = 1000, seed: int = 5) -> tuple[int, int, int]:
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    return play_match(make_task(task, num_areas=16, seed=seed), team0, team1, decisions)


def scalars(brain_dir: Path, tag: str) -> dict[int, float]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(brain_dir), size_guidance={"scalars": 0})
    acc.Reload()
    return {e.step: round(e.value, 3) for e in acc.Scalars(tag)} if tag in acc.Tags()["scalars"] else {}


def train(args) -> Path:
    results = Path(tempfile.mkdtemp(prefix="selfplay_bench_"))
    cfg = results / f"{args.task}.yaml"
    text = (ROOT / "configs" / f"{args.task}.yaml").read_text()
    if args.steps is not None:
        text = re.sub(r"max_steps: \d+", f"max_steps: {args.steps}", text)
    cfg.write_text(text)
    cmd = [sys.executable, "-m", "trainer.cli", str(cfg), "--env", f"stub:{args.task}", "--num-areas", str(args.areas),
           "--seed", str(args.seed), "--run-id", args.task, "--results-dir", str(results)]
    subprocess.run(cmd, check=True, cwd=ROOT)
    return results / args.task


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=("soccer", "soccer_twos"), default="soccer")
    parser.add_argument("--steps", type=int, default=None, help="max_steps (default: the config's)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--areas", type=int, default=16)
    parser.add_argument("--results", type=Path, default=None, help="score this run folder instead of training")
    args = parser.parse_args()
    from unity_stub_env.tasks import TASKS

    behavior = TASKS[args.task].behavior_name
    run = args.results or train(args)
    brain = run / behavior
    elo = scalars(brain, "Self-play/ELO")
    group = scalars(brain, "Environment/Group Cumulative Reward")
    curve = [(step, round(value, 1), group.get(step)) for step, value in sorted(elo.items())]
    checkpoints = sorted((int(m.group(1)), p) for p in brain.glob(f"{behavior}-*.onnx")
                         if (m := re.fullmatch(rf"{behavior}-(\d+)\.onnx", p.name)))
    final = run / f"{behavior}.onnx"
    rows = [("random", "random", match(args.task, random_player(1), random_player(2)))]
    for step, path in checkpoints:
        rows.append((f"{behavior}-{step}", "random", match(args.task, onnx_player(path), random_player(2))))
    for step, path in checkpoints[:-1]:
        rows.append(("final", f"{behavior}-{step}", match(args.task, onnx_player(final), onnx_player(path))))
    print("| step | Self-play/ELO | Group Cumulative Reward |\n|---|---|---|")
    for step, value, reward in curve:
        print(f"| {step} | {value} | {'' if reward is None else reward} |")
    print("\n| team 0 | team 1 | goals for : against | draws |\n|---|---|---|---|")
    for a, b, (wins, losses, draws) in rows:
        print(f"| {a} | {b} | {wins} : {losses} | {draws} |")
    OUT.mkdir(exist_ok=True)
    name = "selfplay.json" if args.task == "soccer" else "selfplay_twos.json"
    (OUT / name).write_text(json.dumps({"run": str(run), "elo": curve, "matches": [
        {"team0": a, "team1": b, "for": w, "against": l_, "draws": d} for a, b, (w, l_, d) in rows]}, indent=1))


if __name__ == "__main__":
    main()
