"""Does one part of the trainer keep memory? Each part in a loop, in this process, after a warm-up.

    PYTHONPATH=$PWD .venv/bin/python bench/rss_parts.py [onnx checkpoint update act endpoint] [--scale 1]

The soak (bench/soak.py) saw the trainer's RSS rise with the steps it trains; this runs the parts
a step goes through one at a time, with the soak's network (stub:basic's 20-float observation,
3 discrete actions, 2 x 32 units, buffer 1024, batch 64, 3 epochs):

* ``onnx``: ``export_policy`` (one per checkpoint); ``checkpoint``: ``save_checkpoint`` of the
  policy's state (two per checkpoint);
* ``update``: 64 trajectories of 16 steps through ``process_trajectory``, then ``update()``: one
  PPO update, 1,024 steps;
* ``act``: 1,000 forward passes of 3 agents (``Policy.act``);
* ``endpoint``: ``UnityEndpoint`` against a stub:basic process, codec included, the trainer's side
  of the exchange (bench/protocol.py's endpoint row), 20,000 exchanges a round.

For each: RSS (/proc/self/status) and glibc's bytes in use (``mallinfo2``: ``uordblks + hblkhd``)
before and after, per round. A part that keeps memory grows both linearly; allocator
fragmentation grows RSS but not the bytes in use. Not a test: it asserts nothing. Results, dated:
bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import ctypes
import gc
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "bench")]


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]


def rss_mb() -> float:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) / 1024 for line in status if line.startswith("VmRSS:"))


def malloc_in_use_mb() -> float:
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return (info.uordblks + info.hblkhd) / 2**20


def parts():
    import numpy as np
    import torch

    from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
    from trainer.artifacts.checkpoints import save_checkpoint
    from trainer.artifacts.onnx_export import export_policy
    from trainer.common.trajectory import Trajectory
    from trainer.ppo.hyperparams import PPOHyperparams
    from trainer.ppo.trainer import PPOTrainer

    torch.set_num_threads(1)
    spec = BehaviorSpec((ObservationSpec((20,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                        ActionSpec(0, (3,)))
    hyper = PPOHyperparams(hidden_units=32, num_layers=2, batch_size=64, buffer_size=1024, num_epoch=3,
                           max_steps=10**9, reward_signals={"extrinsic": (0.9, 1.0)}, lambd=0.95, normalize=False)
    trainer = PPOTrainer("Basic", spec, hyper, seed=0)
    rng = np.random.default_rng(0)
    folder = tempfile.mkdtemp(prefix="rss-parts-")
    episodes = iter(range(1, 1 << 62))

    def trajectory(length: int = 16) -> Trajectory:
        obs = rng.normal(size=(length, 20)).astype(np.float32)
        out = trainer.policy.act([obs])
        episode = next(episodes)
        return Trajectory(obs=[obs], next_obs=[rng.normal(size=20).astype(np.float32)],
                          rewards=rng.normal(size=length).astype(np.float32), continuous_actions=out.continuous_raw,
                          discrete_actions=out.discrete, log_probs=out.log_probs, action_masks=None,
                          done=episode % 3 == 0, interrupted=False, episode=(1, episode))

    def update() -> None:
        for _ in range(64):
            trainer.process_trajectory(trajectory())
        trainer.update()

    def act() -> None:
        obs = [rng.normal(size=(3, 20)).astype(np.float32)]
        for _ in range(1000):
            trainer.policy.act(obs)

    def endpoint() -> None:
        import protocol

        protocol.bench_endpoint("basic", 1, 100, 20000)

    return {
        "onnx": (lambda: export_policy(trainer.policy, os.path.join(folder, "Basic.onnx")), 200, "export"),
        "checkpoint": (lambda: save_checkpoint(os.path.join(folder, "Basic.pt"), trainer.state_dict()), 500, "save"),
        "update": (update, 100, "update of 1,024 steps"),
        "act": (act, 100, "1,000 forward passes"),
        "endpoint": (endpoint, 4, "20,000 exchanges"),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="*", default=["onnx", "checkpoint", "update", "act", "endpoint"])
    ap.add_argument("--scale", type=float, default=1.0, help="multiply every part's rounds")
    args = ap.parse_args(argv)
    table = parts()
    print("| part | rounds | one round | RSS before → after (MB) | per round | bytes in use before → after (MB) | per round |")
    print("|---|---:|---|---|---:|---|---:|")
    for name in args.parts:
        run, rounds, unit = table[name]
        rounds = max(1, int(rounds * args.scale))
        for _ in range(max(1, rounds // 10)):  # warm-up: lazy imports, pools, caches
            run()
        gc.collect()
        rss0, used0, t0 = rss_mb(), malloc_in_use_mb(), time.monotonic()
        for _ in range(rounds):
            run()
        gc.collect()
        rss1, used1 = rss_mb(), malloc_in_use_mb()
        print(f"| {name} | {rounds} | {unit} | {rss0:.2f} → {rss1:.2f} | {(rss1 - rss0) * 1024 / rounds:+.2f} KB "
              f"| {used0:.2f} → {used1:.2f} | {(used1 - used0) * 1024 / rounds:+.2f} KB |  ({time.monotonic() - t0:.0f} s)",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
