"""Gymnasium spaces for a stub task's specs, and actions from those spaces back to the task's arrays.

Observations: one sensor -> ``Box(-inf, inf, shape, float32)``; several -> ``Dict`` keyed by
sensor name (what SB3's ``MultiInputPolicy`` reads). Actions: continuous only -> ``Box(-1, 1)``
(the range Unity clips to); one discrete branch -> ``Discrete``; several -> ``MultiDiscrete``.
No stub task mixes continuous and discrete actions; such a spec is refused with a clear message.
"""
from __future__ import annotations

import numpy as np
from gymnasium import spaces

from protos.types import ActionSpec, ObservationSpec


def observation_space(specs: tuple[ObservationSpec, ...]) -> spaces.Space:
    boxes = [spaces.Box(-np.inf, np.inf, tuple(spec.shape), np.float32) for spec in specs]
    if len(boxes) == 1:
        return boxes[0]
    return spaces.Dict({sensor_name(spec, i): box for i, (spec, box) in enumerate(zip(specs, boxes))})


def sensor_name(spec: ObservationSpec, index: int) -> str:
    """The Dict key of a sensor: its name, or ``obs<index>`` for an unnamed one."""
    return spec.name or f"obs{index}"


def observations(specs: tuple[ObservationSpec, ...], arrays: list[np.ndarray], rows=slice(None)):
    """The task's per-sensor arrays [n, ...] at ``rows`` in the form of ``observation_space``."""
    if len(arrays) == 1:
        return arrays[0][rows]
    return {sensor_name(spec, i): array[rows] for i, (spec, array) in enumerate(zip(specs, arrays))}


def action_space(spec: ActionSpec) -> spaces.Space:
    branches = tuple(int(b) for b in spec.discrete_branches)
    if spec.continuous_size and branches:
        raise ValueError(f"This task's actions mix {spec.continuous_size} continuous with discrete branches "
                         f"{list(branches)}; the Gymnasium and PettingZoo forms support one kind only "
                         "(use the task through UnityEnvironment for hybrid actions)")
    if spec.continuous_size:
        return spaces.Box(-1.0, 1.0, (int(spec.continuous_size),), np.float32)
    if len(branches) == 1:
        return spaces.Discrete(branches[0])
    return spaces.MultiDiscrete(np.array(branches, dtype=np.int64))


def task_actions(spec: ActionSpec, actions, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(continuous float32 [count, c], discrete int32 [count, b]) for ``count`` agents' actions
    from ``action_space``: [count, c] / [count] / [count, b], or one agent's action when count = 1."""
    c, b = int(spec.continuous_size), len(spec.discrete_branches)
    actions = np.asarray(actions)
    if c:
        continuous = actions.astype(np.float32, copy=False).reshape(count, c)
        return continuous, np.zeros((count, 0), dtype=np.int32)
    return np.zeros((count, 0), dtype=np.float32), actions.astype(np.int32, copy=False).reshape(count, b)
