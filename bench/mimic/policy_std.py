"""How far a mimic run's exploration noise has come down: the policy's standard deviation per checkpoint.

    .venv/bin/python bench/mimic/policy_std.py RESULTS/RUN_ID/Mimic

Why: an untrained policy's noise (std 1 before the clip, about 1/3 in action units) topples the
ragdoll within a second, and a std near 0.05 in action units would let it stand for seconds
(bench/RESULTS.md, "mimic: decision rate"); PPO lowers the std only through its gradient steps,
and Adam moves ``log_sigma`` by at most about the learning rate per step. Per checkpoint (our
trainer's ``Mimic-STEP.pt``, in step order): the std before the clip averaged over the 26 axes, its
smallest value and the axes that have come down furthest.
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import torch

from unity_stub_env.tasks.mimic.motions import JOINTS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("behavior_dir", type=Path)
    args = parser.parse_args()
    checkpoints = sorted(args.behavior_dir.glob("Mimic-*.pt"), key=lambda p: int(re.findall(r"\d+", p.stem)[-1]))
    print("| checkpoint | mean std (pre-clip) | smallest | lowest axes |")
    print("|---|---:|---:|---|")
    for path in checkpoints:
        state = torch.load(path, map_location="cpu", weights_only=True)
        sigma = np.exp(state["Policy"]["log_sigma"].float().numpy().ravel())
        lowest = ", ".join(f"{JOINTS[i]} {sigma[i]:.3f}" for i in np.argsort(sigma)[:3])
        print(f"| {path.name} | {sigma.mean():.3f} | {sigma.min():.3f} | {lowest} |")


if __name__ == "__main__":
    main()
