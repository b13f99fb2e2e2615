"""The ``creature`` task: ``task`` (arenas, creature, actions, observations, rewards), ``terrain``
(the heightfields' noise) and ``evaluation`` (a policy per simulated minute). Their public names
are importable from here."""
from __future__ import annotations

from unity_stub_env.tasks.creature.evaluation import run_policy
from unity_stub_env.tasks.creature.task import (
    AREA_SPACING,
    ARENA_HALF,
    DEFAULTS,
    HFIELD_BASE,
    HFIELD_SIZE,
    KINDS,
    MAX_OBSTACLES,
    MAX_STEP,
    MAX_TERRAIN_HEIGHT,
    PARK,
    REACH_DISTANCE,
    SPAWN_CLEARANCE,
    SPAWN_RADIUS,
    SUBSTEPS,
    TARGET_MIN_DISTANCE,
    TARGET_RANGE,
    VITAL,
    WALL_HEIGHT,
    WALL_THICKNESS,
    CreatureTask,
    arena_xml,
    creature_of,
    look_reward,
    match_speed_reward,
    observation_size,
)
from unity_stub_env.tasks.creature.terrain import NOISE_CELL, NOISE_OCTAVES, perlin

__all__ = [
    "AREA_SPACING", "ARENA_HALF", "CreatureTask", "DEFAULTS", "HFIELD_BASE", "HFIELD_SIZE", "KINDS",
    "MAX_OBSTACLES", "MAX_STEP", "MAX_TERRAIN_HEIGHT", "NOISE_CELL", "NOISE_OCTAVES", "PARK",
    "REACH_DISTANCE", "SPAWN_CLEARANCE", "SPAWN_RADIUS", "SUBSTEPS", "TARGET_MIN_DISTANCE",
    "TARGET_RANGE", "VITAL", "WALL_HEIGHT", "WALL_THICKNESS", "arena_xml", "creature_of", "look_reward",
    "match_speed_reward", "observation_size", "perlin", "run_policy"
]
