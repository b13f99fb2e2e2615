"""What the run loop (trainer/run.py) and a behavior's runner (trainer/behavior.py) ask of a
trainer, whatever its algorithm: the one interface PPO, SAC and POCA implement.

The loop hands every finished or cut trajectory to ``process_trajectory``, calls ``update`` when
``ready_to_update`` says so, acts with ``policy`` and counts agent steps in ``step``; the runner
saves and restores ``state_dict`` and exports ONNX. What only some algorithms have is stated
here as a class attribute or a method with a default, never probed with hasattr:
``uses_groups`` (POCA: trajectories carry the teammates' columns, rollout.GroupTracker),
``saves_replay_buffer`` (SAC's save_replay_buffer), ``behavioral_cloning`` (set by
behavior.attach_demonstrations, run after each update) and ``providers`` (the intrinsic reward
signals, GAIL's among them).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar

import torch

from trainer.config.support import SUPPORTED_REWARD_SIGNALS
from trainer.errors import ConfigError

if TYPE_CHECKING:
    from protos.types import BehaviorSpec
    from trainer.behavioral_cloning import BehavioralCloning
    from trainer.common.policy import Policy
    from trainer.common.reward_providers import RewardProvider
    from trainer.common.trajectory import Trajectory


class Trainer(ABC):
    """One behavior's learner. ``Trainer.__init__`` checks the reward signals and sets
    ``brain_name``, ``behavior_spec``, ``hyperparams`` and ``device``; subclasses set the rest."""

    uses_groups: ClassVar[bool] = False  # True: the loop assembles trajectories with GroupTracker

    brain_name: str
    behavior_spec: BehaviorSpec
    policy: Policy  # acts for every deciding agent of the behavior
    step: int  # agent steps trained on (the max_steps, summary and checkpoint clock)
    providers: dict[str, RewardProvider]  # intrinsic reward signals by name (curiosity, rnd, gail)
    behavioral_cloning: BehavioralCloning | None  # behavioral_cloning: one round after each update
    hyperparams: Any  # the algorithm's view of the behavior's settings (trainer/config/views.py)
    device: torch.device

    def __init__(self, brain_name: str, behavior_spec: BehaviorSpec, hyperparams: Any, device: str = "cpu") -> None:
        """What every trainer starts with: its reward signals checked (a ConfigError naming the
        behavior), then ``brain_name``, ``behavior_spec``, ``hyperparams`` and ``device`` set."""
        for name in hyperparams.reward_signals:
            if name not in SUPPORTED_REWARD_SIGNALS:
                raise ConfigError(f"reward_signals.{name} is not supported yet for behavior "
                                  f"{brain_name!r}; use only {list(SUPPORTED_REWARD_SIGNALS)}")
        if not hyperparams.reward_signals:
            raise ConfigError(f"behavior {brain_name!r} has no reward_signals; add an extrinsic block")
        self.brain_name = brain_name
        self.behavior_spec = behavior_spec
        self.hyperparams = hyperparams
        self.device = torch.device(device)

    # ------------------------------------------------------------------ experience
    @abstractmethod
    def process_trajectory(self, traj: Trajectory) -> dict[str, float]:
        """Take one agent's trajectory into the buffer; the statistics it produced."""

    @abstractmethod
    def forget_episodes(self) -> None:
        """After a reset or a simulator restart: drop what was kept for unfinished episodes."""

    # ------------------------------------------------------------------ update
    @abstractmethod
    def ready_to_update(self) -> bool:
        """Whether enough experience is buffered for ``update``."""

    @abstractmethod
    def update(self, rows: int | None = None) -> dict[str, float]:
        """Learn from the buffer (``rows``: the data-parallel ranks' agreed length); statistics."""

    # ------------------------------------------------------------------ persistence
    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """checkpoint.pt's content (ML-Agents' keys)."""

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore from a ``state_dict`` (--resume, --initialize-from)."""

    @abstractmethod
    def restart_counters(self) -> None:
        """--initialize-from: the weights stay, the step count starts over."""

    @abstractmethod
    def export_onnx(self, path: str) -> None:
        """The policy as an ONNX model that Unity's inference engine runs."""

    @property
    def saves_replay_buffer(self) -> bool:
        """Whether a checkpoint also writes the replay buffer (SAC's save_replay_buffer)."""
        return False

    def save_replay_buffer(self, path: str) -> None:
        raise NotImplementedError(f"{type(self).__name__} keeps no replay buffer")

    def load_replay_buffer(self, path: str) -> None:
        raise NotImplementedError(f"{type(self).__name__} keeps no replay buffer")

    def replay_buffer_size(self) -> int:
        """Experiences in the replay buffer (0 without one)."""
        return 0
