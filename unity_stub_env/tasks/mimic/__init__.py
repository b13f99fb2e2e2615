"""The ``mimic`` task: ``task`` (model, reference tables, actions, observations, rewards),
``motions`` (the reference clips), ``expert`` (a scripted balance expert) and ``evaluation`` (every
motion, then standing under pushes). Their public names are importable from here."""
from __future__ import annotations

from unity_stub_env.geometry import cross, quat_angle, quat_conj, quat_matrix, quat_mul
from unity_stub_env.tasks.mimic.evaluation import (
    EVAL_SECONDS,
    PUSH_EVAL_INTERVAL,
    PUSH_LADDER,
    evaluate,
    format_table,
    run_trials,
)
from unity_stub_env.tasks.mimic.expert import BALANCE_ANKLE_GAIN, BALANCE_COM_HEIGHT, BalanceExpert
from unity_stub_env.tasks.mimic.motions import JOINTS, MOTIONS, RATE, load_motion
from unity_stub_env.tasks.mimic.task import (
    AGENT_SPACING,
    AGENTS_PER_AREA,
    AREA_SPACING,
    CONTROL_DT,
    DEEPMIMIC_WEIGHTS,
    END_EFFECTORS,
    FEET,
    MAX_DRIFT,
    OBSERVATION_SIZE,
    OBSERVED,
    PUSH_INTERVAL,
    SCALES,
    SEED_WEIGHTS,
    SUBSTEPS,
    TERMS,
    XML_PATH,
    MimicTask,
    Reference,
    build_model,
    reward_terms,
)

__all__ = [
    "AGENT_SPACING", "AGENTS_PER_AREA", "AREA_SPACING", "BALANCE_ANKLE_GAIN", "BALANCE_COM_HEIGHT", "CONTROL_DT",
    "DEEPMIMIC_WEIGHTS", "END_EFFECTORS", "EVAL_SECONDS", "FEET", "JOINTS", "MAX_DRIFT", "MOTIONS",
    "OBSERVATION_SIZE", "OBSERVED", "PUSH_EVAL_INTERVAL", "PUSH_INTERVAL", "PUSH_LADDER", "RATE", "SCALES",
    "SEED_WEIGHTS", "SUBSTEPS", "TERMS", "XML_PATH", "BalanceExpert", "MimicTask", "Reference", "build_model",
    "cross", "evaluate", "format_table", "load_motion", "quat_angle", "quat_conj", "quat_matrix", "quat_mul",
    "reward_terms", "run_trials",
]
