"""A behavior's first decisions, made before torch is imported.

Importing torch takes longer than the stub (or a small Unity build) takes to boot and connect
(docs/performance.md, "Start-up and exit"). So a new behavior's first actions are decided by a
``StartingBehavior``: the actor initial_parameters.py draws from the behavior's seed, run by
numpy_net and sampled by numpy_policy with the policy's own noise generator. No torch is needed
until the first trajectory is complete; then the run (trainer/run.py) waits for torch, builds the
behavior's real runner, and its policy takes over this actor's arrays and noise generator
(``Policy.take_over``). Nothing was learned in between (no trajectory was processed, no
normaliser updated), so the run is the same, bit for bit, whenever torch finished importing.

Only where nothing else would differ: one rank, the CPU, a fresh start (no --resume, inference,
init_path), no self-play, vector observations. Otherwise the behavior's runner is created at once,
as before, and waits for torch.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from protos.types import BehaviorSpec
from trainer.common.initial_parameters import actor_parameters
from trainer.common.numpy_net import NumpyActor
from trainer.common.numpy_policy import NumpyPolicy, noise_generator
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.sac.hyperparams import SACHyperparams


@dataclass
class _Sizes:
    """What the experience trackers read of a runner's trainer before there is one (trainer/run.py)."""

    uses_groups: bool  # POCA: GroupTracker
    policy: NumpyPolicy
    step: int = 0


@dataclass
class StartingBehavior:
    """Stands in for a BehaviorRunner (trainer/behavior.py) until torch is loaded: it decides and
    collects, nothing else. ``behavior_name`` and ``agents`` are what ``RunState.ensure_runner``
    creates the real runner from."""

    behavior_name: str
    agents: int | None
    brain: str
    spec: BehaviorSpec
    settings: object  # TrainerSettings
    seed: int
    policy: NumpyPolicy
    trainer: _Sizes = field(init=False)
    self_play = None

    def __post_init__(self) -> None:
        self.trainer = _Sizes(self.settings.trainer_type == "poca", self.policy)
        self.episode_returns: list[float] = []

    @classmethod
    def create(cls, behavior_name: str, agents: int | None, brain: str, spec: BehaviorSpec, settings,
               seed: int) -> "StartingBehavior | None":
        """The behavior's first-steps policy, or None if it must wait for torch (visual
        observations, or a configuration the caller ruled out)."""
        if settings.self_play is not None or settings.init_path:
            return None
        squashed = settings.trainer_type == "sac"
        hyperparams = (SACHyperparams if squashed else PPOHyperparams).from_settings(settings)
        action_spec = spec.action_spec
        params = actor_parameters([tuple(o.shape) for o in spec.observation_specs], action_spec.continuous_size,
                                  action_spec.discrete_branches, hyperparams, squashed, seed)
        if params is None:
            return None
        actor = NumpyActor.from_parameters(params, len(spec.observation_specs), action_spec.discrete_branches)
        policy = NumpyPolicy(actor, noise_generator(seed), squashed, hyperparams.deterministic)
        return cls(behavior_name, agents, brain, spec, settings, seed, policy)

    def policy_for(self, team: int) -> NumpyPolicy:
        return self.policy

    def learns_from(self, team: int) -> bool:
        return True

    def add_episodes(self, returns: list[float]) -> None:
        """Episode returns, handed to the real runner (its reward buffer) when it is created."""
        self.episode_returns.extend(returns)
