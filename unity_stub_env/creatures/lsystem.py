r"""Stochastic bracketed L-system creatures drawn by a 3D turtle (the creature report's first
generator; docs/stub-tasks.md, "Seed projects").

The grammar (``RULES``): one non-terminal per body part, each with weighted alternatives chosen
by the seeded generator at every rewrite; ``STEPS`` parallel rewrites of the axiom, then any
non-terminal left is erased. The start string lays the body out: the turtle starts at the front
end of the torso heading backwards (-x), draws the neck and head in a branch turned round, then
the torso backwards with pairs of legs (and optionally arms) branching off at its joints::

    axiom  B
    B -> [N] Q t P t P           0.3      (two leg pairs, arms)
       | [N] t P t P             0.4      (two leg pairs)
       | [N] t P t P t P         0.3      (three leg pairs)
    P -> [+(90) s &(90) L] [-(90) s &(90) L]      a pair of legs, left and right
    L -> l l                     0.4  | l l l   0.4  | l l l l  0.2
    Q -> [+(90) o &(30) A] [-(90) o &(30) A]      a pair of arms, 30 deg below horizontal
    A -> a a                     1.0
    N -> |(180) ^(35) n H        0.5  | |(180) ^(35) n n H  0.5
    H -> h                       1.0

Turtle commands (angles in degrees, the default 25 when no ``(angle)`` follows): ``+``/``-`` yaw
left/right about the turtle's up axis, ``&``/``^`` pitch down/up about its left axis, ``\``/``/``
roll, ``|`` turn about up by the angle, ``[``/``]`` push/pop the turtle state. Lower-case letters
draw one segment each, which becomes one bone of a category: ``t`` torso, ``s`` hip and ``o``
shoulder (rigid), ``l`` leg, ``a`` arm, ``n`` neck, ``h`` head; the first ``l``/``a`` after an
``s``/``o`` is ``leg_upper``/``arm_upper``. Segment length = the category's base length
(``LENGTHS``) times a uniform factor in [0.8, 1.2], radius = ``RADII`` of the category; each
segment's factor is drawn when it is drawn, so left and right limbs generally differ, as in
the report (these creatures are not symmetric).

The bone tree is rebuilt from the segments' endpoints alone (the report's method): the root is
the first torso segment; any other segment's parent is the earliest segment whose distal point
equals its proximal point (within 1e-9 m). The report assumes such a segment always exists; the
branches leaving the torso's front end (neck, arms) start where no segment ends, and are attached
to the root at its proximal point. The bones are then ordered breadth-first from the root. Bone frames: proximal axis along the segment, ventral axis = the turtle's
down vector while drawing; joint limits by category as in ``skeleton.py``.
"""
from __future__ import annotations

import re

import numpy as np

from unity_stub_env.creatures.skeleton import Bone, Skeleton, rotate, unit

AXIOM = "B"
STEPS = 4
RULES: dict[str, list[tuple[float, str]]] = {
    "B": [(0.3, "[N]Qt P t P"), (0.4, "[N]t P t P"), (0.3, "[N]t P t P t P")],
    "P": [(1.0, "[+(90)s&(90)L][-(90)s&(90)L]")],
    "L": [(0.4, "ll"), (0.4, "lll"), (0.2, "llll")],
    "Q": [(1.0, "[+(90)o&(30)A][-(90)o&(30)A]")],
    "A": [(1.0, "aa")],
    "N": [(0.5, "|(180)^(35)nH"), (0.5, "|(180)^(35)nnH")],
    "H": [(1.0, "h")],
}
DEFAULT_ANGLE = 25.0
CATEGORY = {"t": "torso", "s": "hip", "o": "shoulder", "l": "leg", "a": "arm", "n": "neck", "h": "head"}
LENGTHS = {"t": 0.25, "s": 0.10, "o": 0.10, "l": 0.18, "a": 0.20, "n": 0.10, "h": 0.18}
RADII = {"t": 0.11, "s": 0.08, "o": 0.07, "l": 0.05, "a": 0.04, "n": 0.05, "h": 0.08}
_TOKEN = re.compile(r"([A-Za-z+\-&^\\/|\[\]])(?:\(([-+\d.]+)\))?")


def derive(seed: int, steps: int = STEPS, rng: np.random.Generator | None = None) -> str:
    """The L-system string after ``steps`` stochastic rewrites (non-terminals left are erased)."""
    rng = rng if rng is not None else np.random.default_rng(seed)
    text = AXIOM
    for _ in range(steps):
        out = []
        for symbol in text:
            if symbol in RULES:
                weights = np.array([w for w, _ in RULES[symbol]])
                out.append(RULES[symbol][int(rng.choice(len(weights), p=weights / weights.sum()))][1])
            else:
                out.append(symbol)
        text = "".join(out)
    return "".join(symbol for symbol in text if symbol not in RULES and symbol != " ")


def draw(text: str, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray, str, np.ndarray]]:
    """Run the turtle: (start, end, drawing symbol, turtle down vector) per segment."""
    position = np.zeros(3)
    heading, left, up = np.array([-1.0, 0, 0]), np.array([0, -1.0, 0]), np.array([0, 0, 1.0])
    stack, segments = [], []
    for symbol, argument in _TOKEN.findall(text):
        angle = float(argument) if argument else DEFAULT_ANGLE
        if symbol in CATEGORY:
            end = position + heading * LENGTHS[symbol] * rng.uniform(0.8, 1.2)
            segments.append((position.copy(), end, symbol, -up.copy()))
            position = end
        elif symbol in "+-":
            sign = 1.0 if symbol == "+" else -1.0
            heading, left = rotate(heading, up, sign * angle), rotate(left, up, sign * angle)
        elif symbol in "&^":
            sign = 1.0 if symbol == "&" else -1.0
            heading, up = rotate(heading, left, sign * angle), rotate(up, left, sign * angle)
        elif symbol in "\\/":
            sign = 1.0 if symbol == "\\" else -1.0
            left, up = rotate(left, heading, sign * angle), rotate(up, heading, sign * angle)
        elif symbol == "|":
            heading, left = rotate(heading, up, angle), rotate(left, up, angle)
        elif symbol == "[":
            stack.append((position.copy(), heading.copy(), left.copy(), up.copy()))
        elif symbol == "]":
            position, heading, left, up = stack.pop()
    return segments


def build_tree(segments) -> list[Bone]:
    """Bones from turtle segments, parents found from the endpoints (module docstring)."""
    symbols = [symbol for _, _, symbol, _ in segments]
    if "t" not in symbols:
        raise ValueError("an L-system creature needs at least one torso segment 't'")
    root = symbols.index("t")
    parent = {root: -1}
    for k, (start, _, _, _) in enumerate(segments):
        if k == root:
            continue
        ends = [j for j, segment in enumerate(segments) if j != k and np.linalg.norm(segment[1] - start) < 1e-9]
        if ends:
            parent[k] = ends[0]
        elif np.linalg.norm(segments[root][0] - start) < 1e-9:
            parent[k] = root
        else:
            raise ValueError(f"segment {k} starts where no segment ends")
    order, index = [root], {root: 0}
    for k in order:  # breadth-first; grows while iterating
        for child in sorted(c for c, p in parent.items() if p == k):
            index[child] = len(order)
            order.append(child)
    bones: list[Bone] = []
    for k in order:
        start, end, symbol, down = segments[k]
        category = CATEGORY[symbol]
        up = parent[k]
        if symbol in "la" and up >= 0 and segments[up][2] in "so":
            category += "_upper"
        direction = unit(end - start)
        ventral = unit(down - np.dot(down, direction) * direction)
        bones.append(Bone(f"{category}{len(bones)}", category, index[up] if up >= 0 else -1, start, end,
                          RADII[symbol], ventral))
    return bones


def lsystem(seed: int, steps: int = STEPS) -> Skeleton:
    """An L-system creature from ``seed``: derive, draw, rebuild the tree, stand it on z = 0."""
    rng = np.random.default_rng(seed)
    text = derive(seed, steps, rng)
    return Skeleton("lsystem", int(seed), build_tree(draw(text, rng))).standing()
