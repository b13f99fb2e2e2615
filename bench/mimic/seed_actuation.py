"""Does the seed's actuation keep an untrained mimic ragdoll up? Noise survival under its joint drive and action map.

    .venv/bin/python bench/mimic/seed_actuation.py [--trials 16]

Why: PPO's first episodes in ``mimic`` end in a fall within about a second (bench/RESULTS.md, "mimic:
decision rate"), yet the seed learned each motion from scratch. This asks whether the seed's own
actuation, as its published Unity project sets it up, would have spared it those falls. What that
project does (docs/stub-tasks.md, "mimic"): every unlocked axis is a Unity joint drive with spring 400
N m/rad and damper 40 N m s/rad, its torque capped per joint (``SEED_LIMIT``), and an action a in
[-1, 1] is the target ``lerp(low, high, (a + 1) / 2)`` on the axis' limits (Unity's y and z limits are
symmetric, so 0 is their neutral; the flexion axis' a = 0 is the middle of its range).

Each row steps ``stand`` from its first frame for 10 s with fresh Gaussian actions every decision
(clipped to [-1, 1]; PPO starts at about std 1/3 in action units) and prints the mean seconds
before the fall (10 = never) and the percentage of the maximum reward. Variants:
  drive  ours = mimic.xml's PD (kp 1500 / kv 150 on legs and waist, force limits up to 400 N m);
         seed = kp 400, kv 40 on every axis, the seed's per-joint torque caps (``SEED_LIMIT``)
  map    ours = the task's default (a = 0 is the standing pose, a scales towards each limit);
         lerp = the seed's map on our limits (every axis' a = 0 at the middle of its range);
         seed mid-range = the seed's map with the seed's own ranges (a = 0: hips 26.5, knees 52.5,
         ankles 8 degrees flexed, ...; a moves the target by a x half our range)
Then, for the task's default actuation, which joints' noise alone topples it; and a stand-in for the
seed's 20 rad/s maximum angular velocity per rigid body (MuJoCo has none): every hinge's speed
clipped to 20 (and Unity's default 7) rad/s after each MuJoCo step.
"""
from __future__ import annotations

import argparse
import contextlib

import mujoco
import numpy as np

from unity_stub_env.tasks.base import EnvironmentParameters
from unity_stub_env.tasks.mimic.motions import JOINTS
from unity_stub_env.tasks.mimic.task import AGENTS_PER_AREA, MimicTask

# the seed's maximum drive torques (N m) for our joint groups (its hip 120, knee 80, foot 60, chest
# 100, shoulder 70, forearm 50, head 20)
SEED_LIMIT = {"waist": 100.0, "neck": 20.0, "shoulder": 70.0, "elbow": 50.0, "hip": 120.0, "knee": 80.0, "ankle": 60.0}
SEED_KP, SEED_KV = 400.0, 40.0
# the middle of the seed's flexion ranges (degrees, positive = flexion), where its a = 0 puts the target
SEED_MID = {"hip_x": 26.5, "knee": 52.5, "ankle_x": 8.0, "waist_x": 3.8, "elbow": 76.3, "shoulder_x": 12.4,
            "neck_x": 4.5}
GROUPS = {"legs (hips, knees, ankles)": ("hip", "knee", "ankle"), "knees": ("knee",), "ankles": ("ankle",),
          "hips": ("hip",), "waist": ("waist",), "arms and neck": ("shoulder", "elbow", "neck")}


def seed_drive(task: MimicTask) -> None:
    """Give every actuator of ``task`` the seed's drive: kp 400, kv 40, its torque caps."""
    model = task.model
    for j, name in enumerate(JOINTS):
        ids = task.actuator[:, j]
        limit = SEED_LIMIT[name.split("_")[0]]
        model.actuator_gainprm[ids, 0] = SEED_KP
        model.actuator_biasprm[ids, 1] = -SEED_KP
        model.actuator_biasprm[ids, 2] = -SEED_KV
        model.actuator_forcerange[ids] = (-limit, limit)
    task.force_limit = model.actuator_forcerange[task.actuator, 1]


def seed_map(task: MimicTask, own_ranges: bool) -> None:
    """Replace the task's action map by the seed's lerp onto the limits (ours, or the seed's own
    mid-range targets with our half-range as the scale)."""
    low, high = task.low, task.high
    if not own_ranges:
        task.targets = lambda a: low + (a + 1.0) / 2.0 * (high - low)
        return
    mid = np.radians([next((v for k, v in SEED_MID.items() if j.startswith(k)), 0.0) for j in JOINTS])
    task.targets = lambda a: np.clip(mid + a * (high - low) / 2.0, low, high)


@contextlib.contextmanager
def speed_cap(task: MimicTask, cap: float | None):
    """While open, every ``mujoco.mj_step`` (the task calls it per physics step) ends by clipping the
    task's hinge speeds to +-cap rad/s; None = no cap."""
    step = mujoco.mj_step

    def capped(model, data):
        step(model, data)
        data.qvel[task.joint_dof] = np.clip(data.qvel[task.joint_dof], -cap, cap)

    mujoco.mj_step = step if cap is None else capped
    try:
        yield
    finally:
        mujoco.mj_step = step


def survive(std: float, hz: int, trials: int, drive: str = "ours", mapping: str = "ours",
            noisy: np.ndarray | None = None, cap: float | None = None) -> tuple[float, float]:
    """(mean seconds up, % of the maximum reward) over ``trials`` 10 s episodes of ``stand``."""
    params = EnvironmentParameters()
    for key, value in (("motion", 0), ("rsi", 0), ("decision_hz", hz)):
        params.set(key, lambda value=value: value)
    task = MimicTask(-(-trials // AGENTS_PER_AREA), 0, params)
    if drive == "seed":
        seed_drive(task)
    if mapping != "ours":
        seed_map(task, own_ranges=mapping == "seed mid-range")
    task.reset()
    n, decisions = task.num_agents, 10 * task.decision_hz
    rng = np.random.default_rng(0)
    mask = np.ones(len(JOINTS)) if noisy is None else noisy
    running, steps, reward = np.ones(n, dtype=bool), np.zeros(n), np.zeros(n)
    with speed_cap(task, cap):
        for _ in range(decisions):
            action = np.clip(rng.normal(scale=std, size=(n, len(JOINTS))), -1.0, 1.0) * mask
            result = task.step(action, np.zeros((n, 0)))
            reward[running] += result.rewards[running]
            steps[running] += 1
            running &= ~result.done
            if not running.any():
                break
    return float(steps[:trials].mean() / task.decision_hz), float(100.0 * reward[:trials].mean() / decisions)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=16)
    args = parser.parse_args()
    print("| drive | action map | noise std | decisions/s | mean s up | % of max reward |")
    print("|---|---|---|---|---|---|")
    for drive, mapping in (("ours", "ours"), ("seed", "ours"), ("ours", "lerp"), ("seed", "lerp"),
                           ("ours", "seed mid-range"), ("seed", "seed mid-range")):
        for std in (0.0, 1 / 3, 0.1):
            for hz in (50, 250):
                seconds, percent = survive(std, hz, args.trials, drive, mapping)
                print(f"| {drive} | {mapping} | {std:.3g} | {hz} | {seconds:.2f} | {percent:.1f} |", flush=True)
    print()
    print("| noise std 1/3 only on | mean s up |")
    print("|---|---|")
    for label, prefixes in GROUPS.items():
        noisy = np.array([name.startswith(prefixes) for name in JOINTS], dtype=float)
        print(f"| {label} | {survive(1 / 3, 50, args.trials, noisy=noisy)[0]:.2f} |", flush=True)
    print()
    print("| drive | hinge speed cap rad/s | noise std | mean s up (50 decisions/s) | % of max reward |")
    print("|---|---|---|---|---|")
    for drive in ("ours", "seed"):
        for cap in (None, 20.0, 7.0):
            for std in (1 / 3, 0.1):
                seconds, percent = survive(std, 50, args.trials, drive, cap=cap)
                print(f"| {drive} | {cap or 'none'} | {std:.3g} | {seconds:.2f} | {percent:.1f} |", flush=True)


if __name__ == "__main__":
    main()
