"""The ``mimic`` task's reference motions: generate them (run once) and load them.

    .venv/bin/python -m unity_stub_env.tasks.mimic.motions   # rewrites clips/*.csv

Each motion is a CSV file in ``clips/`` beside this module, sampled at ``RATE`` = 50 Hz (the
task's control rate, so a control step is one frame): a header row, then one row per frame with
``time`` (s), the root (pelvis) position ``root_x root_y root_z`` (m, relative to the character's
base on the floor) and orientation ``root_qw root_qx root_qy root_qz``, and the 26 joint angles (rad)
in ``JOINTS`` order (mimic.xml's actuator order; positive = flexion / abduction / lateral rotation).
The clips loop: the last frame is followed by the first.

How they are made (keyframe-free, closed-form curves of the joint angles; w = 2 pi / period):
  stand  1 s, every joint at 0 (upright, arms hanging).
  arms   4 s: one arm rises sideways while the other comes down (shoulder abduction 75 deg
         (1 -+ cos wt) / 2, elbows at 10 deg) and the head turns from side to side (neck rotation
         40 deg sin wt), like the seed project's arm animation (docs/stub-tasks.md).
  squat  4 s: depth s = (1 - cos wt) / 2; thighs flex 50 s deg, shanks lean 30 s deg forward (knees
         80 s, ankles 30 s dorsiflexion, so the soles stay flat), the pelvis pitches 15 s deg forward
         and the waist flexes 10 s deg; the arms reach forward (shoulder flexion 60 s deg) to keep
         the centre of mass over the feet.
  walk   1.1 s per gait cycle (two steps), legs in antiphase: hips flex 25 deg sin(phase), knees
         5 + 55 max(0, cos phase)^2 deg in swing, ankles dorsiflex 10 max(0, cos phase) deg in swing,
         arms swing against the legs (shoulder flexion -20 deg sin(phase), elbows 15 deg).
For every frame the root height puts the lowest sole corner on the floor (forward kinematics of
mimic.xml); the root's forward position keeps the feet from sliding: for the static motions the
mean of the two feet stays where it is when standing, for the walk the stance foot (the lower one)
stays put, so the clip advances ``root_y`` by one stride per cycle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

XML_PATH = Path(__file__).with_name("mimic.xml")
MOTION_DIR = Path(__file__).with_name("clips")
RATE = 50  # frames per second
MOTIONS = ("stand", "arms", "squat", "walk")  # environment parameter ``motion`` = index into this
JOINTS = ("waist_x", "waist_y", "waist_z", "neck_x", "neck_y", "neck_z",
          "shoulder_x_r", "shoulder_y_r", "shoulder_z_r", "elbow_r",
          "shoulder_x_l", "shoulder_y_l", "shoulder_z_l", "elbow_l",
          "hip_x_r", "hip_y_r", "hip_z_r", "knee_r", "ankle_x_r", "ankle_y_r",
          "hip_x_l", "hip_y_l", "hip_z_l", "knee_l", "ankle_x_l", "ankle_y_l")
ROOT_COLUMNS = ("root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz")
DURATION = {"stand": 1.0, "arms": 4.0, "squat": 4.0, "walk": 1.1}


@dataclass
class Motion:
    """A loaded clip: ``qpos`` float [frames, 33] (root position, root quaternion, JOINTS), at RATE."""

    name: str
    qpos: np.ndarray

    @property
    def frames(self) -> int:
        return len(self.qpos)


def load_motion(name: str) -> Motion:
    """Read ``clips/NAME.csv``; ValueError names the known motions."""
    if name not in MOTIONS:
        raise ValueError(f"unknown motion {name!r}; known motions: {', '.join(MOTIONS)}")
    path = MOTION_DIR / f"{name}.csv"
    header = path.read_text().splitlines()[0].split(",")
    if header != ["time", *ROOT_COLUMNS, *JOINTS]:
        raise ValueError(f"{path}: unexpected columns {header}")
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return Motion(name, table[:, 1:])


# --- generation -----------------------------------------------------------------------------------
def _angles(name: str, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles [frames, 26] (rad) and root pitch [frames] (rad, forward positive) of ``name``."""
    q = np.zeros((len(t), len(JOINTS)))
    col = {joint: i for i, joint in enumerate(JOINTS)}
    pitch = np.zeros(len(t))
    w = 2 * math.pi / DURATION[name]
    deg = math.radians
    if name == "arms":
        q[:, col["shoulder_y_r"]] = deg(75) * (1 - np.cos(w * t)) / 2
        q[:, col["shoulder_y_l"]] = deg(75) * (1 + np.cos(w * t)) / 2
        q[:, [col["elbow_r"], col["elbow_l"]]] = deg(10)
        q[:, col["neck_z"]] = deg(40) * np.sin(w * t)
    elif name == "squat":
        s = (1 - np.cos(w * t)) / 2
        thigh, shank = deg(50) * s, deg(30) * s
        pitch = deg(15) * s
        for side in ("r", "l"):
            q[:, col[f"hip_x_{side}"]] = thigh + pitch
            q[:, col[f"knee_{side}"]] = thigh + shank
            q[:, col[f"ankle_x_{side}"]] = shank
            q[:, col[f"shoulder_x_{side}"]] = deg(60) * s
        q[:, col["waist_x"]] = deg(10) * s
    elif name == "walk":
        for side, offset in (("r", 0.0), ("l", math.pi)):
            phase = w * t + offset
            swing = np.maximum(0.0, np.cos(phase))
            q[:, col[f"hip_x_{side}"]] = deg(25) * np.sin(phase)
            q[:, col[f"knee_{side}"]] = deg(5) + deg(55) * swing**2
            q[:, col[f"ankle_x_{side}"]] = deg(10) * swing
            q[:, col[f"shoulder_x_{side}"]] = -deg(20) * np.sin(phase)
            q[:, col[f"elbow_{side}"]] = deg(15)
    return q, pitch


def _soles(model, data, qpos: np.ndarray) -> np.ndarray:
    """float [2, 8, 3]: the corners of both soles (right, left) for the pose ``qpos``."""
    import mujoco

    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    out = []
    for foot in ("foot_r", "foot_l"):
        g = model.geom(foot).id
        half = model.geom_size[g]
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        out.append(data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T)
    return np.array(out)


def generate(name: str) -> np.ndarray:
    """The table [frames, 1 + 33] of ``name`` (time, root, joints)."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    data = mujoco.MjData(model)
    frames = round(DURATION[name] * RATE)
    t = np.arange(frames) / RATE
    angles, pitch = _angles(name, t)
    joint_adr = [model.joint(j).qposadr[0] for j in JOINTS]
    qpos = np.zeros((frames, model.nq))
    qpos[:, 3] = np.cos(pitch / 2)
    qpos[:, 4] = -np.sin(pitch / 2)  # forward pitch = rotation about -x
    qpos[:, joint_adr] = angles
    stand = qpos.copy()[0]
    stand[3:] = 0.0
    stand[3] = 1.0
    stand_feet_y = _soles(model, data, stand)[:, :, 1].mean()
    for k in range(frames):
        soles = _soles(model, data, qpos[k])
        qpos[k, 2] = -soles[:, :, 2].min()
        if name != "walk":
            qpos[k, 1] = stand_feet_y - soles[:, :, 1].mean()
            continue
        stance = int(soles[1, :, 2].min() < soles[0, :, 2].min())  # the lower foot
        foot_y = soles[stance, :, 1].mean()
        if k == 0:
            qpos[k, 1] = 0.0
        else:  # the stance foot of this frame did not move since the last one
            previous = _soles(model, data, qpos[k - 1])[stance, :, 1].mean()  # world y (root y set)
            qpos[k, 1] = previous - foot_y
    return np.column_stack([t, qpos[:, :7], angles])


def write_all() -> None:
    MOTION_DIR.mkdir(exist_ok=True)
    for name in MOTIONS:
        table = generate(name)
        header = ",".join(["time", *ROOT_COLUMNS, *JOINTS])
        np.savetxt(MOTION_DIR / f"{name}.csv", table, delimiter=",", header=header, comments="", fmt="%.6f")
        print(f"{name}: {len(table)} frames at {RATE} Hz -> {MOTION_DIR / (name + '.csv')}")


if __name__ == "__main__":
    write_all()
