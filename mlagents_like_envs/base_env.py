"""The environment-facing types of mlagents_envs.base_env: specs, steps, actions and ``BaseEnv``.

The data types are the project's one data model (``protos.types``), which already has
mlagents_envs' names and behaviour; this module adds the abstract environment and the aliases, so
``from mlagents_like_envs.base_env import ...`` finds everything ``mlagents_envs.base_env`` had.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping

from protos.types import (
    ActionSpec,
    ActionTuple,
    BehaviorSpec,
    DecisionStep,
    DecisionSteps,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
    TerminalStep,
    TerminalSteps,
)

AgentId = int
GroupId = int
BehaviorName = str


class BehaviorMapping(Mapping):
    """A read-only view of behavior name → BehaviorSpec (what ``behavior_specs`` returns)."""

    def __init__(self, specs: dict[BehaviorName, BehaviorSpec]) -> None:
        self._dict = specs

    def __len__(self) -> int:
        return len(self._dict)

    def __getitem__(self, behavior: BehaviorName) -> BehaviorSpec:
        return self._dict[behavior]

    def __iter__(self) -> Iterator[BehaviorName]:
        yield from self._dict


class BaseEnv(ABC):
    """A simulation of agents grouped by behavior name, stepped until some agent needs a decision.

    After ``reset()`` or ``step()``, ``get_steps(name)`` holds the agents of that behavior that
    need an action (DecisionSteps) and those whose episode ended since the last step
    (TerminalSteps). Actions set with ``set_actions`` / ``set_action_for_agent`` are sent by the
    next ``step()``; agents without one get all-zero actions.
    """

    @abstractmethod
    def step(self) -> None:
        """Send the actions set so far and advance until some agent needs a decision."""

    @abstractmethod
    def reset(self) -> None:
        """Reset the simulation; ``get_steps`` then holds the first decisions."""

    @abstractmethod
    def close(self) -> None:
        """End the simulation and release what it holds (process, port)."""

    @property
    @abstractmethod
    def behavior_specs(self) -> Mapping[BehaviorName, BehaviorSpec]:
        """Behavior name → BehaviorSpec of every behavior seen so far (new ones may appear)."""

    @abstractmethod
    def set_actions(self, behavior_name: BehaviorName, action: ActionTuple) -> None:
        """Actions for every deciding agent of ``behavior_name``, rows in DecisionSteps order:
        continuous [n_agents, continuous_size], discrete [n_agents, discrete_size]."""

    @abstractmethod
    def set_action_for_agent(self, behavior_name: BehaviorName, agent_id: AgentId, action: ActionTuple) -> None:
        """The action of one deciding agent: arrays of one row."""

    @abstractmethod
    def get_steps(self, behavior_name: BehaviorName) -> tuple[DecisionSteps, TerminalSteps]:
        """(DecisionSteps, TerminalSteps) of ``behavior_name`` from the last reset or step."""


__all__ = [
    "ActionSpec", "ActionTuple", "AgentId", "BaseEnv", "BehaviorMapping", "BehaviorName", "BehaviorSpec",
    "DecisionStep", "DecisionSteps", "DimensionProperty", "GroupId", "ObservationSpec", "ObservationType",
    "TerminalStep", "TerminalSteps",
]
