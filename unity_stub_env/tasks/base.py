"""What every stub task provides: specs, vectorised reset/step over all agents, episode stats.

A task simulates ``num_agents = num_areas * agents_per_area`` agents of ONE behavior at once.
Arrays are batched over agents (n = num_agents):

  observe()        -> list of float32 [n, *observation_specs[i].shape], one per sensor
  step(cont, disc) -> TaskStep (one control step; cont float32 [n, c], disc int32 [n, b])
  reset(mask)      -> begin a new episode for the agents where mask [n] is True (all if None)
  action_mask()    -> bool [n, sum(discrete_branches)] (True = forbidden) or None

``step`` never resets anyone: the academy reads the terminal observations first, then calls
``reset`` for the finished agents. Tasks count their own episode steps and report
``interrupted`` when ``max_step`` is reached (0 = no limit), like Unity's ``Agent.MaxStep``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from protos.types import ActionSpec, ObservationSpec, StatsAggregationMethod

Stat = tuple[str, float, StatsAggregationMethod]


def tiled_areas(xml_path, num_areas: int, spacing: float):
    """One MjModel with ``num_areas`` copies of a planar area's MJCF (names prefixed ``area<k>/``),
    the k-th area's origin at (0, spacing * k, 0); 0.02 s steps, no gravity (pushblock, dungeon)."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.option.timestep = 0.02
    spec.option.gravity = [0.0, 0.0, 0.0]
    for k in range(num_areas):
        frame = spec.worldbody.add_frame(pos=[0.0, spacing * k, 0.0])
        spec.attach(mujoco.MjSpec.from_file(str(xml_path)), prefix=f"area{k}/", frame=frame)
    return spec.compile()


@dataclass
class TaskStep:
    """The outcome of one control step for all n agents.

    rewards: float32 [n] reward earned in this step; done: bool [n] episode ended;
    interrupted: bool [n] ended by max_step (only meaningful where done); stats: custom stats;
    group_rewards: float32 [n] each agent's group's reward in this step (Unity's
    SimpleMultiAgentGroup.AddGroupReward), or None for tasks without groups.
    """

    rewards: np.ndarray
    done: np.ndarray
    interrupted: np.ndarray
    stats: list[Stat] = field(default_factory=list)
    group_rewards: np.ndarray | None = None


class EnvironmentParameters:
    """Unity's ``Academy.Instance.EnvironmentParameters``: each read draws a fresh value.

    ``samplers`` maps a key to a zero-argument callable (``EnvParameter.sampler()``); keys
    the trainer never sent fall back to the default given at the read, as in Unity.
    """

    def __init__(self) -> None:
        self.samplers: dict[str, Callable[[], float]] = {}

    def set(self, key: str, sampler: Callable[[], float]) -> None:
        self.samplers[key] = sampler

    def get(self, key: str, default: float) -> float:
        sampler = self.samplers.get(key)
        return float(sampler()) if sampler is not None else float(default)

    def get_many(self, key: str, default: float, count: int) -> np.ndarray:
        """float64 [count]: one read per agent (samplers draw a fresh value for each)."""
        sampler = self.samplers.get(key)
        if sampler is None:
            return np.full(count, float(default))
        return np.array([sampler() for _ in range(count)], dtype=np.float64)


class Task:
    """Base class with the attributes the academy and the CLI read."""

    name: str = ""
    behavior_name: str = ""
    team_id: int = 0  # the behavior is sent as behavior_name?team=team_id
    observation_specs: tuple[ObservationSpec, ...] = ()
    # per observation "none" or "png" (a camera sent PNG-compressed); None: all uncompressed
    observation_compressions: tuple[str, ...] | None = None
    action_spec: ActionSpec = ActionSpec(0, ())
    agents_per_area: int = 1
    # True: the agents of an area play together (teams, groups), so an area's agent count is fixed;
    # False: they are independent copies, and ``make_task(agents_per_area=...)`` may change it
    agents_interact: bool = False
    max_step: int = 0
    decision_period: int = 1
    # True: the per-decision reward is the LAST step's reward (Unity's SetReward every step);
    # False: rewards of the steps between decisions are summed (AddReward).
    sets_reward: bool = False
    description: str = ""

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        if num_areas < 1:
            raise ValueError(f"num_areas must be >= 1, got {num_areas}")
        self.num_areas = int(num_areas)
        self.num_agents = self.num_areas * self.agents_per_area
        self.seed = int(seed)
        self.env_params = env_params if env_params is not None else EnvironmentParameters()

    # The interface every task implements --------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        raise NotImplementedError

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        raise NotImplementedError

    def observe(self) -> list[np.ndarray]:
        raise NotImplementedError

    def action_mask(self) -> np.ndarray | None:
        return None

    def group_ids(self) -> np.ndarray | None:
        return None

    def behaviors(self) -> list[tuple[str, slice | np.ndarray]]:
        """(behavior key as sent, the rows of its agents): one behavior with every agent, unless
        the task has several sharing one physics (e.g. ``soccer``: one behavior per team)."""
        return [(f"{self.behavior_name}?team={self.team_id}", slice(None))]

    # Helpers -------------------------------------------------------------------------------
    def all_agents(self, mask: np.ndarray | None) -> np.ndarray:
        """bool [n]: the given mask, or every agent when None."""
        if mask is None:
            return np.ones(self.num_agents, dtype=bool)
        return np.asarray(mask, dtype=bool)

    @classmethod
    def describe(cls) -> str:
        """One human-readable line per spec, for ``unity-stub-env --list``."""
        obs = ", ".join(f"{spec.name or 'obs'} {list(spec.shape)}" for spec in cls.observation_specs)
        act = cls.action_spec
        return (
            f"{cls.name}: behavior '{cls.behavior_name}', {cls.agents_per_area} agent(s) per area, "
            f"observations [{obs}], actions continuous={act.continuous_size} "
            f"discrete_branches={list(act.discrete_branches)}, decision_period={cls.decision_period}, "
            f"max_step={cls.max_step}. {cls.description}"
        )
