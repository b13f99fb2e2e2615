"""``unity-stub-env --task TASK --evaluate POLICY``: a task's scripted evaluation, without a trainer.

POLICY is a trained ``.onnx`` file (the model a run exports; run with onnxruntime, taking the
ONNX contract's ``deterministic_continuous_actions``, i.e. the mean action), ``zero`` (every action
0), ``random`` (uniform in [-1, 1], seeded) or ``scripted`` (the task's hand-written expert from
its observations: mimic's ``BalanceExpert``, standing with an ankle strategy against pushes, in the
default absolute mode). ``--evaluate`` may be repeated; the zero and random
baselines are always evaluated beside it. Printed per policy, for the scripted and the random
throws: hit rate, the hit rate of the throws aimed above the pelvis (with their count: the ones
fixed feet leave dodgeable), balance-loss rate, pass rate, mean effort (the effort terms' magnitudes summed
over an episode, averaged over the episodes) and mean episode return. ``mimic``: per reference motion,
the fraction of trials that kept their balance for 10 s, the percentage of the maximum reward
and the mean reward terms r_r, r_v, r_m, r_e, r_t; then standing under pushes of growing impulse (``unity_stub_env.tasks.mimic.evaluate``), with
an extra row for the PD controllers tracking the reference on their own. Tasks with an evaluation
are the keys of ``_evaluations``.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Callable

import numpy as np

BASELINES = ("zero", "random")


class PolicyError(ValueError):
    """The policy cannot be used for this task (missing file, wrong shapes, no onnxruntime)."""


def _evaluations() -> dict:
    """task -> (evaluate(act, seed, episodes, **options), format_table(results), default episodes)."""
    from unity_stub_env.tasks import dodge, mimic

    return {"dodge": (dodge.evaluate, format_table, 500), "mimic": (mimic.evaluate, mimic.format_table, 32)}


# The options ``--evaluate-option KEY=VALUE`` may set, per task (float values).
OPTIONS = {"mimic": ("residual", "decision_hz", "effort_weight")}


# Rows a task evaluates beside the baselines: label -> (policy, the task's evaluate options).
# mimic: zero actions in residual mode, i.e. the PD controllers tracking the reference unaided.
EXTRA_ROWS = {"mimic": {"reference PD": ("zero", {"residual": 1.0})}}


def scripted_policy(task_name: str) -> Callable[[np.ndarray], np.ndarray]:
    """The task's hand-written expert acting on observations (``--evaluate scripted``)."""
    if task_name != "mimic":
        raise PolicyError(f"policy 'scripted': task {task_name} has no scripted expert for --evaluate (mimic has)")
    from unity_stub_env.tasks.mimic import BalanceExpert

    return BalanceExpert()


def load_policy(spec: str, observation_size: int, action_size: int, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """The action function of ``spec``: float32 [n, observation_size] -> [n, action_size]."""
    if spec == "zero":
        return lambda obs: np.zeros((len(obs), action_size), dtype=np.float32)
    if spec == "random":
        rng = np.random.default_rng(seed)
        return lambda obs: rng.uniform(-1.0, 1.0, (len(obs), action_size)).astype(np.float32)
    path = Path(spec)
    if not path.is_file():
        raise PolicyError(f"policy {spec!r} is neither 'zero', 'random' nor an existing .onnx file")
    try:
        import onnxruntime
    except ImportError as error:
        raise PolicyError("evaluating an .onnx policy needs onnxruntime: pip install onnxruntime") from error
    try:
        session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    except Exception as error:  # onnxruntime raises its own exception types for bad files
        raise PolicyError(f"{spec}: not a loadable ONNX model ({error})") from error
    inputs = {i.name: i.shape for i in session.get_inputs()}
    outputs = {o.name for o in session.get_outputs()}
    if set(inputs) != {"obs_0"} or "deterministic_continuous_actions" not in outputs:
        raise PolicyError(f"{spec}: expected one input obs_0 and the output deterministic_continuous_actions "
                          f"(an ML-Agents continuous-action model), found inputs {sorted(inputs)}")
    if inputs["obs_0"][-1] != observation_size:
        raise PolicyError(f"{spec}: obs_0 has {inputs['obs_0'][-1]} values per agent, the task observes "
                          f"{observation_size}")

    def act(obs: np.ndarray) -> np.ndarray:
        (actions,) = session.run(["deterministic_continuous_actions"], {"obs_0": np.asarray(obs, np.float32)})
        if actions.shape[-1] != action_size:
            raise PolicyError(f"{spec}: the model gives {actions.shape[-1]} actions, the task needs {action_size}")
        return actions

    return act


def parse_options(task_name: str, pairs: list[str]) -> dict[str, float]:
    """``["residual=0.25"]`` -> ``{"residual": 0.25}``; PolicyError names the task's known options."""
    known, options = OPTIONS.get(task_name, ()), {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        if key not in known:
            raise PolicyError(f"--evaluate-option {pair!r}: task {task_name} takes "
                              f"{', '.join(k + '=NUMBER' for k in known) or 'no options'}")
        try:
            options[key] = float(value)
        except ValueError:
            raise PolicyError(f"--evaluate-option {pair!r}: {value!r} is not a number") from None
    return options


def run(task_name: str, policies: list[str], seed: int, episodes: int | None, json_path: str | None = None,
        option_pairs: list[str] | None = None, video_dir: str | None = None) -> int:
    """Evaluate every policy (baselines added), print a table; exit code 0, or 2 on bad input."""
    evaluations = _evaluations()
    if task_name not in evaluations:
        print(f"unity-stub-env: task {task_name!r} has no scripted evaluation; tasks with one: "
              f"{', '.join(sorted(evaluations))}.", file=sys.stderr)
        return 2
    evaluate, format_results, default_episodes = evaluations[task_name]
    episodes = default_episodes if episodes is None else episodes
    if episodes < 1:
        print(f"unity-stub-env: --episodes must be 1 or more, got {episodes}.", file=sys.stderr)
        return 2
    from unity_stub_env.tasks import TASKS

    task_class = TASKS[task_name]
    observation_size = int(math.prod(task_class.observation_specs[0].shape))
    action_size = task_class.action_spec.continuous_size
    names = list(dict.fromkeys([*policies, *BASELINES]))
    try:
        options = parse_options(task_name, option_pairs or [])
        actors = {name: scripted_policy(task_name) if name == "scripted" else
                  load_policy(name, observation_size, action_size, seed) for name in names}
        results = {name: evaluate(actors[name], seed=seed, episodes=episodes, **options) for name in names}
        for label, (policy, extra) in EXTRA_ROWS.get(task_name, {}).items():
            results[label] = evaluate(actors[policy], seed=seed, episodes=episodes, **{**options, **extra})
    except PolicyError as error:
        print(f"unity-stub-env: {error}", file=sys.stderr)
        return 2
    print(format_results(results))
    if video_dir is not None:  # one clip per scripted case of each policy asked for (unity_stub_env.render)
        from unity_stub_env.render import RenderError
        from unity_stub_env.render.evaluate_clips import write

        try:
            clips = write(task_name, {name: actors[name] for name in dict.fromkeys(policies)}, seed, video_dir,
                          options)
        except RenderError as error:
            print(f"unity-stub-env: {error}", file=sys.stderr)
            return 2
        print(f"Wrote {len(clips)} clips to {video_dir}")
    if json_path:
        Path(json_path).write_text(json.dumps({"task": task_name, "seed": seed, "options": options,
                                               "results": results}, indent=1))
    return 0


def format_table(results: dict) -> str:
    """dodge's table. Markdown: one row per policy and throw set, then each policy's scripted throws."""
    lines = ["| policy | throws | episodes | hit rate | upper-body hit rate | balance-loss rate | pass rate | "
             "mean effort | mean return |", "|---|---|---|---|---|---|---|---|---|"]
    for name, result in results.items():
        for part in ("scripted", "random"):
            s = result[part]
            lines.append(f"| {name} | {part} | {s['episodes']} | {s['hit_rate']:.3f} | "
                         f"{s['upper_body_hit_rate']:.3f} ({s['upper_body_throws']}) | {s['balance_loss_rate']:.3f} | "
                         f"{s['pass_rate']:.3f} | {s['mean_effort']:.3f} | {s['mean_return']:.3f} |")
    for name, result in results.items():
        outcomes = ", ".join(f"{t['throw']} {t['side']}/{t['mark']}: {t['outcome']}" for t in result["scripted_throws"])
        lines.append(f"\n{name}, scripted throws: {outcomes}")
    return "\n".join(lines)
