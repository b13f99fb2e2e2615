"""The ``mimic`` task's scripted evaluation: every motion for 10 s, then standing under pushes.

Per motion, ``trials`` ragdolls start at the clip's first frame (no RSI) and act for 10 s of
simulated time (500 decisions); then the standing ragdoll is pushed every PUSH_EVAL_INTERVAL s
with each impulse of PUSH_LADDER (N s; 70 kg: 10 N s changes the whole body's velocity by
0.14 m/s), in a random horizontal direction at the torso.
"""
from __future__ import annotations

import numpy as np

from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.mimic.motions import MOTIONS
from unity_stub_env.tasks.mimic.task import AGENTS_PER_AREA, CONTROL_DT, TERMS, MimicTask

EVAL_SECONDS = 10.0
PUSH_LADDER = (10.0, 15.0, 20.0, 30.0)
PUSH_EVAL_INTERVAL = 2.0


def run_trials(act, motion: int, trials: int, seed: int, push_impulse: float = 0.0,
               push_interval: float = PUSH_EVAL_INTERVAL, residual: float = 0.0) -> dict:
    """``trials`` episodes of EVAL_SECONDS with the policy ``act`` (float32 [n, 170] -> [n, 26]):
    the fraction that kept their balance (no early termination) and, over every decision before a
    trial ended, the mean of each reward term and of the reward."""
    params = EnvironmentParameters()
    for key, value in (("motion", motion), ("rsi", 0), ("push_impulse", push_impulse),
                       ("push_interval", push_interval), ("residual", residual)):
        params.set(key, lambda value=value: value)
    task = MimicTask(-(-trials // AGENTS_PER_AREA), seed, params)
    n = task.num_agents
    running = np.ones(n, dtype=bool)
    kept = np.zeros(n, dtype=bool)
    terms, reward, steps = np.zeros((n, 5)), np.zeros(n), np.zeros(n)
    for _ in range(round(EVAL_SECONDS / CONTROL_DT)):
        result = task.step(np.asarray(act(task.observe()[0]), dtype=np.float64), np.zeros((n, 0)))
        terms[running] += task.last_terms[running]
        reward[running] += result.rewards[running]
        steps[running] += 1
        kept |= running & result.interrupted
        running &= ~result.done
        if not running.any():
            break
    kept, terms, reward, steps = kept[:trials], terms[:trials], reward[:trials], steps[:trials]
    total = steps.sum()
    out = {"trials": int(trials), "balance_kept": float(kept.mean()), "mean_seconds": float(steps.mean() * CONTROL_DT),
           "mean_reward": float(reward.sum() / total)}
    out.update({term: float(terms[:, j].sum() / total) for j, term in enumerate(TERMS)})
    return out


def evaluate(act, seed: int = 0, episodes: int = 32, residual: float = 0.0) -> dict:
    """The scripted evaluation: every motion unpushed, then standing under the PUSH_LADDER."""
    motions = {name: run_trials(act, m, episodes, seed, residual=residual) for m, name in enumerate(MOTIONS)}
    pushed = {f"{impulse:g}": run_trials(act, 0, episodes, seed, impulse, PUSH_EVAL_INTERVAL, residual)
              for impulse in PUSH_LADDER}
    return {"motions": motions, "pushed_stand": pushed, "push_interval_s": PUSH_EVAL_INTERVAL}


def format_table(results: dict) -> str:
    """Markdown: per policy and motion the balance-kept rate and the mean reward terms; then the
    standing balance under pushes."""
    lines = ["| policy | motion | trials | balance kept 10 s | mean s | r_r | r_v | r_m | r_e | r_t | mean reward |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, result in results.items():
        for motion, s in result["motions"].items():
            lines.append(f"| {name} | {motion} | {s['trials']} | {s['balance_kept']:.3f} | {s['mean_seconds']:.2f} | "
                         f"{s['r_r']:.3f} | {s['r_v']:.3f} | {s['r_m']:.3f} | {s['r_e']:.3f} | {s['r_t']:.3f} | "
                         f"{s['mean_reward']:.3f} |")
    first = next(iter(results.values()))
    lines += ["", f"Standing, balance kept for 10 s under a push every {first['push_interval_s']:g} s (random "
              "horizontal direction, at the torso), per impulse:",
              "| policy | " + " | ".join(f"{k} N s" for k in first["pushed_stand"]) + " |",
              "|---|" + "---|" * len(first["pushed_stand"])]
    for name, result in results.items():
        lines.append(f"| {name} | " + " | ".join(f"{s['balance_kept']:.3f}" for s in result["pushed_stand"].values()) + " |")
    return "\n".join(lines)
