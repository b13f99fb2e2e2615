"""Hyperparameter decay over the trainer step (ML-Agents ``linear`` / ``constant`` schedules)."""
from __future__ import annotations

LEARNING_RATE_FLOOR = 1e-10
EPSILON_FLOOR = 0.1
BETA_FLOOR = 1e-5

SCHEDULES = ("linear", "constant")


def decay(schedule: str, initial: float, floor: float, step: int, max_step: int) -> float:
    """Value of a hyperparameter at ``step``.

    linear:   (initial - floor) * (1 - min(step, max_step) / max_step) + floor
    constant: initial
    """
    if schedule == "constant":
        return float(initial)
    if schedule != "linear":
        raise ValueError(f"unknown schedule {schedule!r}; expected one of {SCHEDULES}")
    if max_step <= 0:
        return float(floor)
    fraction_left = 1.0 - min(step, max_step) / max_step
    return float((initial - floor) * fraction_left + floor)
