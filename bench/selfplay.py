"""Self-play on the ``soccer`` stub: the ELO curve and what the checkpoints are worth in matches.

    nice -n 10 .venv/bin/python bench/selfplay.py [--steps 200000] [--seed 1] [--areas 16]
    .venv/bin/python bench/selfplay.py --results results/soccer       # only score an earlier run

Trains ``configs/soccer.yaml`` (max_steps replaced by --steps) through mlagents-like-learn and the
stub over gRPC, then prints:

* ``Self-play/ELO`` at every summary (TensorBoard, as the run wrote it);
* every kept checkpoint (``Soccer-<step>.onnx``, deterministic) against a player choosing
  uniformly at random, and the final model against each checkpoint, with
  ``unity_stub_env.tasks.soccer.play_match`` (16 pitches, 1,000 decisions each; goals for : against,
  draws = episodes interrupted at max_step).

Writes bench/out/selfplay.json. Asserts nothing.
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


def match(team0, team1, decisions: int = 1000, seed: int = 5) -> tuple[int, int, int]:
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    return play_match(make_task("soccer", num_areas=16, seed=seed), team0, team1, decisions)


def elo_curve(brain_dir: Path) -> list[tuple[int, float]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(brain_dir), size_guidance={"scalars": 0})
    acc.Reload()
    return [(e.step, round(e.value, 1)) for e in acc.Scalars("Self-play/ELO")]


def train(args) -> Path:
    results = Path(tempfile.mkdtemp(prefix="selfplay_bench_"))
    cfg = results / "soccer.yaml"
    cfg.write_text((ROOT / "configs" / "soccer.yaml").read_text().replace("max_steps: 200000",
                                                                           f"max_steps: {args.steps}"))
    cmd = [sys.executable, "-m", "trainer.cli", str(cfg), "--env", "stub:soccer", "--num-areas", str(args.areas),
           "--seed", str(args.seed), "--run-id", "soccer", "--results-dir", str(results)]
    subprocess.run(cmd, check=True, cwd=ROOT)
    return results / "soccer"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--areas", type=int, default=16)
    parser.add_argument("--results", type=Path, default=None, help="score this run folder instead of training")
    args = parser.parse_args()
    run = args.results or train(args)
    brain = run / "Soccer"
    curve = elo_curve(brain)
    checkpoints = sorted((int(m.group(1)), p) for p in brain.glob("Soccer-*.onnx")
                         if (m := re.fullmatch(r"Soccer-(\d+)\.onnx", p.name)))
    final = run / "Soccer.onnx"
    rows = [("random", "random", match(random_player(1), random_player(2)))]
    for step, path in checkpoints:
        rows.append((f"Soccer-{step}", "random", match(onnx_player(path), random_player(2))))
    for step, path in checkpoints[:-1]:
        rows.append(("final", f"Soccer-{step}", match(onnx_player(final), onnx_player(path))))
    print("| step | Self-play/ELO |\n|---|---|")
    for step, value in curve:
        print(f"| {step} | {value} |")
    print("\n| team 0 | team 1 | goals for : against | draws |\n|---|---|---|---|")
    for a, b, (wins, losses, draws) in rows:
        print(f"| {a} | {b} | {wins} : {losses} | {draws} |")
    OUT.mkdir(exist_ok=True)
    (OUT / "selfplay.json").write_text(json.dumps({"run": str(run), "elo": curve, "matches": [
        {"team0": a, "team1": b, "for": w, "against": l_, "draws": d} for a, b, (w, l_, d) in rows]}, indent=1))


if __name__ == "__main__":
    main()
