"""GAIL alone on ball3d: does a policy trained only on the discriminator's reward beat the untrained one?

    nice -n 10 python bench/gail_ball3d.py [--steps 240000] [--seed 3] [--areas 2]

Records the scripted expert (unity-stub-env --record-demo, 5005 steps = 5 episodes of 100),
trains configs/ball3d_gail.yaml (GAIL only, no extrinsic reward) cut to --steps, and prints the
environment's mean return per summary (Environment/Cumulative Reward, TensorBoard) beside the
GAIL statistics. The untrained policy is the first summary (a policy that does nothing holds the
ball ~13 decisions, return ~1.4). Too long for the test suite; tests/unit/test_gail.py proves the
discriminator's reward separates expert from random steps.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def scalars(folder: Path, tag: str) -> list[tuple[int, float]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    return [(e.step, e.value) for e in acc.Scalars(tag)] if tag in acc.Tags()["scalars"] else []


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=240000)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--areas", type=int, default=2)
    parser.add_argument("--base-port", type=int, default=6731)
    args = parser.parse_args()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "--task", "ball3d", "--record-demo",
                        "demos/ball3d.demo", "--policy", "scripted", "--demo-steps", "5000"],
                       cwd=work, env=env, check=True)
        text = (ROOT / "configs" / "ball3d_gail.yaml").read_text()
        (work / "gail.yaml").write_text(text.replace("max_steps: 500000", f"max_steps: {args.steps}"))
        subprocess.run([sys.executable, "-m", "trainer.cli", "gail.yaml", "--env", "stub:ball3d", "--num-areas",
                        str(args.areas), "--seed", str(args.seed), "--run-id", "g", "--base-port",
                        str(args.base_port)], cwd=work, env=env, check=True, stdout=subprocess.DEVNULL)
        folder = work / "results" / "g" / "3DBall"
        tags = ["Environment/Cumulative Reward", "Policy/Gail Reward", "Policy/GAIL Expert Estimate",
                "Policy/GAIL Policy Estimate"]
        columns = {tag: dict(scalars(folder, tag)) for tag in tags}
        print("step    | " + " | ".join(tags))
        for step in sorted(columns[tags[0]]):
            print(f"{step:7d} | " + " | ".join(f"{columns[t].get(step, float('nan')):.3f}" for t in tags))
    return 0


if __name__ == "__main__":
    sys.exit(main())
