"""The ``runner`` task's levels: a track of platforms and props from the zones' hidden Markov
models (docs/hmm.md), with stackable spawn points; a pure function of its seed and settings.

See the module docstring of ``task.py`` for the track's rules.
"""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from unity_stub_env.hmm import EPSILON_LABEL, Hmm

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")
ZONES = ("urban", "rural", "desert")
PLATFORM_LABELS = ("Left", "Right", "Straight")  # sorted: the codes an hmm sampler sends
TURN_OF_KIND = {"Start": 0, "Transition": 0, "Straight": 0, "Left": 1, "Right": -1}
COIN = "coin"
DEFAULTS = {"zones": 3, "zone_length_min": 4, "zone_length_max": 8, "first_zone": -1}
# objects a spawn point holds at most (left, centre, right lane); more than 1 = stackable
SPAWN_STACKS = {"urban": (1, 2, 1), "rural": (2, 1, 2), "desert": (1, 1, 3)}


@functools.lru_cache(maxsize=None)
def zone_models(zone: str) -> tuple[Hmm, Hmm]:
    """(platform model, prop model) of a zone, read once from data/."""
    return (Hmm.load(os.path.join(DATA, f"{zone}_platforms.json")),
            Hmm.load(os.path.join(DATA, f"{zone}_props.json")))


@dataclass
class Track:
    kinds: list[str]        # per platform: Start, Left, Right, Straight or Transition
    zones: list[int]        # per platform: 0 urban, 1 rural, 2 desert
    props: list[list[list[str]]]  # per platform and spawn point (left, centre, right): its stack, bottom first

    def turns(self) -> np.ndarray:
        return np.array([TURN_OF_KIND[kind] for kind in self.kinds], dtype=np.float64)

    def prop_codes(self) -> np.ndarray:
        """int8 [P, 3]: per spawn point +k for k stacked coins, -k for k obstacles, 0 empty."""
        return np.array([[sum(1 if label == COIN else -1 for label in stack) for stack in row]
                         for row in self.props], dtype=np.int8).reshape(len(self.props), 3)


def stack(labels: list[str]) -> list[str]:
    """The objects a stackable spawn point really holds, bottom first, from its share of the prop
    chain: up to the first empty label or change between coin and obstacle."""
    kept: list[str] = []
    for label in labels:
        if label == EPSILON_LABEL or (kept and (label == COIN) != (kept[0] == COIN)):
            break
        kept.append(label)
    return kept


def _props(zone: int, count: int, rng: np.random.Generator) -> list[list[list[str]]]:
    """Props of ``count`` consecutive platforms: one chain of labels, each platform taking one per
    place of its spawn points (SPAWN_STACKS), in spawn order, bottom first; a platform whose three
    spawn points all hold obstacles gets its centre emptied (the corpora never block a whole
    platform, but an HMM's sample may)."""
    if count == 0:
        return []
    model = zone_models(ZONES[zone])[1]
    sizes = SPAWN_STACKS[ZONES[zone]]
    per_platform = sum(sizes)
    labels = model.decode(model.sample_codes(1, per_platform * count, rng))[0]
    bounds = np.cumsum((0,) + sizes)
    rows = []
    for i in range(count):
        chain = labels[per_platform * i:per_platform * (i + 1)]
        row = [stack(chain[bounds[j]:bounds[j + 1]]) for j in range(3)]
        if all(spawn and spawn[0] != COIN for spawn in row):
            row[1] = []
        rows.append(row)
    return rows


def generate_track(seed: int, zones: int = 3, zone_length_min: int = 4, zone_length_max: int = 8,
                   first_zone: int = -1, platforms: list[str] | None = None) -> Track:
    """The track of ``seed`` (the same arguments always give the same track). ``platforms``: use
    this platform sequence (from an hmm sampler) instead of the zone models, with zone
    ``first_zone``'s props."""
    rng = np.random.default_rng(seed)
    first = int(rng.integers(0, len(ZONES))) if first_zone < 0 else int(first_zone) % len(ZONES)
    kinds, zone_of, props = ["Start"], [first], [[[], [], []]]
    if platforms is not None:
        kinds += list(platforms)
        zone_of += [first] * len(platforms)
        props += _props(first, len(platforms), rng)
        return Track(kinds, zone_of, props)
    low = max(1, int(zone_length_min))
    high = max(low, int(zone_length_max))
    for z in range(max(1, int(zones))):
        zone = (first + z) % len(ZONES)
        if z:
            kinds.append("Transition")
            zone_of.append(zone)
            props.append([[], [], []])
        length = int(rng.integers(low, high + 1))
        platform_model = zone_models(ZONES[zone])[0]
        kinds += platform_model.decode(platform_model.sample_codes(1, length, rng))[0]
        zone_of += [zone] * length
        props += _props(zone, length, rng)
    return Track(kinds, zone_of, props)
