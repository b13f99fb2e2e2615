"""Actor/critic construction: ML-Agents initialisation, visual encoders and clear errors."""
from __future__ import annotations

import math

import pytest
import torch

from protos.types import ActionSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.errors import ConfigError
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.networks import Actor, Critic


def vector_spec(size: int) -> ObservationSpec:
    return ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector")


def visual_spec(shape: tuple[int, int, int]) -> ObservationSpec:
    props = (DimensionProperty.NONE, DimensionProperty.TRANSLATIONAL_EQUIVARIANCE,
             DimensionProperty.TRANSLATIONAL_EQUIVARIANCE)
    return ObservationSpec(shape, props, ObservationType.DEFAULT, "camera")


def test_initialisation_matches_ml_agents_scheme():
    torch.manual_seed(0)
    hyper = PPOHyperparams(hidden_units=512, num_layers=2)
    actor = Actor([vector_spec(400)], ActionSpec(64, (300,)), hyper)
    first, second = actor.network_body.hidden[0], actor.network_body.hidden[2]
    # Kaiming normal with nonlinearity "linear": std = gain / sqrt(fan_in)
    assert first.weight.std().item() == pytest.approx(1 / math.sqrt(400), rel=0.03)
    assert second.weight.std().item() == pytest.approx(1 / math.sqrt(512), rel=0.03)
    assert actor.mu.weight.std().item() == pytest.approx(0.2 / math.sqrt(512), rel=0.03)
    assert actor.discrete_branches[0].weight.std().item() == pytest.approx(0.1 / math.sqrt(512), rel=0.03)
    for layer in (first, second, actor.mu, actor.discrete_branches[0]):
        assert torch.count_nonzero(layer.bias) == 0
    assert torch.equal(actor.log_sigma, torch.zeros(1, 64))

    critic = Critic([vector_spec(400)], ["extrinsic", "curiosity"], hyper)
    head = critic.value_heads["extrinsic"].weight
    bound = math.sqrt(6 / (512 + 1))  # Xavier uniform
    assert head.abs().max().item() <= bound
    assert head.std().item() == pytest.approx(bound / math.sqrt(3), rel=0.1)
    assert set(critic.value_heads) == {"extrinsic", "curiosity"}


def test_body_is_swish_stack_and_constants_are_in_state_dict():
    actor = Actor([vector_spec(3)], ActionSpec(2, (3, 2)), PPOHyperparams(hidden_units=8, num_layers=3))
    layer_types = [type(m).__name__ for m in actor.network_body.hidden]
    assert layer_types == ["Linear", "Swish"] * 3
    state = actor.state_dict()
    assert state["version_number"].tolist() == [3.0]
    assert state["memory_size_vector"].tolist() == [0.0]
    assert state["continuous_act_size_vector"].tolist() == [2.0]
    assert state["discrete_act_size_vector"].tolist() == [[3.0, 2.0]]
    assert not actor.version_number.requires_grad


def test_actor_and_critic_keep_separate_normalisers():
    hyper = PPOHyperparams(normalize=True, hidden_units=8, num_layers=1)
    actor = Actor([vector_spec(2)], ActionSpec(1, ()), hyper)
    critic = Critic([vector_spec(2)], ["extrinsic"], hyper)
    actor.update_normalization([torch.ones(4, 2)])
    assert int(actor.network_body.observation_encoder.encoders[0].normalizer.normalization_steps) == 5
    assert int(critic.network_body.observation_encoder.encoders[0].normalizer.normalization_steps) == 1


@pytest.mark.parametrize("encoder, shape", [
    ("simple", (3, 36, 36)), ("nature_cnn", (3, 36, 36)), ("fully_connected", (1, 4, 4)),
    ("resnet", (3, 20, 20)), ("match3", (2, 5, 5)),
])
def test_visual_encoders_give_hidden_units(encoder, shape):
    hyper = PPOHyperparams(hidden_units=16, num_layers=1, vis_encode_type=encoder)
    critic = Critic([visual_spec(shape), vector_spec(3)], ["extrinsic"], hyper)
    values = critic([torch.rand(5, *shape), torch.zeros(5, 3)])
    assert values["extrinsic"].shape == (5,)
    assert critic.network_body.observation_encoder.output_size == 16 + 3


def test_unknown_or_too_small_visual_encoder_is_a_config_error():
    with pytest.raises(ConfigError, match="vis_encode_type 'vit'"):
        Critic([visual_spec((3, 36, 36))], ["extrinsic"], PPOHyperparams(vis_encode_type="vit"))
    with pytest.raises(ConfigError, match="needs height and width >= 36"):
        Critic([visual_spec((3, 30, 30))], ["extrinsic"], PPOHyperparams(vis_encode_type="nature_cnn"))


def test_masked_logits_give_zero_probability():
    actor = Actor([vector_spec(2)], ActionSpec(0, (3, 2)), PPOHyperparams(hidden_units=8, num_layers=1))
    allowed = torch.tensor([[1.0, 0.0, 1.0, 0.0, 1.0]])
    _, logits = actor.heads([torch.randn(1, 2)], allowed)
    assert torch.softmax(logits[0], 1)[0, 1].item() == 0.0
    assert torch.softmax(logits[1], 1)[0].tolist() == [0.0, 1.0]
