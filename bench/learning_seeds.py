"""Seed spread of the learning tests (run by hand, not a test): each test's own training run
(its ``train_*`` function, the same configuration and command) with other seeds, and the numbers
its assertions read. The tests keep one fixed seed; their thresholds are set from this spread so
that no seed passes by luck or fails by an unlucky draw (bench/RESULTS.md).

    PYTHONPATH=$PWD .venv/bin/python bench/learning_seeds.py --test ball3d --seeds 1 2 3 [--out bench/out]

Tests: ball3d (PPO, tests/learning/test_learning.py), bc (tests/learning/test_learning_demo.py),
mimic (tests/learning/test_learning_mimic.py), soccer (the 1 v 1, tests/learning/test_learning_selfplay.py);
soccer_untrained: the soccer test's match for a policy that never updated (what the threshold must exclude).
Prints one JSON line per seed and appends them to <out>/learning_seeds.jsonl.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _env() -> dict:
    env = dict(os.environ)
    for k in ("http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY", "grpc_proxy"):
        env.pop(k, None)
    return env


def ball3d(tmp: pathlib.Path, seed: int) -> dict:
    from tests.learning.test_learning import train_ball3d

    curve = train_ball3d(tmp, _env(), seed)
    return {"first": curve[0][1], "last": curve[-1][1], "curve": [round(v, 2) for _, v in curve]}


def bc(tmp: pathlib.Path, seed: int) -> dict:
    from tests.learning.test_learning_demo import train_bc

    curve = train_bc(tmp, _env(), seed)
    return {"first": curve[0][1], "last": curve[-1][1], "curve": [round(v, 3) for _, v in curve]}


def mimic(tmp: pathlib.Path, seed: int) -> dict:
    from tests.learning.test_learning_mimic import train_mimic

    acc = train_mimic(tmp, _env(), seed)
    reward = [e.value for e in acc.Scalars("Environment/Cumulative Reward")]
    length = [e.value for e in acc.Scalars("Environment/Episode Length")]
    pose = [e.value for e in acc.Scalars("Mimic/r_r")]
    return {"reward_first": reward[0], "reward_last3": sum(reward[-3:]) / 3,
            "length_first": length[0], "length_last3": sum(length[-3:]) / 3,
            "r_r_first": pose[0], "r_r_last": pose[-1]}


def soccer(tmp: pathlib.Path, seed: int) -> dict:
    from tests.learning.test_learning_selfplay import onnx_player, random_player, train_soccer
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    acc = train_soccer(tmp, _env(), seed)
    elo = [e.value for e in acc.Scalars("Self-play/ELO")]
    wins, losses, _ = play_match(make_task("soccer", num_areas=16, seed=5),
                                 onnx_player(tmp / "results" / "s" / "Soccer.onnx"), random_player(2), 1000)
    return {"elo_first": elo[0], "elo_last": elo[-1], "wins": int(wins), "losses": int(losses)}


def soccer_untrained(tmp: pathlib.Path, seed: int) -> dict:
    """What the soccer test's match gives a policy that never updated: configs/soccer.yaml with
    max_steps 1,000 (below buffer_size 2,048), its ONNX against the random player."""
    from tests.integration.conftest import ROOT, train_on_stub
    from tests.learning.test_learning_selfplay import onnx_player, random_player
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.soccer import play_match

    cfg = tmp / "soccer.yaml"
    cfg.write_text((ROOT / "configs" / "soccer.yaml").read_text().replace("max_steps: 200000", "max_steps: 1000"))
    train_on_stub(tmp, cfg, "soccer", "Soccer", _env(), num_areas=16, seed=seed, run_id="s")
    wins, losses, _ = play_match(make_task("soccer", num_areas=16, seed=5),
                                 onnx_player(tmp / "results" / "s" / "Soccer.onnx"), random_player(2), 1000)
    random_wins, random_losses, _ = play_match(make_task("soccer", num_areas=16, seed=5), random_player(1),
                                               random_player(2), 1000)
    return {"wins": int(wins), "losses": int(losses), "random_vs_random": [int(random_wins), int(random_losses)]}


TESTS = {"ball3d": ball3d, "bc": bc, "mimic": mimic, "soccer": soccer, "soccer_untrained": soccer_untrained}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", choices=sorted(TESTS), required=True)
    parser.add_argument("--seeds", type=int, nargs="+", required=True)
    parser.add_argument("--label", default="", help="a note kept with each line (e.g. the tree or init)")
    parser.add_argument("--out", default=str(ROOT / "bench" / "out"))
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    for seed in args.seeds:
        tmp = pathlib.Path(tempfile.mkdtemp(prefix=f"learning_seeds_{args.test}_"))
        start = time.time()
        try:
            row = {"test": args.test, "seed": seed, "label": args.label, **TESTS[args.test](tmp, seed),
                   "wall_s": round(time.time() - start, 1)}
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        print(json.dumps(row), flush=True)
        with open(os.path.join(args.out, "learning_seeds.jsonl"), "a") as f:
            f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
