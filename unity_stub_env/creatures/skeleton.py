"""The bone tree every creature generator produces, and the joint limits by bone category.

World frame of a generated creature: z up, the creature faces +x, +y is its left. Lengths in
metres, angles in degrees.

Bone frame (the convention of the creature report, docs/stub-tasks.md, "Seed projects"): the **proximal
point** is where the bone is attached to its parent (the end nearest the body's centre), the **distal
point** its other end; the **proximal axis** runs from the proximal to the distal point; the **ventral
axis** is orthogonal to it and points to the bone's front (for arms: towards the body; for a horizontal
torso: down; otherwise: where the creature looks); the **lateral axis** = proximal x ventral completes a
right-handed frame.
A bone's joint sits at its proximal point and rotates it relative to its parent about these axes.

Joint limits by category (``LIMITS``; degrees, (min, max) per axis; an axis not listed is locked).
Every range contains 0, the rest pose:

  =========  ==============  =============  ===============
  category   lateral         ventral        proximal (twist)
  =========  ==============  =============  ===============
  torso      -30 .. 30       -20 .. 20      -20 .. 20
  hip        (rigid: welded to its parent, no joint)
  shoulder   (rigid: welded to its parent, no joint)
  leg_upper  -70 .. 70       -30 .. 30      locked
  leg        -90 .. 60       locked         locked
  foot       -45 .. 45       -20 .. 20      locked
  arm_upper  -90 .. 90       -60 .. 60      -45 .. 45
  arm        -120 .. 10      locked         locked
  neck       -30 .. 30       -30 .. 30      locked
  head       -30 .. 30       -30 .. 30      locked
  =========  ==============  =============  ===============

A joint with one free axis is a MuJoCo hinge; with two or three, one hinge per free axis in the
order lateral, ventral, proximal (like Unity's ConfigurableJoint, which limits each axis on its
own; a MuJoCo ``ball`` joint can only limit one cone angle, so it cannot express this table).

Mirrored bones (the left member of a symmetric pair, ``side == +1``) are the reflection of their
right partner through the plane y = 0; their joint axes are the reflected axes times -1 (as the
report does for Unity), so one table entry moves both limbs mirror-symmetrically. Bones on the
mid-plane have ``side == 0``, right bones ``side == -1``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

AXES = ("lateral", "ventral", "proximal")
LIMITS: dict[str, dict[str, tuple[float, float]]] = {
    "torso": {"lateral": (-30.0, 30.0), "ventral": (-20.0, 20.0), "proximal": (-20.0, 20.0)},
    "hip": {},
    "shoulder": {},
    "leg_upper": {"lateral": (-70.0, 70.0), "ventral": (-30.0, 30.0)},
    "leg": {"lateral": (-90.0, 60.0)},
    "foot": {"lateral": (-45.0, 45.0), "ventral": (-20.0, 20.0)},
    "arm_upper": {"lateral": (-90.0, 90.0), "ventral": (-60.0, 60.0), "proximal": (-45.0, 45.0)},
    "arm": {"lateral": (-120.0, 10.0)},
    "neck": {"lateral": (-30.0, 30.0), "ventral": (-30.0, 30.0)},
    "head": {"lateral": (-30.0, 30.0), "ventral": (-30.0, 30.0)},
}
CATEGORIES = tuple(LIMITS)
# reflection through the creature's mid-plane y = 0
MIRROR = np.diag([1.0, -1.0, 1.0])


@dataclass
class Bone:
    """One bone: a capsule from ``proximal`` to ``distal`` (world points of the rest pose) with
    radius ``radius``; ``parent`` indexes the skeleton's bone list (-1: the root)."""

    name: str
    category: str
    parent: int
    proximal: np.ndarray
    distal: np.ndarray
    radius: float
    ventral: np.ndarray
    side: int = 0  # +1 left (mirrored), -1 right, 0 mid-plane
    # the joint axes (world, rest pose), one unit vector per AXES entry; None: computed from the frame
    joint_axes: np.ndarray | None = field(default=None, repr=False)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.distal - self.proximal))

    @property
    def proximal_axis(self) -> np.ndarray:
        d = self.distal - self.proximal
        return d / np.linalg.norm(d)

    @property
    def lateral(self) -> np.ndarray:
        return np.cross(self.proximal_axis, self.ventral)

    def axes(self) -> np.ndarray:
        """float [3, 3]: the joint axes lateral, ventral, proximal (rows)."""
        if self.joint_axes is not None:
            return self.joint_axes
        return np.stack([self.lateral, self.ventral, self.proximal_axis])

    def free_axes(self) -> list[tuple[str, np.ndarray, tuple[float, float]]]:
        """(axis name, world unit vector, (min, max) degrees) of each hinge of this bone's joint."""
        limits = LIMITS[self.category]
        axes = self.axes()
        return [(name, axes[i], limits[name]) for i, name in enumerate(AXES) if name in limits]


@dataclass
class Skeleton:
    """A creature: its bones (parents before children, bone 0 the root) and how it was made."""

    kind: str
    seed: int
    bones: list[Bone]

    def children(self, index: int) -> list[int]:
        return [i for i, bone in enumerate(self.bones) if bone.parent == index]

    def lowest_point(self) -> float:
        """The lowest z of any capsule surface."""
        return min(min(b.proximal[2], b.distal[2]) - b.radius for b in self.bones)

    def translated(self, offset) -> "Skeleton":
        offset = np.asarray(offset, dtype=np.float64)
        bones = [Bone(b.name, b.category, b.parent, b.proximal + offset, b.distal + offset, b.radius,
                      b.ventral, b.side, b.joint_axes) for b in self.bones]
        return Skeleton(self.kind, self.seed, bones)

    def standing(self, clearance: float = 0.005) -> "Skeleton":
        """The same skeleton lifted (or lowered) so its lowest point is ``clearance`` above z = 0."""
        return self.translated([0.0, 0.0, clearance - self.lowest_point()])

    def num_hinges(self) -> int:
        """Hinges of all bones but the root (it hangs on a free joint)."""
        return sum(len(b.free_axes()) for b in self.bones[1:])


def mirrored(bone: Bone, parent: int, name: str) -> Bone:
    """The left partner of a right bone ``bone``: reflected through y = 0, joint axes reflected
    and negated (module docstring)."""
    axes = -(bone.axes() @ MIRROR.T)
    return Bone(name, bone.category, parent, MIRROR @ bone.proximal, MIRROR @ bone.distal, bone.radius,
                MIRROR @ bone.ventral, +1, axes)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def rotate(v: np.ndarray, axis: np.ndarray, degrees: float) -> np.ndarray:
    """Rodrigues: ``v`` rotated by ``degrees`` about the unit ``axis``."""
    a = np.radians(degrees)
    axis = unit(axis)
    return v * np.cos(a) + np.cross(axis, v) * np.sin(a) + axis * np.dot(axis, v) * (1 - np.cos(a))
