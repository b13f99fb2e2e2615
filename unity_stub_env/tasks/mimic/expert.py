"""The ``mimic`` task's scripted balance expert: standing under pushes with an ankle strategy.

An ankle strategy from the capture point (measured in bench/RESULTS.md, "mimic: pushed standing"):
every decision, from the observation alone, the centre of mass is estimated as the mass-weighted
mean of the 13 observed parts' origins and velocities (a hand goes with its forearm), taken into
the heading frame (the pelvis' yaw, z up; x right, y forward) and compared with the midpoint of
the feet. The capture point offset xi = (c - c0) + v / omega0, omega0 = sqrt(g / 0.93 m) (the
neutral pose's CoM height) and c0 = the neutral pose's own offset, is where the CoM would come to
rest as a linear inverted pendulum. Both ankles then turn the soles to press towards it,
BALANCE_ANKLE_GAIN rad of PD target per m: plantar flexion when xi points forward, the right edges
of both soles down when it points right; every other joint's target stays at the neutral 0 rad
(the stand clip's pose). The gains come from a sweep at 15 N s every 2 s (bench/RESULTS.md): the
lateral gain has a narrow band that holds, and the wrong sign falls.
"""
from __future__ import annotations

import math

import mujoco
import numpy as np

from unity_stub_env.geometry import quat_matrix
from unity_stub_env.tasks.mimic.motions import JOINTS
from unity_stub_env.tasks.mimic.task import OBSERVED, XML_PATH

BALANCE_ANKLE_GAIN = 1.5  # rad of ankle target per m of capture-point offset
BALANCE_COM_HEIGHT = 0.93  # m, the neutral pose's centre of mass above the floor (mimic.xml)
GRAVITY = 9.81


class BalanceExpert:
    """``act(obs [n, 170]) -> actions [n, 26]`` of the default (absolute) mode: the neutral standing
    pose with the ankle strategy above. Reads mimic.xml once for the part masses and joint limits."""

    def __init__(self, gain: float = BALANCE_ANKLE_GAIN) -> None:
        model = mujoco.MjModel.from_xml_path(str(XML_PATH))
        body = lambda name: model.body(name).id  # noqa: E731
        # a part's own mass; the forearm carries its welded hand
        self.mass = np.array([model.body_subtreemass[body(b)] if b.startswith("forearm") else model.body_mass[body(b)]
                              for b in OBSERVED])
        self.low = model.jnt_range[[model.joint(j).id for j in JOINTS], 0]
        self.high = model.jnt_range[[model.joint(j).id for j in JOINTS], 1]
        self.gain = gain
        self.omega = math.sqrt(GRAVITY / BALANCE_COM_HEIGHT)
        self.index = {name: j for j, name in enumerate(JOINTS)}

    def offset(self, position: np.ndarray, to_heading: np.ndarray) -> np.ndarray:
        """[n, 2]: the estimated CoM minus the feet's midpoint, horizontal, in the heading frame, from
        the parts' positions relative to the pelvis [n, 13, 3] (pelvis frame) and the pelvis-to-heading
        rotations [n, 3, 3]."""
        com = (self.mass[:, None] * position).sum(axis=1) / self.mass.sum()
        feet = position[:, [OBSERVED.index("foot_r"), OBSERVED.index("foot_l")]].mean(axis=1)
        return np.einsum("nij,nj->ni", to_heading, com - feet)[:, :2]

    def capture_point(self, obs: np.ndarray) -> np.ndarray:
        """[n, 2]: the capture point offset xi (m; x right, y forward) of every agent's observation."""
        parts = np.asarray(obs, np.float64)[:, :13 * len(OBSERVED)].reshape(len(obs), len(OBSERVED), 13)
        rotation = quat_matrix(parts[:, 0, 0:4])  # pelvis -> world
        forward = rotation[:, :, 1]
        yaw = np.arctan2(-forward[:, 0], forward[:, 1])
        c, s, zero, one = np.cos(yaw), np.sin(yaw), np.zeros(len(yaw)), np.ones(len(yaw))
        heading = np.stack([c, -s, zero, s, c, zero, zero, zero, one], axis=1).reshape(-1, 3, 3)
        to_heading = np.einsum("nji,njk->nik", heading, rotation)  # heading^T rotation
        position = parts[:, :, 10:13].copy()
        position[:, 0] = 0.0  # the pelvis' slot holds its height, not a relative position
        velocity = (self.mass[:, None] * parts[:, :, 4:7]).sum(axis=1) / self.mass.sum()
        speed = np.einsum("nij,nj->ni", to_heading, velocity)[:, :2]
        return self.offset(position, to_heading) + speed / self.omega

    def targets(self, obs: np.ndarray) -> np.ndarray:
        """[n, 26] PD targets (rad): 0 but the four ankle axes."""
        xi = self.capture_point(obs)
        target, j = np.zeros((len(obs), len(JOINTS))), self.index
        target[:, j["ankle_x_r"]] = target[:, j["ankle_x_l"]] = -self.gain * xi[:, 1]  # plantar flexion
        target[:, j["ankle_y_r"]] = -self.gain * xi[:, 0]  # positive ankle_y lifts a sole's outer edge
        target[:, j["ankle_y_l"]] = self.gain * xi[:, 0]
        return target

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Actions [n, 26] (float32): the absolute map's inverse of ``targets``."""
        q = np.clip(self.targets(obs), self.low, self.high)
        up = np.divide(q, self.high, out=np.zeros_like(q), where=self.high > 0)
        down = np.divide(-q, self.low, out=np.zeros_like(q), where=self.low < 0)
        return np.where(q >= 0.0, up, down).astype(np.float32)
