"""The ``runner`` task: ``track`` (levels from the zones' HMMs, stackable spawn points), ``task``
(kinematics, observations, rewards) and ``evaluation`` (a policy along seeded tracks); the models
and corpora in ``data/``. Their public names are importable from here."""
from __future__ import annotations

from unity_stub_env.tasks.runner.evaluation import evaluate_tracks, runner_on_tracks
from unity_stub_env.tasks.runner.task import (
    COIN_REWARD,
    CURVATURE,
    DT,
    FALL_REWARD,
    FINISH_REWARD,
    HALF_WIDTH,
    HELD_OUT_SEED_START,
    HIT_RADIUS,
    LANES,
    LOOKAHEAD,
    MAX_TURN_RATE,
    OBS_SIZE,
    OBSTACLE_REWARD,
    PLATFORM_LENGTH,
    PROGRESS_REWARD,
    SPEED,
    START_DISTANCE,
    RunnerTask,
)
from unity_stub_env.tasks.runner.track import (
    COIN,
    DATA,
    DEFAULTS,
    PLATFORM_LABELS,
    SPAWN_STACKS,
    TURN_OF_KIND,
    ZONES,
    Track,
    generate_track,
    stack,
    zone_models,
)

__all__ = [
    "COIN", "COIN_REWARD", "CURVATURE", "DATA", "DEFAULTS", "DT", "FALL_REWARD", "FINISH_REWARD", "HALF_WIDTH",
    "HELD_OUT_SEED_START", "HIT_RADIUS", "LANES", "LOOKAHEAD", "MAX_TURN_RATE", "OBS_SIZE", "OBSTACLE_REWARD",
    "PLATFORM_LABELS", "PLATFORM_LENGTH", "PROGRESS_REWARD", "SPAWN_STACKS", "SPEED", "START_DISTANCE",
    "TURN_OF_KIND", "ZONES", "RunnerTask", "Track", "evaluate_tracks", "generate_track", "runner_on_tracks",
    "stack", "zone_models",
]
