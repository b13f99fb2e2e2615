"""The one initialisation (trainer/common/initial_parameters.py) and the torch-free first-steps
policy (trainer/first_steps.py): the torch Actor loads exactly the numpy arrays, and the numpy
policy and the torch modules give the same actions and log-probs for the same parameters."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.common.initial_parameters import KAIMING_NORMAL, XAVIER_UNIFORM, kernel
from trainer.common.numpy_policy import noise_generator
from trainer.common.policy import Policy, allowed_from_mask, initial_actor
from trainer.config.settings import MemorySettings, NetworkSettings, PPOSettings, SACSettings, TrainerSettings
from trainer.first_steps import StartingBehavior
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.sac.hyperparams import SACHyperparams
from trainer.common.distributions import squashed_log_prob
from trainer.sac.policy import SACPolicy


def spec(continuous: int, branches: tuple[int, ...], sizes=(4, 3)) -> BehaviorSpec:
    obs = tuple(ObservationSpec((s,), (DimensionProperty.NONE,), ObservationType.DEFAULT, f"o{i}")
                for i, s in enumerate(sizes))
    return BehaviorSpec(obs, ActionSpec(continuous, branches))


def test_kernels_have_the_schemes_moments_and_are_stored_input_major():
    rng = np.random.default_rng(0)
    w = kernel(rng, 300, 400, KAIMING_NORMAL, 0.5)
    assert w.shape == (300, 400) and w.dtype == np.float32 and w.T.flags.c_contiguous
    assert abs(w.std() - 0.5 / np.sqrt(400)) < 0.01 * 0.5 / np.sqrt(400) * 5  # 120k draws: ~0.2 % error
    u = kernel(rng, 300, 400, XAVIER_UNIFORM)
    bound = np.sqrt(6.0 / 700)
    assert np.abs(u).max() <= bound and np.abs(u).max() > 0.99 * bound
    assert abs(u.std() - bound / np.sqrt(3)) < 0.01 * bound


@pytest.mark.parametrize("squashed, normalize, memory", [(False, True, 0), (True, False, 0), (False, False, 8)])
def test_the_torch_actor_loads_exactly_the_numpy_initialisation(squashed, normalize, memory):
    hp = PPOHyperparams(hidden_units=16, num_layers=2, normalize=normalize, memory_size=memory)
    s = spec(2, (3, 2))
    policy = (SACPolicy if squashed else Policy)(s, hp, seed=5)
    initial = initial_actor(s, hp, squashed, 5)
    state = policy.actor.state_dict()
    assert state.keys() == initial.keys()
    for name, value in initial.items():
        np.testing.assert_array_equal(state[name].numpy(), value, err_msg=name)
    assert not np.array_equal(initial_actor(s, hp, squashed, 6)["mu.weight"], initial["mu.weight"])  # seeded


def settings(trainer_type: str, memory: int = 0) -> TrainerSettings:
    network = NetworkSettings(hidden_units=16, num_layers=2, normalize=True,
                              memory=MemorySettings(memory_size=memory, sequence_length=4) if memory else None)
    hyper = SACSettings() if trainer_type == "sac" else PPOSettings()
    return TrainerSettings(trainer_type=trainer_type, hyperparameters=hyper, network_settings=network)


@pytest.mark.parametrize("trainer_type, memory", [("ppo", 0), ("sac", 0), ("poca", 0), ("ppo", 8)])
def test_the_first_steps_policy_acts_as_the_torch_modules_do(trainer_type, memory):
    s = spec(2, (3, 2))
    first = StartingBehavior.create("B?team=0", 4, "B", s, settings(trainer_type, memory), seed=11)
    squashed = trainer_type == "sac"
    policy_class = SACPolicy if squashed else Policy
    hyper = (SACHyperparams if squashed else PPOHyperparams).from_settings(settings(trainer_type, memory))
    torch_policy = policy_class(s, hyper, seed=11)
    rng = np.random.default_rng(1)
    n = 64
    obs = [rng.normal(size=(n, 4)).astype(np.float32), rng.normal(size=(n, 3)).astype(np.float32)]
    mask = rng.random((n, 5)) < 0.3
    mask[:, 0] = mask[:, 3] = False  # one option allowed per branch at least
    memories = rng.normal(size=(n, memory)).astype(np.float32) if memory else None
    out = first.policy.act(obs, mask, memories=memories)
    # the torch modules on the same parameters: log-probs of the numpy samples, and the memories
    allowed = allowed_from_mask(mask)
    tensors = [torch.from_numpy(o) for o in obs]
    with torch.no_grad():
        if memory:
            encoding, after = torch_policy.actor.network_body.forward_memory(
                tensors, torch.from_numpy(memories)[None], 1)
            np.testing.assert_allclose(out.memories, after[0].numpy(), atol=1e-6)
        else:
            encoding = torch_policy.actor.network_body(tensors)
        mu, logits = torch_policy.actor.heads_of(encoding, allowed)
        parts = []
        if squashed:
            # the raw sample before the tanh, from the same noise: the generator's first draws
            noise = torch.from_numpy(noise_generator(11).standard_normal(mu.shape, dtype=np.float32))
            log_sigma = torch_policy.actor.log_sigma_of(encoding, mu)
            raw = mu + noise * torch.exp(log_sigma)
            np.testing.assert_allclose(out.continuous_raw, torch.tanh(raw).numpy(), atol=1e-6)
            parts.append(squashed_log_prob(raw, mu, log_sigma))
        else:
            from trainer.common.distributions import gaussian_log_prob

            parts.append(gaussian_log_prob(torch.from_numpy(out.continuous_raw), mu,
                                           torch_policy.actor.log_sigma.expand_as(mu)))
        for index, branch in enumerate(logits):
            probs = torch.softmax(branch, dim=1)
            chosen = torch.from_numpy(out.discrete[:, index].astype(np.int64))
            assert not mask[np.arange(n), torch_policy.actor.mask_offsets[index] + out.discrete[:, index]].any()
            parts.append(torch.log(probs.gather(1, chosen[:, None]) + 1e-7))
        expected = torch.cat(parts, dim=1).numpy()
    np.testing.assert_allclose(out.log_probs, expected, atol=1e-6, rtol=1e-6)
    # deterministic: the same mean / argmax from numpy and torch
    det = first.policy.act(obs, mask, deterministic=True, memories=memories)
    if squashed:
        np.testing.assert_allclose(det.env_actions.continuous, np.tanh(mu.numpy()), atol=1e-6)
    else:
        np.testing.assert_allclose(det.continuous_raw, mu.numpy(), atol=1e-6)
    np.testing.assert_array_equal(det.discrete, np.stack([b.argmax(1).numpy() for b in logits], axis=1))


def test_take_over_continues_the_same_noise_and_parameters():
    s = spec(2, (3,))
    first = StartingBehavior.create("B?team=0", 4, "B", s, settings("ppo"), seed=2)
    hp = PPOHyperparams.from_settings(settings("ppo"))
    obs = [np.ones((5, 4), np.float32), np.ones((5, 3), np.float32)]
    reference = Policy(s, hp, seed=2)
    outputs = [reference.act(obs) for _ in range(3)]
    first.policy.act(obs)  # one decision before torch, then the torch policy takes over
    later = Policy(s, hp, seed=2)
    later.take_over(first.policy)
    for expected in outputs[1:]:
        got = later.act(obs)
        np.testing.assert_array_equal(got.continuous_raw, expected.continuous_raw)
        np.testing.assert_array_equal(got.discrete, expected.discrete)


def test_nothing_on_the_first_steps_path_imports_torch():
    code = ("import sys; import trainer.run, trainer.first_steps, trainer.common.numpy_policy; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
