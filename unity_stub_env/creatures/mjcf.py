"""MuJoCo XML (MJCF) of a generated creature.

Each bone is a body at its proximal point (a world-aligned frame, so body frames equal the
world frame in the rest pose) with one capsule geom from the proximal to the distal point. The
root bone carries a free joint named ``root``; every other bone has one hinge per free axis of
its category (``skeleton.LIMITS``), named ``<bone>_<axis>``, with the category's range; rigid
categories (hip, shoulder) have no joint and are welded to their parent.

Motors: one MuJoCo ``position`` actuator per hinge (a PD servo whose control is the target angle,
ctrlrange = the hinge's range), named like its joint; proportional gain ``KP_PER_KG`` N m/rad per
kg of the creature's mass for every hinge, torque limited to kp x 1 rad, joint damping
``DAMPING_TIME`` x kp (a derivative gain, integrated implicitly: ``implicitfast``), armature
0.01 kg m^2. Mass: every capsule has the density of water (MuJoCo integrates the masses).

Contacts: creature geoms have contype 2 / conaffinity 1 and the ground contype 1 / conaffinity 2,
so a creature touches the ground, walls and obstacles but never itself nor another creature
(ragdolls in Unity's Walker ignore self-collision as well). Timestep 0.005 s.

Numbers are written with 6 significant digits (``%.6g``), so the same skeleton always gives the
same bytes.
"""
from __future__ import annotations

import numpy as np

from unity_stub_env.creatures.skeleton import Skeleton

DENSITY = 1000.0
KP_PER_KG = 5.0
DAMPING_TIME = 0.05
ARMATURE = 0.01
TIMESTEP = 0.005
GRAVITY = 9.81
CREATURE_CONTACT = 'contype="2" conaffinity="1"'
GROUND_CONTACT = 'contype="1" conaffinity="2"'


def fmt(*values) -> str:
    return " ".join("%.6g" % (0.0 if abs(v) < 5e-13 else v) for v in np.ravel(values))


def capsule_mass(length: float, radius: float) -> float:
    return DENSITY * np.pi * radius**2 * (length + 4.0 / 3.0 * radius)


def total_mass(skeleton: Skeleton) -> float:
    return float(sum(capsule_mass(b.length, b.radius) for b in skeleton.bones))


def gain(skeleton: Skeleton) -> float:
    """The proportional gain of every hinge servo, N m/rad."""
    return KP_PER_KG * total_mass(skeleton)


def defaults(skeleton: Skeleton) -> str:
    kp = gain(skeleton)
    return (f'  <default>\n    <joint damping="{fmt(DAMPING_TIME * kp)}" armature="{fmt(ARMATURE)}"/>\n'
            f'    <geom {CREATURE_CONTACT} density="{fmt(DENSITY)}" friction="1 0.05 0.01"/>\n'
            f'  </default>\n')


def body(skeleton: Skeleton, prefix: str = "", offset=(0.0, 0.0, 0.0), indent: int = 2) -> str:
    """The ``<body>`` tree of the creature, names prefixed by ``prefix``, the root at its rest
    position plus ``offset``."""
    bones = skeleton.bones
    lines: list[str] = []

    def emit(index: int, depth: int) -> None:
        bone = bones[index]
        pad = "  " * depth
        if bone.parent < 0:
            pos = bone.proximal + np.asarray(offset, dtype=np.float64)
        else:
            pos = bone.proximal - bones[bone.parent].proximal
        lines.append(f'{pad}<body name="{prefix}{bone.name}" pos="{fmt(pos)}">')
        if bone.parent < 0:
            lines.append(f'{pad}  <freejoint name="{prefix}root"/>')
        for axis_name, axis, (low, high) in (bone.free_axes() if bone.parent >= 0 else ()):
            lines.append(f'{pad}  <joint name="{prefix}{bone.name}_{axis_name}" type="hinge" axis="{fmt(axis)}" '
                         f'range="{fmt(np.radians(low), np.radians(high))}"/>')
        lines.append(f'{pad}  <geom name="{prefix}{bone.name}" type="capsule" '
                     f'fromto="{fmt(np.zeros(3), bone.distal - bone.proximal)}" size="{fmt(bone.radius)}"/>')
        for child in skeleton.children(index):
            emit(child, depth + 1)
        lines.append(f"{pad}</body>")

    emit(0, indent)
    return "\n".join(lines) + "\n"


def actuators(skeleton: Skeleton, prefix: str = "", indent: int = 2) -> str:
    kp = gain(skeleton)
    pad = "  " * indent
    lines = []
    for bone in skeleton.bones[1:]:
        for axis_name, _, (low, high) in bone.free_axes():
            name = f"{prefix}{bone.name}_{axis_name}"
            lines.append(f'{pad}<position name="{name}" joint="{name}" kp="{fmt(kp)}" '
                         f'ctrlrange="{fmt(np.radians(low), np.radians(high))}" forcerange="{fmt(-kp, kp)}"/>')
    return "\n".join(lines) + ("\n" if lines else "")


def header(model_name: str) -> str:
    return (f'<mujoco model="{model_name}">\n'
            '  <compiler angle="radian" autolimits="true"/>\n'
            f'  <option timestep="{fmt(TIMESTEP)}" gravity="0 0 {fmt(-GRAVITY)}" integrator="implicitfast"/>\n')


def to_mjcf(skeleton: Skeleton) -> str:
    """A standalone model: the creature standing on a floor plane at the origin."""
    return (header(f"creature-{skeleton.kind}-{skeleton.seed}") + defaults(skeleton)
            + "  <worldbody>\n"
            + f'    <geom name="floor" type="plane" size="0 0 1" {GROUND_CONTACT}/>\n'
            + body(skeleton)
            + "  </worldbody>\n  <actuator>\n" + actuators(skeleton) + "  </actuator>\n</mujoco>\n")
