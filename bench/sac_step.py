"""One SAC gradient step, torch autograd against numpy (trainer/sac/numpy_step.py), same minibatch.

    .venv/bin/python bench/sac_step.py                         # basic and ball3d SAC configs
    .venv/bin/python bench/sac_step.py --task ball3d --steps 200 --repeats 9

For each task: the trainer its SAC config builds for the stub task's behavior (networks, batch
size, normalisation), a replay buffer filled with random experiences through the policy, then
``--repeats`` x ``--steps`` gradient steps on one fixed minibatch per path, alternating the
paths; prints the min and the median per step, and the ratio of the mins. One BLAS and torch
thread, as the trainer runs. Results: bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from protos.types import BehaviorSpec  # noqa: E402
from trainer.sac.hyperparams import SACHyperparams  # noqa: E402
from trainer.config.cli_args import parse_run_options  # noqa: E402
from trainer.common.trajectory import Trajectory
from trainer.sac.trainer import SACTrainer  # noqa: E402
from unity_stub_env.tasks import make_task  # noqa: E402

CONFIGS = {"basic": "configs/basic_sac.yaml", "ball3d": "configs/ball3d_sac.yaml"}


def build(task: str, numpy: bool) -> tuple[SACTrainer, dict[str, np.ndarray]]:
    stub = make_task(task)
    brain, _ = stub.behaviors()[0]
    options = parse_run_options([CONFIGS[task]])
    brain = brain.split("?")[0]
    hp = SACHyperparams.from_settings(options.behaviors[brain])
    spec = BehaviorSpec(tuple(stub.observation_specs), stub.action_spec)
    trainer = SACTrainer(brain, spec, hp, seed=1)
    if not numpy:
        trainer._numpy_step = None
    rng = np.random.default_rng(0)
    branches = spec.action_spec.discrete_branches
    for k in range(20):  # 20 trajectories of 50 experiences
        obs = [rng.standard_normal((50, *o.shape)).astype(np.float32) for o in spec.observation_specs]
        mask = np.zeros((50, sum(branches)), dtype=bool) if branches else None
        out = trainer.policy.act(obs, mask)
        trainer.process_trajectory(Trajectory(obs, [o[-1] for o in obs], rng.standard_normal(50).astype(np.float32),
                                              out.continuous_raw, out.discrete, out.log_probs, mask, k % 3 == 0,
                                              False, episode=k))
    batch = trainer.buffer.sample(hp.batch_size, torch.Generator().manual_seed(0))
    return trainer, batch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=sorted(CONFIGS), action="append")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"load average at start: {os.getloadavg()}")
    print("| task | path | min ms/step | median ms/step | torch/numpy (min) |")
    print("|---|---|---:|---:|---:|")
    for task in args.task or sorted(CONFIGS):
        runs = {path: build(task, path == "numpy") for path in ("torch", "numpy")}
        times: dict[str, list[float]] = {"torch": [], "numpy": []}
        for _ in range(args.repeats):
            for path, (trainer, batch) in runs.items():
                start = time.perf_counter()
                for _ in range(args.steps):
                    trainer.gradient_step(batch)
                times[path].append((time.perf_counter() - start) / args.steps * 1e3)
        ratio = min(times["torch"]) / min(times["numpy"])
        for path in ("torch", "numpy"):
            last = f"{ratio:.1f}×" if path == "numpy" else ""
            print(f"| {task} | {path} | {min(times[path]):.3f} | {np.median(times[path]):.3f} | {last} |")
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
