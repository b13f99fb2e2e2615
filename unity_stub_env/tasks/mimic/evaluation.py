"""The ``mimic`` task's scripted evaluation: every motion for 10 s, then standing under pushes.

Per motion, ``trials`` ragdolls start at the clip's first frame (no RSI) and act for 10 s of
simulated time (500 decisions at 50 Hz, 2,500 at 250 Hz); then the standing ragdoll is pushed every PUSH_EVAL_INTERVAL s
with each impulse of PUSH_LADDER (N s; 70 kg: 10 N s changes the whole body's velocity by
0.14 m/s), in a random horizontal direction at the torso.

The percentage of the maximum reward is the mimic thesis' metric (docs/stub-tasks.md, "Seed
projects"): an episode of fixed length can earn at most 1 per decision (the weights sum to 1,
every term and the effort factor are <= 1), so a trial's reward summed over the 10 s, divided by
the decisions in 10 s, is that fraction; the decisions after a fall earn 0.
"""
from __future__ import annotations

import numpy as np

from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.mimic.motions import MOTIONS
from unity_stub_env.tasks.mimic.task import AGENTS_PER_AREA, DECISION_HZ, TERMS, MimicTask

EVAL_SECONDS = 10.0
PUSH_LADDER = (10.0, 15.0, 20.0, 30.0)
PUSH_EVAL_INTERVAL = 2.0


def run_trials(act, motion: int, trials: int, seed: int, push_impulse: float = 0.0,
               push_interval: float = PUSH_EVAL_INTERVAL, residual: float = 0.0,
               decision_hz: float = DECISION_HZ, effort_weight: float = 0.0) -> dict:
    """``trials`` episodes of EVAL_SECONDS with the policy ``act`` (float32 [n, 170] -> [n, 26]):
    the fraction that kept their balance (no early termination); over every decision before a
    trial ended, the mean of each reward term and of the reward; and the percentage of the maximum
    reward (see the module docstring)."""
    params = EnvironmentParameters()
    for key, value in (("motion", motion), ("rsi", 0), ("push_impulse", push_impulse),
                       ("push_interval", push_interval), ("residual", residual),
                       ("decision_hz", decision_hz), ("effort_weight", effort_weight)):
        params.set(key, lambda value=value: value)
    task = MimicTask(-(-trials // AGENTS_PER_AREA), seed, params)
    n = task.num_agents
    running = np.ones(n, dtype=bool)
    kept = np.zeros(n, dtype=bool)
    terms, reward, steps = np.zeros((n, 5)), np.zeros(n), np.zeros(n)
    decisions = round(EVAL_SECONDS * task.decision_hz)
    for _ in range(decisions):
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
    out = {"trials": int(trials), "balance_kept": float(kept.mean()),
           "mean_seconds": float(steps.mean() * task.control_dt), "mean_reward": float(reward.sum() / total),
           "percent_of_max": float(100.0 * reward.mean() / decisions)}
    out.update({term: float(terms[:, j].sum() / total) for j, term in enumerate(TERMS)})
    return out


def evaluate(act, seed: int = 0, episodes: int = 32, residual: float = 0.0, decision_hz: float = DECISION_HZ,
             effort_weight: float = 0.0) -> dict:
    """The scripted evaluation: every motion unpushed, then standing under the PUSH_LADDER."""
    rate = {"decision_hz": decision_hz, "effort_weight": effort_weight, "residual": residual}
    motions = {name: run_trials(act, m, episodes, seed, **rate) for m, name in enumerate(MOTIONS)}
    pushed = {f"{impulse:g}": run_trials(act, 0, episodes, seed, impulse, PUSH_EVAL_INTERVAL, **rate)
              for impulse in PUSH_LADDER}
    return {"motions": motions, "pushed_stand": pushed, "push_interval_s": PUSH_EVAL_INTERVAL}


def format_table(results: dict) -> str:
    """Markdown: per policy and motion the balance-kept rate and the mean reward terms; then the
    standing balance under pushes."""
    lines = ["| policy | motion | trials | balance kept 10 s | mean s | % of max reward | r_r | r_v | r_m | r_e | r_t "
             "| mean reward |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, result in results.items():
        for motion, s in result["motions"].items():
            lines.append(f"| {name} | {motion} | {s['trials']} | {s['balance_kept']:.3f} | {s['mean_seconds']:.2f} | "
                         f"{s['percent_of_max']:.1f} | {s['r_r']:.3f} | {s['r_v']:.3f} | {s['r_m']:.3f} | {s['r_e']:.3f} | {s['r_t']:.3f} | "
                         f"{s['mean_reward']:.3f} |")
    first = next(iter(results.values()))
    lines += ["", f"Standing, balance kept for 10 s under a push every {first['push_interval_s']:g} s (random "
              "horizontal direction, at the torso), per impulse:",
              "| policy | " + " | ".join(f"{k} N s" for k in first["pushed_stand"]) + " |",
              "|---|" + "---|" * len(first["pushed_stand"])]
    for name, result in results.items():
        lines.append(f"| {name} | " + " | ".join(f"{s['balance_kept']:.3f}" for s in result["pushed_stand"].values()) + " |")
    return "\n".join(lines)
