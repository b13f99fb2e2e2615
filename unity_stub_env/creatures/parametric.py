"""Parametric bipeds and quadrupeds (the creature report's generator, after Hudson's
model; docs/stub-tasks.md, "Seed projects").

Every length and girth is drawn uniformly between the per-part bounds of ``BIPED`` / ``QUADRUPED``
(metres; a girth is a circumference, the capsule radius is girth / 2 pi) from one
``numpy.random.Generator(PCG64(seed))``, in a fixed order, so a seed always gives the same
creature (with this version of the module). Frames and limits: ``skeleton.py``.

Construction, in the report's order:
  * **torso**: a total length, split into 3 bones at uniform fractions (each bone's share drawn in
    [0.5, 1.5] and normalised), each bone with its own girth; upright for bipeds, along +x for
    quadrupeds; the lowest (biped) / rearmost (quadruped) torso bone is the root.
  * **hip**: a rigid bone at the root's proximal point pointing away from the torso (it lengthens
    it); one pair of legs hangs from its midpoint, each leg offset sideways by the hip's radius.
    Quadrupeds get a second hip at the last torso bone's distal point, continuing the torso, with
    the front pair of legs.
  * **legs**, generated once per pair and mirrored (so pairs are symmetric): a total length split
    into 2 bones (biped) or 4 (quadruped), girths drawn and sorted so the thickest bone is nearest
    the body; straight down; a biped's lower leg ends in a foot pointing forward.
  * **arms** (bipeds only): like the legs, 2 bones per arm, hanging from the midpoint of a rigid
    shoulder bone that continues the torso upwards.
  * **neck**: a random number of bones (1..3) and total length; the biped's continues the torso up
    from the shoulder's distal point; the quadruped's starts at the front hip's distal point, its
    first bone pitched up between the front hip's proximal axis (forward) and its negative ventral
    axis (up) by a uniform angle; each further neck bone turns by a uniform angle in [-20, 20] deg.
    The turns are about the lateral axis (in the mid-plane): a turn about any other axis would
    break the creature's left/right symmetry. **head**: one bone extending the last neck bone.
  * A quadruped's front and rear legs may differ in length: the torso is pitched so that all four
    feet end at the same height with the legs still vertical (the report's final rotation).
Finally the creature is lifted so that its lowest point is 5 mm above z = 0.
"""
from __future__ import annotations

import numpy as np

from unity_stub_env.creatures.skeleton import Bone, Skeleton, mirrored, rotate, unit

TWO_PI = 2.0 * np.pi
BIPED = {
    "torso_length": (0.45, 0.65), "torso_girth": (0.50, 0.80),
    "hip_length": (0.08, 0.14), "hip_girth": (0.50, 0.70),
    "leg_length": (0.70, 0.95), "leg_girth": (0.25, 0.45),
    "foot_length": (0.14, 0.22), "foot_girth": (0.20, 0.30),
    "shoulder_length": (0.05, 0.10), "shoulder_girth": (0.45, 0.65),
    "arm_length": (0.50, 0.70), "arm_girth": (0.18, 0.30),
    "neck_bones": (1, 3), "neck_length": (0.08, 0.18), "neck_girth": (0.25, 0.35),
    "head_length": (0.15, 0.25), "head_girth": (0.50, 0.70),
}
QUADRUPED = {
    "torso_length": (0.60, 1.00), "torso_girth": (0.60, 0.90),
    "hip_length": (0.08, 0.14), "hip_girth": (0.50, 0.70),
    "leg_length": (0.50, 0.70), "leg_girth": (0.20, 0.40),
    "neck_bones": (1, 3), "neck_length": (0.15, 0.30), "neck_girth": (0.30, 0.45),
    "head_length": (0.15, 0.30), "head_girth": (0.40, 0.60),
}
X, Y, Z = np.eye(3)


def _split(rng: np.random.Generator, total: float, count: int) -> np.ndarray:
    shares = rng.uniform(0.5, 1.5, count)
    return total * shares / shares.sum()


def _radii(rng: np.random.Generator, bounds: tuple[float, float], count: int, sort: bool = False) -> np.ndarray:
    girth = rng.uniform(*bounds, count)
    if sort:
        girth = np.sort(girth)[::-1]  # thickest nearest the body
    return girth / TWO_PI


class _Builder:
    def __init__(self) -> None:
        self.bones: list[Bone] = []

    def add(self, name, category, parent, proximal, direction, length, radius, ventral, side=0) -> int:
        proximal = np.asarray(proximal, dtype=np.float64)
        self.bones.append(Bone(name, category, parent, proximal, proximal + unit(direction) * length,
                               float(radius), unit(ventral), side))
        return len(self.bones) - 1

    def chain(self, prefix, categories, parent, start, direction, lengths, radii, ventral, side=0) -> list[int]:
        """Bones end to end from ``start``; returns their indices."""
        indices, point = [], np.asarray(start, dtype=np.float64)
        for k, (category, length, radius) in enumerate(zip(categories, lengths, radii)):
            parent = self.add(f"{prefix}{k}", category, parent, point, direction, length, radius, ventral, side)
            point = self.bones[parent].distal
            indices.append(parent)
        return indices

    def mirror_pair(self, right: list[int], left_prefix: str) -> None:
        """Append the mirrored (left) copy of the right chain ``right``."""
        remap: dict[int, int] = {}
        for k, index in enumerate(right):
            bone = self.bones[index]
            parent = remap.get(bone.parent, bone.parent)
            self.bones.append(mirrored(bone, parent, f"{left_prefix}{k}" if bone.category != "foot"
                                       else bone.name.replace("_r", "_l")))
            remap[index] = len(self.bones) - 1


def _leg_categories(count: int) -> list[str]:
    return ["leg_upper"] + ["leg"] * (count - 1)


def _neck_and_head(b: _Builder, rng, p: dict, parent: int, start, direction, ventral, first_pitch: float) -> None:
    count = int(rng.integers(p["neck_bones"][0], p["neck_bones"][1] + 1))
    lengths = _split(rng, rng.uniform(*p["neck_length"]), count)
    radii = _radii(rng, p["neck_girth"], count)
    turns = rng.uniform(-20.0, 20.0, count - 1)
    lateral = np.cross(unit(direction), unit(ventral))
    direction, ventral = rotate(direction, lateral, first_pitch), rotate(ventral, lateral, first_pitch)
    point = np.asarray(start, dtype=np.float64)
    for k in range(count):
        if k > 0:
            direction, ventral = rotate(direction, lateral, turns[k - 1]), rotate(ventral, lateral, turns[k - 1])
        parent = b.add(f"neck{k}", "neck", parent, point, direction, lengths[k], radii[k], ventral)
        point = b.bones[parent].distal
    head_length, head_radius = rng.uniform(*p["head_length"]), rng.uniform(*p["head_girth"]) / TWO_PI
    b.add("head", "head", parent, point, direction, head_length, head_radius, ventral)


def biped(seed: int, params: dict | None = None) -> Skeleton:
    """A biped: 3 upright torso bones, hip, 2 legs of 2 bones + foot, shoulder, 2 arms of 2 bones,
    a neck of 1-3 bones and a head."""
    p = {**BIPED, **(params or {})}
    rng = np.random.default_rng(seed)
    b = _Builder()
    torso = b.chain("torso", ["torso"] * 3, -1, [0, 0, 0], Z, _split(rng, rng.uniform(*p["torso_length"]), 3),
                    _radii(rng, p["torso_girth"], 3), X)
    hip = b.add("hip", "hip", torso[0], [0, 0, 0], -Z, rng.uniform(*p["hip_length"]),
                rng.uniform(*p["hip_girth"]) / TWO_PI, X)
    hip_bone = b.bones[hip]
    leg_lengths = _split(rng, rng.uniform(*p["leg_length"]), 2)
    leg_radii = _radii(rng, p["leg_girth"], 2, sort=True)
    foot_length, foot_radius = rng.uniform(*p["foot_length"]), rng.uniform(*p["foot_girth"]) / TWO_PI
    attach = (hip_bone.proximal + hip_bone.distal) / 2 - Y * hip_bone.radius
    right = b.chain("leg_r", _leg_categories(2), hip, attach, -Z, leg_lengths, leg_radii, X, side=-1)
    right.append(b.add("foot_r", "foot", right[-1], b.bones[right[-1]].distal, X, foot_length, foot_radius,
                       -Z, side=-1))
    b.mirror_pair(right, "leg_l")
    top = b.bones[torso[2]]
    shoulder = b.add("shoulder", "shoulder", torso[2], top.distal, Z, rng.uniform(*p["shoulder_length"]),
                     rng.uniform(*p["shoulder_girth"]) / TWO_PI, X)
    shoulder_bone = b.bones[shoulder]
    arm_lengths = _split(rng, rng.uniform(*p["arm_length"]), 2)
    arm_radii = _radii(rng, p["arm_girth"], 2, sort=True)
    attach = (shoulder_bone.proximal + shoulder_bone.distal) / 2 - Y * (top.radius + arm_radii[0])
    right = b.chain("arm_r", ["arm_upper", "arm"], shoulder, attach, -Z, arm_lengths, arm_radii, Y, side=-1)
    b.mirror_pair(right, "arm_l")
    _neck_and_head(b, rng, p, shoulder, shoulder_bone.distal, Z, X, 0.0)
    return Skeleton("biped", int(seed), b.bones).standing()


def quadruped(seed: int, params: dict | None = None) -> Skeleton:
    """A quadruped: 3 torso bones along +x, a rear and a front hip with a pair of 4-bone legs each,
    a neck of 1-3 bones and a head."""
    p = {**QUADRUPED, **(params or {})}
    rng = np.random.default_rng(seed)
    torso_lengths = _split(rng, rng.uniform(*p["torso_length"]), 3)
    torso_radii = _radii(rng, p["torso_girth"], 3)
    hip_lengths = rng.uniform(*p["hip_length"], 2)
    hip_radii = rng.uniform(*p["hip_girth"], 2) / TWO_PI
    pairs = []
    for _ in range(2):  # rear, front
        pairs.append((_split(rng, rng.uniform(*p["leg_length"]), 4), _radii(rng, p["leg_girth"], 4, sort=True)))
    rear_length, front_length = pairs[0][0].sum(), pairs[1][0].sum()
    # pitch the torso so both pairs of vertical legs end at the same height
    span = hip_lengths[0] / 2 + torso_lengths.sum() + hip_lengths[1] / 2
    pitch = np.arcsin(np.clip((front_length - rear_length) / span, -0.5, 0.5))
    forward = np.array([np.cos(pitch), 0.0, np.sin(pitch)])
    belly = np.array([np.sin(pitch), 0.0, -np.cos(pitch)])  # the ventral axis of a horizontal torso
    b = _Builder()
    torso = b.chain("torso", ["torso"] * 3, -1, [0, 0, 0], forward, torso_lengths, torso_radii, belly)
    rear = b.add("hip", "hip", torso[0], [0, 0, 0], -forward, hip_lengths[0], hip_radii[0], belly)
    front = b.add("hip_front", "hip", torso[2], b.bones[torso[2]].distal, forward, hip_lengths[1], hip_radii[1],
                  belly)
    for hip, tag, (lengths, radii) in ((rear, "rear", pairs[0]), (front, "front", pairs[1])):
        bone = b.bones[hip]
        attach = (bone.proximal + bone.distal) / 2 - Y * bone.radius
        right = b.chain(f"leg_{tag}_r", _leg_categories(4), hip, attach, -Z, lengths, radii, X, side=-1)
        b.mirror_pair(right, f"leg_{tag}_l")
    front_bone = b.bones[front]
    _neck_and_head(b, rng, p, front, front_bone.distal, forward, belly, float(np.degrees(-rng.uniform(0, np.pi / 2))))
    return Skeleton("quadruped", int(seed), b.bones).standing()
