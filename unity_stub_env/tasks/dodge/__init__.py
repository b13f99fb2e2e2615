"""The ``dodge`` task: ``task`` (model, actions, observations, rewards) and ``evaluation`` (the
scripted and random throws). Their public names are importable from here."""
from __future__ import annotations

from unity_stub_env.geometry import (
    axis_angle_matrix,
    convex_hull,
    euler_to_matrix,
    euler_to_quat,
    matrix_to_euler,
    polygon_centroid,
)
from unity_stub_env.tasks.dodge.evaluation import (
    EVAL_AREAS_PER_BATCH,
    MARKS,
    SCRIPTED_HEIGHT,
    SCRIPTED_SPEED,
    SCRIPTED_THROWS,
    SIDES,
    UPPER_BODY,
    evaluate,
    random_throws,
    run_throws,
    scripted_throws,
    summarize,
)
from unity_stub_env.tasks.dodge.task import (
    AGENT_SPACING,
    AGENTS_PER_AREA,
    AREA_SPACING,
    BALANCE_REWARD,
    CROUCH_RATE,
    DEAD_ZONE,
    FAR_DISTANCE,
    HIP_HEIGHT,
    HIT_PENALTY,
    LEG_LENGTH,
    NECK_RATE,
    PASS_DISTANCE,
    PASS_REWARD,
    POSE_JOINTS,
    REGIONS,
    SUBSTEPS,
    THROW_AZIMUTH,
    THROW_DISTANCE,
    THROW_HEIGHT,
    THROW_SPEED,
    TORSO_RATE,
    XML_PATH,
    DodgeTask,
    Throws,
    build_model,
    effort,
)

__all__ = [
    "AGENT_SPACING", "AGENTS_PER_AREA", "AREA_SPACING", "BALANCE_REWARD", "CROUCH_RATE", "DEAD_ZONE",
    "EVAL_AREAS_PER_BATCH", "FAR_DISTANCE", "HIP_HEIGHT", "HIT_PENALTY", "LEG_LENGTH", "MARKS", "NECK_RATE",
    "PASS_DISTANCE", "PASS_REWARD", "POSE_JOINTS", "REGIONS", "SCRIPTED_HEIGHT", "SCRIPTED_SPEED",
    "SCRIPTED_THROWS", "SIDES", "SUBSTEPS", "THROW_AZIMUTH", "THROW_DISTANCE", "THROW_HEIGHT", "THROW_SPEED",
    "TORSO_RATE", "UPPER_BODY", "XML_PATH", "DodgeTask", "Throws", "axis_angle_matrix", "build_model",
    "convex_hull", "effort", "euler_to_matrix", "euler_to_quat", "evaluate", "matrix_to_euler",
    "polygon_centroid", "random_throws", "run_throws", "scripted_throws", "summarize",
]
