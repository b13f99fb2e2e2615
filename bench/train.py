"""Training benchmark (run by hand, not a test): our trainer vs the real ``mlagents-learn`` 1.1.0.

    .venv/bin/python bench/train.py [--task basic|ball3d|dodge|creature] [--config YAML] [--max-steps N]
                                    [--num-areas N] [--seed S | --seeds S ...] [--pairs P] [--out bench/out]

One run trains the same stub task with the same YAML twice, one process after the other:
  (1) ours:      ``.venv/bin/mlagents-like-learn CONFIG --env stub:TASK``
  (2) reference: ``.venv-interop/bin/mlagents-learn CONFIG --env <tmp>/Stub<Task>.x86_64``, a shell
                 launcher that execs this interpreter's ``-m unity_stub_env.cli --task TASK``.
Both get the same ``--seed``, ``--num-areas``, a fresh results dir and a fresh port, and the same
simulator: the launcher passes the stub the ``--spin-wait-ms`` that our trainer passes it for one
environment on this machine (protos/pacing.py, trainer/envs/cpus.py).

The YAML is copied to a temp dir and, for BOTH trainers alike, ``max_steps`` is overridden when
``--max-steps`` is given and ``checkpoint_interval`` is raised above ``max_steps``: mlagents 1.1.0
exports ONNX at every checkpoint with ``torch.onnx.export`` (dynamo by default on torch 2.13, which
needs ``onnxscript``), so a checkpoint inside the run would crash the reference. Its FINAL export
still fails (exit code 1, ``No module named 'onnxscript'``) after the last summary was written:
torch 2.13's ``torch.onnx.export`` defaults to the dynamo exporter, which needs onnxscript, and
its older TorchScript exporter (``dynamo=False``) needs ``onnx``, whose release in the interop venv
needs protobuf >= 5 where ML-Agents pins 3.20.3. That outcome is recorded and the run is still
measured from its TensorBoard events. The crash skips the rest of the reference's final save (the
first behavior's ONNX, every other behavior's checkpoint and ONNX, timers.json), which ours does:
so besides the process wall time, both are also timed to their last summary (``to_last_summary_s``:
process start to the wall time of the last summary event, before either's final save), the like-
with-like comparison while the reference cannot finish.

Reported per trainer:
  * wall_s            process start to exit (imports, env launch, training, final save/export)
  * to_last_summary_s process start to the last summary's event wall time (no final save/export);
                      agent_steps_per_s_to_last_summary = final summary step / it
  * agent_steps_per_s final summary step / wall_s (steps count agent-steps, as in ML-Agents)
  * steady_steps_per_s (last - first summary step) / (their event wall_time difference): no startup
  * cpu_s, agent_steps_per_cpu_s  user+sys CPU of the trainer and its reaped children (the stub):
                      less sensitive than wall time to other processes sharing the cores
  * simulator_cpu_s, trainer_cpu_s, agent_steps_per_trainer_cpu_s  the stub logs its own CPU time
                      at exit (Player-<i>.log); subtracted from cpu_s it leaves what the trainer
                      itself (with mlagents-learn: and its env worker process) costs
  * mean reward (``Environment/Cumulative Reward``) at every summary step, side by side
Then the speed ratios and whether our reward over the last 3 common summaries is no worse.

``--reference-tree DIR`` replaces (2) with our own trainer from another source tree (e.g. a git
worktree of an older commit, ``git worktree add /tmp/old <commit>``), run with ``PYTHONPATH=DIR``
so its trainer and the stub it launches are both that tree's: an A/B of two versions of this
project on the same YAML, seeds and ports, alternating which goes first. The ratio is then
new/old (1.00 = no change; the 10x target does not apply).
Prints a markdown table; writes JSON to ``<out>/train_<task>.json``.
Target: ours >= 10x the reference's agent-steps/s with reward at equal steps no worse.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from trainer.config.env_vars import EnvVars
from trainer.envs.cpus import spin_budget
from unity_stub_env.launcher import spin_wait_args, transport_args, write_player_launcher
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

REPO = Path(__file__).resolve().parents[1]
OUR_LEARN = REPO / ".venv" / "bin" / "mlagents-like-learn"
REFERENCE_LEARN = REPO / ".venv-interop" / "bin" / "mlagents-learn"
OUR_PYTHON = REPO / ".venv" / "bin" / "python"  # runs the stub behind the reference
REWARD_TAG = "Environment/Cumulative Reward"
TARGET_SPEEDUP = 10.0
REWARD_TOLERANCE = 1e-6  # relative, for float32 rounding of episode returns
LAST_SUMMARIES = 3
ONNXSCRIPT_FAILURE = "No module named 'onnxscript'"
# --task 2x20k: two behaviors x 8 agents, 20k steps each, on the stub's mirror task (bench/startup.py)
STUB_TASKS = {"2x20k": f"mirror={REPO / 'bench' / 'startup' / 'two_behaviors.json'}"}
CONFIGS = {"2x20k": REPO / "bench" / "startup" / "two_behaviors.yaml"}


def free_port() -> int:
    """A port free on 127.0.0.1 and on the IPv6 wildcard (mlagents binds ``[::]:port``)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        try:
            with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe6:
                probe6.bind(("::", port))
        except OSError:
            continue
        return port
    raise RuntimeError("no free TCP port found")


def stub_launcher(folder: Path, task: str) -> Path:
    """``folder/Stub<Task>.x86_64``: a Unity-build-like shell launcher of the stub (our venv's Python)."""
    # the stub polls as mlagents-like-learn would have it poll for --num-envs 1 (trainer/envs/pool.py)
    env_vars = EnvVars.from_environ()
    return write_player_launcher(folder, [task], python=str(OUR_PYTHON),
                                 extra_args=spin_wait_args(spin_budget(2, env_vars.spin_wait_s))
                                 + transport_args(env_vars.transport))


def write_bench_config(source: Path, target: Path, max_steps: int | None) -> dict:
    """Copy the trainer YAML with ``max_steps`` overridden and checkpoints pushed past the end."""
    config = yaml.safe_load(source.read_text())
    for settings in [config.get("default_settings") or {}, *config["behaviors"].values()]:
        if max_steps is not None:
            settings["max_steps"] = max_steps
        settings["checkpoint_interval"] = 100 * int(settings.get("max_steps", 500000))
    target.write_text(yaml.safe_dump(config, sort_keys=False))
    return config


def children_cpu_seconds() -> float:
    """User + system CPU seconds of all waited-for descendants (trainer and the stub it reaped)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_trainer(command: list[str], cwd: Path, env: dict[str, str], timeout: float,
                log_path: Path) -> dict:
    """Run one trainer process (output to log_path); returns exit code, wall seconds, output tail."""
    cpu_before = children_cpu_seconds()
    started_at = time.time()  # the clock of the summary events' wall_time
    started = time.perf_counter()
    with open(log_path, "w") as log:
        completed = subprocess.run(command, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                   timeout=timeout)
    wall = time.perf_counter() - started
    cpu = children_cpu_seconds() - cpu_before
    output = log_path.read_text(errors="replace")
    return {"returncode": completed.returncode, "wall_s": wall, "started_at": started_at, "cpu_s": cpu,
            "output_tail": output[-3000:],
            "onnx_export_failed": ONNXSCRIPT_FAILURE in output, "log": str(log_path)}


def read_rewards(behavior_dir: Path) -> list[dict]:
    """``[{step, wall_time, value}]`` of the cumulative-reward scalar, in step order."""
    events = EventAccumulator(str(behavior_dir), size_guidance={"scalars": 0})
    events.Reload()
    if REWARD_TAG not in events.Tags().get("scalars", []):
        return []
    return [{"step": e.step, "wall_time": e.wall_time, "value": e.value}
            for e in sorted(events.Scalars(REWARD_TAG), key=lambda e: e.step)]


def read_timers(run_dir: Path) -> dict | None:
    """The run's ``run_logs/timers.json`` tree (both trainers write one), or None."""
    try:
        return json.loads((run_dir / "run_logs" / "timers.json").read_text())
    except (OSError, ValueError):
        return None


def timers_total(timers: dict | None) -> float | None:
    try:
        return float(timers["total"])
    except (KeyError, ValueError, TypeError):
        return None


_STUB_CPU_LINE = re.compile(r"CPU time ([0-9.]+) s \(user")


def simulator_cpu_seconds(run_dir: Path) -> float | None:
    """CPU seconds the stub reported for itself at exit, summed over the run's Player logs
    (both trainers pass ``-logFile <results>/<run-id>/run_logs/Player-<i>.log``); None if absent."""
    total, found = 0.0, False
    for log in sorted((run_dir / "run_logs").glob("Player-*.log")):
        values = _STUB_CPU_LINE.findall(log.read_text(errors="replace"))
        if values:
            total += float(values[-1])
            found = True
    return total if found else None


def summarize(label: str, run: dict, rewards: list[dict], run_dir: Path) -> dict:
    """Rates from the process wall time and from the summary events' own wall times."""
    final_step = rewards[-1]["step"] if rewards else 0
    simulator_cpu = simulator_cpu_seconds(run_dir)
    trainer_cpu = run["cpu_s"] - simulator_cpu if simulator_cpu is not None else None
    timers = read_timers(run_dir)
    steady = None
    if len(rewards) >= 2:
        span = rewards[-1]["wall_time"] - rewards[0]["wall_time"]
        steady = (rewards[-1]["step"] - rewards[0]["step"]) / span if span > 0 else None
    to_last = rewards[-1]["wall_time"] - run["started_at"] if rewards else None
    return {"trainer": label, **run, "final_step": final_step,
            "agent_steps_per_s": final_step / run["wall_s"] if run["wall_s"] > 0 else None,
            "to_last_summary_s": to_last,
            "agent_steps_per_s_to_last_summary": final_step / to_last if to_last and to_last > 0 else None,
            "agent_steps_per_cpu_s": final_step / run["cpu_s"] if run["cpu_s"] > 0 else None,
            "simulator_cpu_s": simulator_cpu, "trainer_cpu_s": trainer_cpu,
            "agent_steps_per_trainer_cpu_s": final_step / trainer_cpu if trainer_cpu else None,
            "steady_steps_per_s": steady, "timers_total_s": timers_total(timers),
            "timers": timers, "rewards": rewards}


def train(label: str, learn: Path, env_arg: str, config: Path, workdir: Path, args,
          behavior: str, env: dict[str, str]) -> dict:
    workdir.mkdir(parents=True, exist_ok=True)
    results = workdir / "results"
    command = [str(learn), str(config), "--env", env_arg, "--run-id", label,
               "--results-dir", str(results), "--base-port", str(free_port()),
               "--seed", str(args.seed), "--no-graphics"]
    if args.num_areas is not None:
        command += ["--num-areas", str(args.num_areas)]
    print(f"[{label}] {' '.join(command)}", flush=True)
    log_path = args.out / f"train_{args.task}_{label}.log"
    run = run_trainer(command, workdir, env, args.timeout, log_path)
    run_dir = results / label
    summary = summarize(label, run, read_rewards(run_dir / behavior), run_dir)
    print(f"[{label}] exit {run['returncode']} after {run['wall_s']:.1f} s, "
          f"final step {summary['final_step']}", flush=True)
    return summary


def compare(ours: dict, reference: dict) -> dict:
    """Speed ratios and the reward check over the last common summary steps."""
    ref_by_step = {r["step"]: r["value"] for r in reference["rewards"]}
    common = [r["step"] for r in ours["rewards"] if r["step"] in ref_by_step]
    last = common[-LAST_SUMMARIES:]
    ours_by_step = {r["step"]: r["value"] for r in ours["rewards"]}
    ours_mean = sum(ours_by_step[s] for s in last) / len(last) if last else None
    ref_mean = sum(ref_by_step[s] for s in last) / len(last) if last else None

    def ratio(key: str) -> float | None:
        a, b = ours.get(key), reference.get(key)
        return a / b if a and b else None

    speedup = ratio("agent_steps_per_s")
    # no worse up to float32 rounding: a return summed in float32 (the reference's 1000 x 0.1 is
    # 100.000015) is not better than the same return summed in float64 (100.0)
    reward_ok = (ours_mean is not None and ref_mean is not None
                 and ours_mean >= ref_mean - REWARD_TOLERANCE * max(1.0, abs(ref_mean)))
    return {"speedup_agent_steps_per_s": speedup, "speedup_steady": ratio("steady_steps_per_s"),
            "speedup_to_last_summary": ratio("agent_steps_per_s_to_last_summary"),
            "speedup_per_cpu_s": ratio("agent_steps_per_cpu_s"),
            "speedup_per_trainer_cpu_s": ratio("agent_steps_per_trainer_cpu_s"),
            "compared_steps": last, "ours_last_mean_reward": ours_mean,
            "reference_last_mean_reward": ref_mean, "reward_no_worse": reward_ok,
            "target_met": bool(speedup and speedup >= TARGET_SPEEDUP and reward_ok)}


def rewards_over_seeds(pairs: list[dict]) -> dict:
    """``--seeds``: the two trainers' mean reward at each summary step both wrote, averaged over the
    seeds, and per seed the mean over those steps (the area under its curve, so a seed that learns
    sooner scores higher). The per-seed differences (ours - reference) give a paired mean and its
    standard error: one seed's luck is visible as such, not as a verdict."""
    curves = []
    for pair in pairs:
        ours = {r["step"]: r["value"] for r in pair["ours"]["rewards"]}
        ref = {r["step"]: r["value"] for r in pair["reference"]["rewards"]}
        curves.append((pair["seed"], ours, ref, sorted(set(ours) & set(ref))))
    steps = sorted(set.intersection(*(set(c[3]) for c in curves)))
    per_step = [(step, statistics.fmean(c[1][step] for c in curves), statistics.fmean(c[2][step] for c in curves))
                for step in steps]
    per_seed = [(seed, statistics.fmean(ours[s] for s in steps), statistics.fmean(ref[s] for s in steps))
                for seed, ours, ref, _ in curves]
    diffs = [o - r for _, o, r in per_seed]
    mean_diff = statistics.fmean(diffs)
    sem = statistics.stdev(diffs) / len(diffs) ** 0.5 if len(diffs) > 1 else None
    lines = ["", f"### rewards over {len(curves)} seeds (mean reward per summary step, averaged over the seeds)", "",
             "| step | ours | reference |", "|---|---:|---:|"]
    lines += [f"| {step} | {o:.3f} | {r:.3f} |" for step, o, r in per_step]
    lines += ["", "| seed | ours: mean over the steps | reference | ours - reference |", "|---|---:|---:|---:|"]
    lines += [f"| {seed} | {o:.3f} | {r:.3f} | {o - r:+.3f} |" for seed, o, r in per_seed]
    lines += ["", f"mean over seeds: ours {statistics.fmean(o for _, o, _ in per_seed):.3f}, reference "
                  f"{statistics.fmean(r for _, _, r in per_seed):.3f}; paired difference {mean_diff:+.3f} "
                  f"(standard error {fmt(sem, '.3f')}; ours ahead on {sum(d > 0 for d in diffs)} of {len(diffs)} seeds)"]
    return {"steps": steps, "per_step": per_step, "per_seed": per_seed, "mean_difference": mean_diff,
            "standard_error": sem, "markdown": "\n".join(lines)}


def fmt(value, spec: str = ".1f") -> str:
    return "-" if value is None else format(value, spec)


def ratios_line(pairs: list[dict], key: str, label: str) -> str:
    """One verdict ratio over the pairs, sorted, and its median; a pair without it (a run that
    wrote no summary) is counted, not given a ratio."""
    ratios = sorted(p["verdict"][key] for p in pairs if p["verdict"][key] is not None)
    missing = len(pairs) - len(ratios)
    median = f"; median {statistics.median(ratios):.2f}x" if ratios else ""
    return (f"{len(pairs)} pairs, speed ratios {label}: " + ", ".join(f"{r:.2f}x" for r in ratios) + median
            + (f"; {missing} without one" if missing else ""))


def markdown(task: str, ours: dict, reference: dict, verdict: dict) -> str:
    lines = [f"### train benchmark: {task}", "",
             "| trainer | exit | wall s | to last summary s | CPU s | of which simulator | final step "
             "| agent-steps/s | steady steps/s | agent-steps/CPU-s | agent-steps/trainer-CPU-s | timers total s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in (ours, reference):
        lines.append(f"| {row['trainer']} | {row['returncode']} | {fmt(row['wall_s'])} | "
                     f"{fmt(row['to_last_summary_s'], '.2f')} | {fmt(row['cpu_s'])} | {fmt(row['simulator_cpu_s'])} | {row['final_step']} | "
                     f"{fmt(row['agent_steps_per_s'])} | {fmt(row['steady_steps_per_s'])} | "
                     f"{fmt(row['agent_steps_per_cpu_s'])} | {fmt(row['agent_steps_per_trainer_cpu_s'])} | "
                     f"{fmt(row['timers_total_s'])} |")
    lines += ["", "| step | ours reward | reference reward |", "|---|---|---|"]
    ref_by_step = {r["step"]: r["value"] for r in reference["rewards"]}
    ours_by_step = {r["step"]: r["value"] for r in ours["rewards"]}
    for step in sorted(set(ref_by_step) | set(ours_by_step)):
        lines.append(f"| {step} | {fmt(ours_by_step.get(step), '.3f')} | "
                     f"{fmt(ref_by_step.get(step), '.3f')} |")
    lines += ["",
              f"speed ratio (agent-steps/s): {fmt(verdict['speedup_agent_steps_per_s'], '.2f')}x, "
              f"to the last summary (no final save): {fmt(verdict['speedup_to_last_summary'], '.2f')}x, "
              f"steady-state: {fmt(verdict['speedup_steady'], '.2f')}x, per CPU-second: "
              f"{fmt(verdict['speedup_per_cpu_s'], '.2f')}x, per trainer CPU-second (the simulator's own "
              f"CPU, from its log, subtracted): {fmt(verdict['speedup_per_trainer_cpu_s'], '.2f')}x "
              f"(target >= {TARGET_SPEEDUP:g}x on agent-steps/s)",
              f"mean reward over steps {verdict['compared_steps']}: ours "
              f"{fmt(verdict['ours_last_mean_reward'], '.3f')} vs reference "
              f"{fmt(verdict['reference_last_mean_reward'], '.3f')} -> no worse: "
              f"{verdict['reward_no_worse']}",
              f"target met: {verdict['target_met']}"]
    return "\n".join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=("basic", "ball3d", "dodge", "creature", "2x20k"), default="ball3d")
    parser.add_argument("--config", type=Path, default=None, help="default configs/<task>.yaml")
    parser.add_argument("--max-steps", type=int, default=None)
    parser.add_argument("--num-areas", type=int, default=None)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="one pair per seed (alternating which trainer goes first) and the rewards "
                             "compared over the seeds: per summary step and per seed (replaces --seed/--pairs)")
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "out")
    parser.add_argument("--timeout", type=float, default=3600.0, help="per trainer, seconds")
    parser.add_argument("--reference-tree", type=Path, default=None,
                        help="A/B against our trainer from this source tree instead of mlagents-learn")
    parser.add_argument("--pairs", type=int, default=1,
                        help="run N pairs, alternating which trainer goes first, and report every pair's "
                             "ratio and their median (this machine's speed drifts between runs)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.seeds and args.pairs > 1:
        print("--seeds runs one pair per seed; drop --pairs")
        return 2
    seeds = args.seeds or [args.seed] * max(1, args.pairs)
    source = args.config or CONFIGS.get(args.task) or REPO / "configs" / f"{args.task}.yaml"
    stub_task = STUB_TASKS.get(args.task, args.task)
    for needed in (OUR_LEARN,) if args.reference_tree else (OUR_LEARN, REFERENCE_LEARN):
        if not needed.exists():
            print(f"missing {needed}: run ./scripts/ensure_interop_venv.sh / install the project")
            return 2
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # neither trainer may see the other's packages
    # both trainers start from byte-compiled modules: pip compiled the wheels, and the venv
    # script compiles our editable tree (again here, in case it changed since). A git worktree
    # that shares another tree's venv must not re-point its editable install: it only compiles
    # its own tree, and "ours" runs that tree (PYTHONPATH).
    installed = subprocess.run([str(OUR_PYTHON), "-I", "-c", "import trainer; print(trainer.__file__)"], env=env,
                               capture_output=True, text=True).stdout.strip()
    if installed and Path(installed).resolve().parents[1] == REPO.resolve():
        subprocess.run([str(REPO / "scripts" / "ensure_venv.sh")], check=True)
    else:
        subprocess.run([str(OUR_PYTHON), "-m", "compileall", "-q", *(str(REPO / p) for p in
                        ("trainer", "unity_stub_env", "protos"))], check=True, stdout=subprocess.DEVNULL)
    ours_env = {**env, "PYTHONPATH": str(REPO)}
    reference_env = env
    if args.reference_tree:
        tree = args.reference_tree.resolve()
        subprocess.run([str(OUR_PYTHON), "-m", "compileall", "-q", *(str(tree / p) for p in
                        ("trainer", "unity_stub_env", "protos"))], check=True, stdout=subprocess.DEVNULL)
        reference_env = {**env, "PYTHONPATH": str(tree)}
    args.out.mkdir(parents=True, exist_ok=True)
    pairs = []
    with tempfile.TemporaryDirectory(prefix=f"bench_train_{args.task}_") as tmp:
        folder = Path(tmp)
        config_path = folder / source.name
        config = write_bench_config(source, config_path, args.max_steps)
        behavior = next(iter(config["behaviors"]))
        exe = stub_launcher(folder, stub_task)
        for index, seed in enumerate(seeds):
            args.seed = seed
            pair_folder = folder / f"pair{index}" if len(seeds) > 1 else folder
            runs = {
                "ours": lambda f=pair_folder: train("ours", OUR_LEARN, f"stub:{stub_task}", config_path,
                                                    f / "ours", args, behavior, ours_env),
                "reference": (lambda f=pair_folder: train("reference", OUR_LEARN, f"stub:{stub_task}", config_path,
                                                          f / "reference", args, behavior, reference_env))
                if args.reference_tree else
                (lambda f=pair_folder: train("reference", REFERENCE_LEARN, str(exe.with_suffix("")),
                                             config_path, f / "reference", args, behavior, env)),
            }
            order = ["ours", "reference"] if index % 2 == 0 else ["reference", "ours"]
            done = {name: runs[name]() for name in order}
            verdict = compare(done["ours"], done["reference"])
            print(markdown(args.task, done["ours"], done["reference"], verdict))
            pairs.append({"seed": seed, "order": order, "ours": done["ours"], "reference": done["reference"],
                          "verdict": verdict})
    ours, reference, verdict = pairs[-1]["ours"], pairs[-1]["reference"], pairs[-1]["verdict"]
    if len(pairs) > 1:
        print()
        print(ratios_line(pairs, "speedup_agent_steps_per_s", "(agent-steps/s)")
              + f" (target >= {TARGET_SPEEDUP:g}x)")
        print(ratios_line(pairs, "speedup_to_last_summary", "to the last summary (neither's final save)"))
    seed_rewards = None
    if args.seeds and len(pairs) > 1:
        seed_rewards = rewards_over_seeds(pairs)
        print(seed_rewards["markdown"])
    args.out.mkdir(parents=True, exist_ok=True)
    report = {"task": args.task, "config": str(source), "bench_config": config,
              "seed": args.seed, "num_areas": args.num_areas, "ours": ours,
              "reference": reference, "verdict": verdict, "pairs": pairs, "seed_rewards": seed_rewards,
              "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                          "loadavg_at_end": os.getloadavg()}}
    out_path = args.out / f"train_{args.task}.json"
    out_path.write_text(json.dumps(report, indent=2))
    print(f"wrote {out_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
