"""How long an untrained policy keeps the mimic ragdoll up, at 50 and at 250 decisions per second.

    .venv/bin/python bench/mimic/decision_rate.py [--trials 32]

Why: the decision rate (environment parameter ``decision_hz``) is the task's default that should
let PPO learn from scratch, and what PPO first sees is its own exploration noise around its initial
mean (0 = the neutral standing pose in the default absolute mode). Per rate and noise level, every
decision draws fresh Gaussian actions of that standard deviation (clipped to [-1, 1]; PPO starts at
std 1 sent as clamp(a, -3, 3) / 3, i.e. about 1/3 in action units), on ``stand`` from its first
frame; printed: mean seconds before the fall (10 = never), the share that stood 10 s and the
percentage of the maximum reward. Equal noise per decision is what the trainer does at either rate.
"""
from __future__ import annotations

import argparse

import numpy as np

from unity_stub_env.tasks.mimic.evaluation import run_trials


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=32)
    parser.add_argument("--motion", type=int, default=0, help="0 stand, 1 arms, 2 squat, 3 walk")
    args = parser.parse_args()
    print("| action noise std | decisions/s | mean s up | stood 10 s | % of max reward |")
    print("|---|---|---|---|---|")
    for std in (1 / 3, 0.1, 0.05, 0.02):
        for hz in (50, 250):
            rng = np.random.default_rng(0)
            act = lambda obs: np.clip(rng.normal(scale=std, size=(len(obs), 26)), -1, 1)  # noqa: E731
            r = run_trials(act, args.motion, args.trials, 0, decision_hz=hz)
            print(f"| {std:.3g} | {hz} | {r['mean_seconds']:.2f} | {r['balance_kept']:.2f} | {r['percent_of_max']:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()
