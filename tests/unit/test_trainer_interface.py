"""The trainer interface the run loop and BehaviorRunner talk to (trainer/common/trainer_interface.py):
PPO, SAC and POCA implement it, and what only some of them have is an attribute every trainer
answers, not something the loop probes for."""
from __future__ import annotations

import pytest

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.common.reward_providers import RewardProvider
from trainer.common.trainer_interface import Trainer
from trainer.poca.trainer import POCATrainer
from trainer.common.hyperparams import SignalNetwork
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.trainer import SACTrainer

SPEC = BehaviorSpec((ObservationSpec((4,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                    ActionSpec(1, (2,)))
SIGNALS = {"extrinsic": (0.99, 1.0), "rnd": (0.9, 0.1)}
NETWORKS = {"rnd": SignalNetwork(hidden_units=8)}


def make(kind: str, **extra) -> Trainer:
    if kind == "sac":
        return SACTrainer("B", SPEC, SACHyperparams(hidden_units=8, reward_signals=SIGNALS,
                                                    reward_signal_networks=NETWORKS, **extra), seed=0)
    cls = POCATrainer if kind == "poca" else PPOTrainer
    return cls("B", SPEC, PPOHyperparams(hidden_units=8, reward_signals=SIGNALS, reward_signal_networks=NETWORKS),
               seed=0)


@pytest.mark.parametrize("kind, groups", [("ppo", False), ("sac", False), ("poca", True)])
def test_every_trainer_implements_the_interface(kind, groups):
    trainer = make(kind)
    assert isinstance(trainer, Trainer)
    assert trainer.uses_groups is groups  # POCA's trajectories come from rollout.GroupTracker
    assert trainer.behavioral_cloning is None  # every trainer takes a cloning learner
    assert trainer.step == 0 and trainer.policy is not None
    assert list(trainer.providers) == ["rnd"] and isinstance(trainer.providers["rnd"], RewardProvider)
    assert trainer.providers["rnd"].needs_done is False


def test_only_sac_with_save_replay_buffer_saves_one():
    assert make("ppo").saves_replay_buffer is False and make("ppo").replay_buffer_size() == 0
    assert make("sac").saves_replay_buffer is False
    sac = make("sac", save_replay_buffer=True)
    assert sac.saves_replay_buffer is True and sac.replay_buffer_size() == 0
    with pytest.raises(NotImplementedError):
        make("ppo").save_replay_buffer("unused.npz")


def test_a_trainer_that_misses_a_method_cannot_be_built():
    class Half(Trainer):
        def process_trajectory(self, traj):
            return {}

    with pytest.raises(TypeError, match="abstract"):
        Half()
