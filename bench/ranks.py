"""Data-parallel ranks benchmark (run by hand, not a test; docs/cluster.md has the model it feeds).

    .venv/bin/python bench/ranks.py allreduce [--repeats 5 --calls 200]
    .venv/bin/python bench/ranks.py train [--task basic] [--max-steps 20000] [--seed 1]
    .venv/bin/python bench/ranks.py srun [--task basic] [--max-steps 10000] [--pairs 2]   (root: starts a private Slurm)

allreduce  two gloo processes on 127.0.0.1 (the cost on one node; between nodes add the network's
           latency and bandwidth): the all-reduce of one flat float32 gradient buffer (what Adam
           hands over per minibatch step, trainer/common/adam.py) for the real parameter counts of
           configs/basic.yaml, configs/ball3d.yaml and ball3d with 3 x 512 units; the cost per
           update = per call x minibatch steps per update (num_epoch x buffer_size / batch_size);
           and the per-exchange agreement of trainer/distributed.py (two all-gathers of a few
           floats). Min over --repeats of the mean over --calls.
train      the same task and step budget as 1 rank x 1 simulator, 2 ranks x 1 simulator (RANK /
           WORLD_SIZE, two processes), 1 rank x 2 simulators (--num-envs 2), and 2 ranks with
           buffer_size and batch_size halved (per rank: the updates of one process): wall seconds,
           agent steps/s in all and per rank, steady steps/s from the summaries' own times, and
           the mean reward at every summary step (rank 0's TensorBoard).
srun       the same 1-rank training run directly and as `srun -n 1` in a private one-node Slurm
           (tests/slurm/cluster.py), alternating, --pairs times: the overhead of srun.
Prints markdown; writes JSON to bench/out/ranks_<mode>.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# as the trainer runs (trainer/cli.py, trainer/run_setup.py): one BLAS and one torch thread; set before
# numpy loads (OpenBLAS's second thread busy-waits, which made the first numbers here 10-100x slower)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
LEARN = [sys.executable, "-m", "trainer.cli"]
REWARD_TAG = "Environment/Cumulative Reward"


def env_for_children(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.lower().endswith("_proxy")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    env.update(extra)
    return env


# --------------------------------------------------------------------------------- allreduce
def parameter_counts(measure: bool = False) -> list[dict]:
    """(name, parameters of actor + critic, minibatch steps per update) of the real networks."""
    from protos.types import BehaviorSpec
    from trainer.ppo.hyperparams import PPOHyperparams
    from trainer.ppo.trainer import PPOTrainer
    from unity_stub_env.tasks import TASKS

    rows = []
    for name, task, config, override in (("basic", "basic", "configs/basic.yaml", None),
                                         ("ball3d", "ball3d", "configs/ball3d.yaml", None),
                                         ("ball3d 3x512", "ball3d", "configs/ball3d.yaml", (512, 3))):
        settings = next(iter(yaml.safe_load((ROOT / config).read_text())["behaviors"].values()))
        h, n = settings["hyperparameters"], settings["network_settings"]
        units, layers = override or (n["hidden_units"], n["num_layers"])
        cls = TASKS[task]
        hp = PPOHyperparams(batch_size=h["batch_size"], buffer_size=h["buffer_size"], num_epoch=h["num_epoch"],
                            hidden_units=units, num_layers=layers, normalize=n.get("normalize", False),
                            reward_signals={"extrinsic": (0.99, 1.0)})
        trainer = PPOTrainer(name, BehaviorSpec(cls.observation_specs, cls.action_spec), hp, seed=0)
        rows.append({"network": name, "parameters": int(trainer.optimizer.exp_avg.size),
                     "steps_per_update": h["num_epoch"] * (h["buffer_size"] // h["batch_size"]),
                     "normalizer_floats": sum(1 + 2 * m.running_mean.numel() for m in trainer.normalizers()),
                     "compute_per_step_ms": update_compute_ms(name, cls, hp) if measure else None})
    return rows


def update_compute_ms(name: str, cls, hp, repeats: int = 3) -> float:
    """One minibatch step's compute (gradients + Adam, actor and critic, as ranks run it: no
    child process), from updates of 20 minibatches on random experiences (the cost per step
    does not depend on the buffer's length): min over ``repeats``."""
    import dataclasses

    import numpy as np

    from protos.types import BehaviorSpec
    from trainer.ppo import numpy_update
    from trainer.common.trajectory import Trajectory
    from trainer.ppo.trainer import PPOTrainer

    hp = dataclasses.replace(hp, buffer_size=20 * hp.batch_size, num_epoch=1)
    trainer = PPOTrainer(name, BehaviorSpec(cls.observation_specs, cls.action_spec), hp, seed=0)

    import torch

    torch.set_num_threads(1)
    numpy_update.FORK_MIN_WORK = float("inf")
    rng = np.random.default_rng(0)
    best = float("inf")
    for _ in range(repeats):
        while not trainer.ready_to_update():
            obs = [rng.standard_normal((64, *o.shape)).astype(np.float32) for o in cls.observation_specs]
            out = trainer.policy.act(obs, None)
            trainer.process_trajectory(Trajectory(obs, [o[-1] for o in obs], rng.standard_normal(64).astype(np.float32),
                                                  out.continuous_raw, out.discrete, out.log_probs, None, False, True))
        steps = trainer.optimizer.step_count
        start = time.perf_counter()
        trainer.update()
        best = min(best, (time.perf_counter() - start) / (trainer.optimizer.step_count - steps))
    return best * 1e3


def _allreduce_worker(rank: int, port: int, rows: list[dict], repeats: int, calls: int, out: str) -> None:
    import numpy as np
    import torch
    import torch.distributed as dist

    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=2)
    results = []

    def timed(call) -> tuple[float, float]:
        """(min over repeats of the mean of ``calls`` calls, the fastest single call), seconds."""
        mean, single = float("inf"), float("inf")
        for _ in range(repeats):
            dist.barrier()
            start = time.perf_counter()
            for _ in range(calls):
                before = time.perf_counter()
                call()
                single = min(single, time.perf_counter() - before)
            mean = min(mean, (time.perf_counter() - start) / calls)
        return mean, single

    for row in rows:
        flat = torch.from_numpy(np.ones(row["parameters"], dtype=np.float32))
        mean, single = timed(lambda: dist.all_reduce(flat))
        header = torch.zeros(3, dtype=torch.float64)
        payload = torch.zeros(2 + row["normalizer_floats"], dtype=torch.float64)

        def agree():
            dist.all_gather([torch.empty_like(header) for _ in range(2)], header)
            dist.all_gather([torch.empty_like(payload) for _ in range(2)], payload)

        agree_mean, agree_single = timed(agree)
        results.append({**row, "allreduce_us": mean * 1e6, "allreduce_best_us": single * 1e6,
                        "per_update_ms": mean * row["steps_per_update"] * 1e3,
                        "per_update_best_ms": single * row["steps_per_update"] * 1e3,
                        "agree_us": agree_mean * 1e6, "agree_best_us": agree_single * 1e6})
    if rank == 0:
        Path(out).write_text(json.dumps(results))
    dist.destroy_process_group()


def bench_allreduce(args) -> dict:
    import torch.multiprocessing as mp

    from tests.integration.conftest import free_port_block

    rows = parameter_counts(measure=True)
    out = tempfile.mktemp(suffix=".json")
    mp.spawn(_allreduce_worker, args=(free_port_block(1), rows, args.repeats, args.calls, out), nprocs=2)
    results = json.loads(Path(out).read_text())
    os.unlink(out)
    lines = ["| network | parameters | compute per minibatch step | all-reduce per step: mean (fastest) | "
             "steps per update | all-reduce per update: mean (fastest) | agreement: mean (fastest) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        lines.append(f"| {r['network']} | {r['parameters']:,} | {r['compute_per_step_ms']:.2f} ms | "
                     f"{r['allreduce_us']:.0f} ({r['allreduce_best_us']:.0f}) µs"
                     f" | {r['steps_per_update']} | {r['per_update_ms']:.1f} ({r['per_update_best_ms']:.1f}) ms | "
                     f"{r['agree_us']:.0f} ({r['agree_best_us']:.0f}) µs |")
    return {"results": results, "markdown": "\n".join(lines)}


# --------------------------------------------------------------------------------- training
def write_config(task: str, max_steps: int, folder: Path, divide: int = 1) -> Path:
    """The task's config with ``max_steps``, no checkpoint inside the run, and buffer_size and
    batch_size divided by ``divide`` (K ranks with the updates of one process)."""
    config = yaml.safe_load((ROOT / "configs" / f"{task}.yaml").read_text())
    for settings in config["behaviors"].values():
        for key in ("buffer_size", "batch_size"):
            settings["hyperparameters"][key] //= divide
        settings["max_steps"] = max_steps
        settings["checkpoint_interval"] = 100 * max_steps
        settings["summary_freq"] = max(500, min(settings["summary_freq"], max_steps // 10))
    path = folder / f"{task}{'' if divide == 1 else f'_div{divide}'}.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def read_rewards(behavior_dir: Path) -> list[dict]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(behavior_dir), size_guidance={"scalars": 0})
    events.Reload()
    if REWARD_TAG not in events.Tags().get("scalars", []):
        return []
    return [{"step": e.step, "wall_time": e.wall_time, "value": e.value}
            for e in sorted(events.Scalars(REWARD_TAG), key=lambda e: e.step)]


def run_setup(label: str, task: str, config: Path, folder: Path, seed: int, ranks: int, envs: int,
              prefix: list[str] | None = None, slurm_env: dict | None = None) -> dict:
    """One training: ``ranks`` processes (RANK / WORLD_SIZE) with ``envs`` simulators each."""
    from tests.integration.conftest import free_port_block

    results = folder / "results"
    base, master = free_port_block(ranks * envs), free_port_block(1)
    args = [str(config), "--env", f"stub:{task}", "--seed", str(seed), "--run-id", label, "--results-dir",
            str(results), "--base-port", str(base), "--num-envs", str(envs)]
    procs = []
    started = time.perf_counter()
    for rank in range(ranks):
        extra = {"RANK": str(rank), "WORLD_SIZE": str(ranks), "MASTER_ADDR": "127.0.0.1",
                 "MASTER_PORT": str(master)} if ranks > 1 else {}
        env = {**env_for_children(**extra), **(slurm_env or {})}
        log = open(folder / f"{label}.rank{rank}.log", "w")
        procs.append(subprocess.Popen([*(prefix or []), *LEARN, *args], cwd=folder, env=env, stdout=log,
                                      stderr=subprocess.STDOUT))
        log.close()
    codes = [p.wait(timeout=3600) for p in procs]
    wall = time.perf_counter() - started
    behavior = next(iter(yaml.safe_load(config.read_text())["behaviors"]))
    rewards = read_rewards(results / label / behavior)
    final = rewards[-1]["step"] if rewards else 0
    steady = None
    if len(rewards) >= 3:  # from the second summary on: no start-up
        steady = (rewards[-1]["step"] - rewards[1]["step"]) / (rewards[-1]["wall_time"] - rewards[1]["wall_time"])
    return {"setup": label, "ranks": ranks, "envs_per_rank": envs, "exit_codes": codes, "wall_s": wall,
            "final_step": final, "steps_per_s": final / wall, "per_rank_steps_per_s": final / wall / ranks,
            "steady_steps_per_s": steady, "rewards": rewards}


def bench_train(args) -> dict:
    folder = Path(tempfile.mkdtemp(prefix="bench-ranks-"))
    config = write_config(args.task, args.max_steps, folder)
    halved = write_config(args.task, args.max_steps, folder, divide=2)
    runs = [run_setup(f"{r}rank_x{e}env", args.task, config, folder, args.seed, r, e)
            for r, e in ((1, 1), (2, 1), (1, 2))]
    runs.append(run_setup("2rank_x1env_halved", args.task, halved, folder, args.seed, 2, 1))
    lines = ["| setup | wall s | agent steps/s | per rank | steady steps/s | reward at the last common summary |",
             "|---|---:|---:|---:|---:|---:|"]
    common = min(r["final_step"] for r in runs)
    for r in runs:
        at = [x["value"] for x in r["rewards"] if x["step"] <= common]
        note = ", buffer/batch ÷ 2" if r["setup"].endswith("halved") else ""
        lines.append(f"| {r['ranks']} rank x {r['envs_per_rank']} sim{note} | {r['wall_s']:.1f} | "
                     f"{r['steps_per_s']:.0f} | "
                     f"{r['per_rank_steps_per_s']:.0f} | {r['steady_steps_per_s'] or 0:.0f} | "
                     f"{at[-1] if at else float('nan'):.3f} |")
    two_ranks, two_envs = runs[1], runs[2]
    ratio = two_ranks["steps_per_s"] / two_envs["steps_per_s"]
    lines.append(f"\n2 ranks x 1 sim ÷ 1 rank x 2 sims, agent steps/s: **{ratio:.2f}**")
    return {"task": args.task, "max_steps": args.max_steps, "seed": args.seed, "runs": runs, "ratio": ratio,
            "markdown": "\n".join(lines)}


def bench_srun(args) -> dict:
    from tests.slurm.cluster import Cluster

    folder = Path(tempfile.mkdtemp(prefix="bench-srun-"))
    config = write_config(args.task, args.max_steps, folder)
    cluster = Cluster().start()
    try:
        runs = {"direct": [], "srun": []}
        for i in range(args.pairs):
            for how in (("direct", "srun") if i % 2 == 0 else ("srun", "direct")):
                prefix = ["srun", "-n", "1", "--mem=1G", "--cpus-per-task=1"] if how == "srun" else None
                runs[how].append(run_setup(f"{how}{i}", args.task, config, folder, args.seed, 1, 1, prefix,
                                           {"SLURM_CONF": cluster.env["SLURM_CONF"]} if how == "srun" else None))
    finally:
        cluster.stop()
    best = {how: min(r["wall_s"] for r in rs) for how, rs in runs.items()}
    overhead = best["srun"] / best["direct"] - 1
    lines = ["| how | wall s (each run) | best |", "|---|---|---:|"]
    for how, rs in runs.items():
        each = ", ".join(f"{r['wall_s']:.1f}" for r in rs)
        lines.append(f"| {how} | {each} | {best[how]:.1f} |")
    lines.append(f"\nsrun overhead (best vs best): **{overhead * 100:+.1f} %** (target within 5 %)")
    return {"task": args.task, "max_steps": args.max_steps, "runs": runs, "overhead": overhead,
            "markdown": "\n".join(lines)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=("allreduce", "train", "srun"))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--task", default="basic")
    parser.add_argument("--max-steps", type=int, default=20000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--pairs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out")
    args = parser.parse_args(argv)
    result = {"allreduce": bench_allreduce, "train": bench_train, "srun": bench_srun}[args.mode](args)
    result["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    result["load_1min"] = os.getloadavg()[0]
    print(result["markdown"])
    print(f"\n{result['date']}, load average {result['load_1min']:.2f} (1 min), {os.cpu_count()} CPUs")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"ranks_{args.mode}.json").write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
