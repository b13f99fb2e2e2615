"""A starting checkpoint for a mimic bench run (``--initialize-from``): exploration noise SIGMA, and
optionally the policy's mean cloned from the reference motion.

    .venv/bin/python bench/mimic/warm_start.py results/fresh results/squat_init --sigma 0.0167 --motion 2
    .venv/bin/mlagents-like-learn bench/mimic/squat_small.yaml --env stub:mimic --run-id squat \\
        --initialize-from squat_init --seed 1 --num-areas 2

SOURCE is a run of the same network (e.g. ``max_steps: 200`` of the bench YAML: fresh weights).

Why the noise (bench/RESULTS.md, 2026-11-25 late evening, mimic): PPO's Gaussian starts at std 1 in
the network's units (as ML-Agents'), and the environment receives clamp(a, -3, 3) / 3: std 1/3 in
action units, random targets over a third of each joint's range at 50 Hz; the ragdoll falls within
~0.85 s whatever the mean action (even std 0.1 falls within 1.3 s). The trainer lowers log std by
only ~0.03 per 25k steps. Every action's log std (``Policy.log_sigma``) is set to log (3 SIGMA),
SIGMA in action units.

Why the clone (``--motion``): from the standing pose, PPO did not move the pose term of arms or
squat in 250k steps (r_r 0.05 and 0.24 flat). With ``--motion`` the actor's mean is first fitted
(mean squared error) to the actions that put every PD target on the reference, a = q / high for
q >= 0 and -q / low below (the inverse of the task's map), on the observations of ragdolls that
follow those actions plus noise SIGMA (reference state initialisation, so the whole clip), i.e.
behavioural cloning of the reference through the task's own controllers; PPO may then go on from
it with the task's reward (``--initialize-from``). The critic stays fresh. The clone alone drifts off the states it was fitted on
(squat: |mu - reference action| 0.01 at first, 0.74 when it fell after 1.7 s), so ``--dagger``
rounds add the states the clone reaches itself, labelled with the reference actions (DAgger).
"""
from __future__ import annotations

import argparse
import math
import shutil
from pathlib import Path

import numpy as np
import torch

from protos.types import BehaviorSpec
from trainer.artifacts.checkpoints import save_checkpoint
from trainer.artifacts.onnx_export import export_policy
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.networks import Actor
from trainer.common.policy import CONTINUOUS_CLIP, Policy
from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.mimic import MimicTask


def reference_actions(task: MimicTask) -> np.ndarray:
    """[n, 26] actions whose absolute PD targets are the reference of the frame each decision leads to."""
    q = task.ref.joints[task.ref_rows((task.frame + 1) % task.ref.frames[task.motion])]
    low = np.where(task.low < 0, task.low, -1.0)  # knees and elbows: no negative half (q >= 0 there)
    return np.where(q >= 0, q / task.high, -q / low).clip(-1.0, 1.0)


def collect(motion: int, sigma: float, decisions: int, seed: int, actor: Actor | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Observations and reference actions of 16 ragdolls acting with the reference actions (or the
    actor's mean, DAgger) plus noise sigma."""
    params = EnvironmentParameters()
    params.set("motion", lambda: motion)
    task = MimicTask(2, seed, params)
    rng = np.random.default_rng(seed)
    obs, act = [], []
    for _ in range(decisions):
        o, a = task.observe()[0], reference_actions(task)
        obs.append(o)
        act.append(a)
        if actor is not None:  # the environment receives clamp(mu, -3, 3) / 3 (trainer/common/policy.py)
            with torch.no_grad():
                mu = actor.heads([torch.as_tensor(o)], None)[0].numpy().astype(np.float64)
            a = mu.clip(-CONTINUOUS_CLIP, CONTINUOUS_CLIP) / CONTINUOUS_CLIP
        result = task.step(a + rng.normal(0.0, sigma, a.shape), np.zeros((task.num_agents, 0)))
        if result.done.any():
            task.reset(result.done)
    return np.concatenate(obs), (CONTINUOUS_CLIP * np.concatenate(act)).astype(np.float32)  # network units


def clone(actor: Actor, obs: np.ndarray, act: np.ndarray, epochs: int, seed: int) -> float:
    """Fit the actor's mean to act by minibatch Adam; the final mean squared error."""
    x, y = torch.as_tensor(obs), torch.as_tensor(act)
    actor.update_normalization([x])
    optimizer = torch.optim.Adam(actor.parameters(), lr=1e-3)
    generator = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        for batch in torch.randperm(len(x), generator=generator).split(256):
            mu, _ = actor.heads([x[batch]], None)
            loss = ((mu - y[batch]) ** 2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    with torch.no_grad():
        return float(((actor.heads([x], None)[0] - y) ** 2).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="results/<run-id> with <behavior>/checkpoint.pt")
    parser.add_argument("target", type=Path, help="results/<new run-id> to write")
    parser.add_argument("--sigma", type=float, required=True,
                        help="exploration std in the environment's action units (the network's is 3x: it sends clamp(a, -3, 3) / 3)")
    parser.add_argument("--motion", type=int, help="clone the mean from this motion's reference")
    parser.add_argument("--decisions", type=int, default=2000, help="per ragdoll (16) for the clone")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--dagger", type=int, default=3, help="rounds on the clone's own states")
    parser.add_argument("--hidden-units", type=int, default=256)
    parser.add_argument("--num-layers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--behavior", default="Mimic")
    parser.add_argument("--onnx", type=Path, help="also export the clone as an .onnx policy (for --evaluate)")
    args = parser.parse_args()
    state = torch.load(args.source / args.behavior / "checkpoint.pt", weights_only=True)
    if args.motion is not None:
        task = MimicTask(1, 0)
        spec = BehaviorSpec(task.observation_specs, task.action_spec)
        actor = Actor(spec.observation_specs, spec.action_spec,
                      PPOHyperparams(hidden_units=args.hidden_units, num_layers=args.num_layers, normalize=True))
        actor.load_state_dict(state["Policy"])
        obs, act = collect(args.motion, args.sigma, args.decisions, args.seed)
        for round_ in range(args.dagger + 1):
            if round_:  # DAgger: the states the clone itself reaches, labelled with the reference actions
                more = collect(args.motion, args.sigma, args.decisions, args.seed + round_, actor)
                obs, act = np.concatenate([obs, more[0]]), np.concatenate([act, more[1]])
            error = clone(actor, obs, act, args.epochs, args.seed)
            print(f"round {round_}: cloned on {len(obs)} decisions, mean squared error {error:.5f}", flush=True)
        state["Policy"] = actor.state_dict()
        if args.onnx is not None:
            policy = Policy(spec, PPOHyperparams(hidden_units=args.hidden_units, num_layers=args.num_layers,
                                                 normalize=True), seed=args.seed)
            policy.actor.load_state_dict(state["Policy"])
            export_policy(policy, args.onnx)
    state["Policy"]["log_sigma"].fill_(math.log(CONTINUOUS_CLIP * args.sigma))  # sigma in action units
    (args.target / args.behavior).mkdir(parents=True, exist_ok=True)
    save_checkpoint(str(args.target / args.behavior / "checkpoint.pt"), state)
    if (args.source / "configuration.yaml").exists():
        shutil.copy(args.source / "configuration.yaml", args.target / "configuration.yaml")
    print(f"{args.target / args.behavior / 'checkpoint.pt'}: log sigma = log {args.sigma:g}")


if __name__ == "__main__":
    main()
