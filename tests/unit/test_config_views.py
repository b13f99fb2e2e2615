"""The flat views (the shared NetworkHyperparams and SignalNetwork, the algorithms' PPOHyperparams and
SACHyperparams on top of the first) are generated from the settings classes and filled from one
behavior's TrainerSettings with no hand mapper."""
from __future__ import annotations

import dataclasses
import pickle

import pytest

from trainer.config import run_options_from_dict
from trainer.config.settings import NetworkSettings, PPOSettings, SACSettings
from trainer.common.hyperparams import NetworkHyperparams, SignalNetwork
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.sac.hyperparams import SACHyperparams


def behavior(block: dict):
    return run_options_from_dict({"behaviors": {"A": block}}).behaviors["A"]


def test_the_views_defaults_are_the_settings_defaults():
    hp = PPOHyperparams()
    assert (hp.batch_size, hp.buffer_size, hp.learning_rate, hp.beta, hp.epsilon, hp.lambd, hp.num_epoch) == (
        1024, 10240, 3.0e-4, 5.0e-3, 0.2, 0.95, 3)
    assert (hp.shared_critic, hp.max_steps, hp.hidden_units, hp.num_layers, hp.normalize) == (
        False, 500000, 128, 2, False)
    assert (hp.memory_size, hp.sequence_length, hp.reward_signals, hp.reward_signal_networks) == (
        0, 64, {"extrinsic": (0.99, 1.0)}, {})
    sac = SACHyperparams()
    assert (sac.batch_size, sac.buffer_size, sac.learning_rate_schedule, sac.tau) == (128, 50000, "constant", 0.005)
    assert (sac.steps_per_update, sac.reward_signal_steps_per_update, sac.hidden_units) == (1.0, 1.0, 128)
    net = SignalNetwork()
    assert (net.learning_rate, net.hidden_units, net.num_layers, net.use_actions, net.use_vail) == (
        3.0e-4, 128, 2, False, False)


def test_every_settings_field_reaches_the_view():
    for view, cls in ((PPOHyperparams, PPOSettings), (SACHyperparams, SACSettings)):
        fields = {f.name for f in dataclasses.fields(view)}
        assert {f.name for f in dataclasses.fields(cls)} <= fields
        assert {f.name for f in dataclasses.fields(NetworkSettings)} - {"memory"} <= fields


def test_a_ppo_behavior_fills_the_view():
    settings = behavior({
        "trainer_type": "ppo", "max_steps": 2000,
        "hyperparameters": {"batch_size": 32, "buffer_size": 320, "beta": 0.01, "shared_critic": True},
        "network_settings": {"hidden_units": 48, "num_layers": 3, "normalize": True,
                             "memory": {"memory_size": 16, "sequence_length": 8}},
        "reward_signals": {"extrinsic": {"gamma": 0.9, "strength": 2.0},
                           "curiosity": {"strength": 0.1, "learning_rate": 1e-3,
                                         "network_settings": {"hidden_units": 24}},
                           "gail": {"demo_path": "x.demo", "use_actions": True}},
    })
    hp = PPOHyperparams.from_settings(settings)
    assert (hp.batch_size, hp.buffer_size, hp.beta, hp.shared_critic, hp.max_steps) == (32, 320, 0.01, True, 2000)
    assert (hp.hidden_units, hp.num_layers, hp.normalize, hp.memory_size, hp.sequence_length) == (48, 3, True, 16, 8)
    assert hp.reward_signals == {"extrinsic": (0.9, 2.0), "curiosity": (0.99, 0.1), "gail": (0.99, 1.0)}
    assert sorted(hp.reward_signal_networks) == ["curiosity", "gail"]
    curiosity = hp.reward_signal_networks["curiosity"]
    assert (curiosity.learning_rate, curiosity.hidden_units, curiosity.num_layers) == (1e-3, 24, 2)
    gail = hp.reward_signal_networks["gail"]
    assert (gail.learning_rate, gail.use_actions, gail.use_vail, gail.hidden_units) == (3e-4, True, False, 128)


def test_poca_keeps_ppos_shared_critic_default_and_sac_is_refused_by_ppos_view():
    poca = PPOHyperparams.from_settings(behavior({"trainer_type": "poca", "hyperparameters": {"lambd": 0.9}}))
    assert (poca.lambd, poca.shared_critic, poca.batch_size) == (0.9, False, 1024)
    sac_settings = behavior({"trainer_type": "sac", "hyperparameters": {"tau": 0.01, "steps_per_update": 4}})
    with pytest.raises(TypeError, match="tau"):
        PPOHyperparams.from_settings(sac_settings)
    sac = SACHyperparams.from_settings(sac_settings)
    assert (sac.tau, sac.steps_per_update, sac.reward_signal_steps_per_update, sac.batch_size) == (0.01, 4.0, 4.0, 128)


def test_views_are_frozen_dataclasses_that_pickle():
    hp = PPOHyperparams(hidden_units=16)
    with pytest.raises(dataclasses.FrozenInstanceError):
        hp.hidden_units = 8  # type: ignore[misc]
    assert pickle.loads(pickle.dumps(hp)) == hp
    assert dataclasses.replace(hp, batch_size=8).batch_size == 8
    assert PPOHyperparams().reward_signals is not PPOHyperparams().reward_signals  # no shared mutable default


def test_the_algorithm_views_and_the_signal_networks_are_the_shared_network_view():
    for view in (PPOHyperparams, SACHyperparams, SignalNetwork):
        assert issubclass(view, NetworkHyperparams)
    network = {f.name for f in dataclasses.fields(NetworkHyperparams)}
    assert network == {f.name for f in dataclasses.fields(NetworkSettings)} - {"memory"} | {
        "memory_size", "sequence_length"}
    hp = PPOHyperparams.from_settings(behavior({
        "trainer_type": "ppo",
        "network_settings": {"memory": {"memory_size": 16, "sequence_length": 8}},
        "reward_signals": {"extrinsic": {}, "rnd": {"network_settings": {
            "hidden_units": 24, "memory": {"memory_size": 32, "sequence_length": 4}}}},
    }))
    assert (hp.memory_size, hp.sequence_length) == (16, 8)
    rnd = hp.reward_signal_networks["rnd"]  # the reference ignores memory in the signals' encoders
    assert (type(rnd), rnd.hidden_units, rnd.memory_size, rnd.sequence_length) == (SignalNetwork, 24, 0, 64)
