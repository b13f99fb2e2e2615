"""The numpy SAC gradient step (trainer/sac/numpy_step.py) against autograd on the same torch
modules (every parameter's gradient of one step), and against the torch path after several
updates (losses, weights, Adam moments, entropy coefficients), for continuous, discrete with
action masks and hybrid actions, with one and with two reward signals (RND ignores done)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.common.hyperparams import SignalNetwork
from trainer.sac import numpy_step
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.trainer import SACTrainer, copy_normalization

from tests.unit.test_ppo_numpy_update import assert_numpy_actor_sees, feed as feed_trajectories

CASES = [
    (ActionSpec(2, ()), False, ()),
    (ActionSpec(0, (3, 2)), True, ()),
    (ActionSpec(2, (4,)), True, ()),
    (ActionSpec(1, (3,)), False, ("rnd",)),
]
IDS = ["continuous", "discrete-masked", "hybrid-masked", "hybrid-rnd"]


def vec(n: int, name: str) -> ObservationSpec:
    return ObservationSpec((n,), (DimensionProperty.NONE,), ObservationType.DEFAULT, name)


def make(action_spec: ActionSpec, signals: tuple[str, ...], numpy: bool) -> SACTrainer:
    reward_signals = {"extrinsic": (0.99, 0.5), **{name: (0.9, 0.3) for name in signals}}
    hp = SACHyperparams(batch_size=32, buffer_size=400, hidden_units=16, num_layers=2, normalize=True,
                        learning_rate=3e-3, init_entcoef=0.3, tau=0.05, steps_per_update=4.0,
                        reward_signals=reward_signals,
                        reward_signal_networks={name: SignalNetwork(hidden_units=8) for name in signals})
    # use_numpy_update: MLAGENTS_LIKE_NUMPY_UPDATE, the one switch of PPO's and SAC's numpy paths
    trainer = SACTrainer("B", BehaviorSpec((vec(5, "a"), vec(3, "b")), action_spec), hp, seed=3,
                         use_numpy_update=numpy)
    assert numpy_step.supports(trainer) and (trainer._numpy_step is not None) == numpy
    return trainer


def feed(trainers: list[SACTrainer], masked: bool, lengths=(40, 50, 30)) -> None:
    """The same trajectories (acted by the first trainer) into every trainer; every other one ends its episode."""
    feed_trajectories(trainers, masked, lengths, done=lambda k, _: k % 2 == 0, episodes=True)


@pytest.mark.parametrize("action_spec,masked,signals", CASES, ids=IDS)
def test_numpy_gradients_equal_autograd_on_the_same_modules(action_spec, masked, signals):
    fast, slow = make(action_spec, signals, True), make(action_spec, signals, False)
    feed([fast, slow], masked)
    with torch.no_grad():  # move Q1 away from V's scale and the alphas off their start: every term counts
        generator = torch.Generator().manual_seed(1)
        for a, b in zip(fast.q_network.parameters(), slow.q_network.parameters()):
            a.add_(0.2 * torch.randn(a.shape, generator=generator))
            b.copy_(a)
        for a, b in zip(fast.log_ent_coef.parameters(), slow.log_ent_coef.parameters()):
            a.add_(torch.linspace(-0.3, 0.4, a.numel()))
            b.copy_(a)
    batch = fast.buffer.sample(32, torch.Generator().manual_seed(2))
    batch["done"][::5] = 1.0
    for trainer in (fast, slow):
        for network in (trainer.critic, trainer.target_network, trainer.q_network.q1_network,
                        trainer.q_network.q2_network):
            copy_normalization(trainer.policy.actor.network_body, network.network_body)
    grads, stats = fast._numpy_step.gradients(batch, fast._rewards(batch))
    optimizers = (slow.policy_optimizer, slow.value_optimizer, slow.entropy_optimizer)
    for optimizer in optimizers:
        optimizer.step = lambda: None  # keep autograd's gradients in .grad
    slow_stats = slow.gradient_step(batch)
    for key, value in stats.items():
        assert value == pytest.approx(slow_stats[key], rel=1e-5, abs=1e-7), key
    params = [p for optimizer in optimizers for p in optimizer.params]
    names = {id(p): name for module in (slow.policy.actor, slow.critic, slow.q_network, slow.log_ent_coef)
             for name, p in module.named_parameters()}
    fast_params = [p for optimizer in (fast.policy_optimizer, fast.value_optimizer, fast.entropy_optimizer)
                   for p in optimizer.params]
    assert set(grads) == {id(p) for p in fast_params}
    for p_fast, p_slow in zip(fast_params, params):
        expected = p_slow.grad.numpy()
        scale = float(np.abs(expected).max())
        assert scale > 0, names[id(p_slow)]
        np.testing.assert_allclose(grads[id(p_fast)], expected, rtol=1e-4, atol=1e-5 * scale,
                                   err_msg=names[id(p_slow)])


@pytest.mark.parametrize("action_spec,masked,signals", CASES, ids=IDS)
def test_numpy_steps_match_the_torch_path(action_spec, masked, signals):
    fast, slow = make(action_spec, signals, True), make(action_spec, signals, False)
    feed([fast, slow], masked)  # 120 agent steps, steps_per_update 4: 29 gradient steps
    fast_stats, slow_stats = fast.update(), slow.update()
    assert fast.update_steps == slow.update_steps == 30
    assert fast.value_optimizer.step_count == slow.value_optimizer.step_count == 29
    for key, value in slow_stats.items():
        assert fast_stats[key] == pytest.approx(value, rel=2e-4, abs=1e-6), key
    pairs = [(fast.policy.actor, slow.policy.actor), (fast.critic, slow.critic),
             (fast.target_network, slow.target_network), (fast.q_network, slow.q_network),
             (fast.log_ent_coef, slow.log_ent_coef)]
    for a, b in pairs:
        for (key, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items()):
            np.testing.assert_allclose(x.numpy(), y.numpy(), rtol=2e-4, atol=2e-5, err_msg=key)
    for x, y in zip((fast.policy_optimizer, fast.value_optimizer, fast.entropy_optimizer),
                    (slow.policy_optimizer, slow.value_optimizer, slow.entropy_optimizer)):
        np.testing.assert_allclose(x.exp_avg, y.exp_avg, rtol=1e-3, atol=1e-7)
    # the weights moved from their start, and the numpy actor that decides sees them
    start = make(action_spec, signals, True)
    assert any(not torch.equal(a, b) for a, b in zip(fast.policy.actor.parameters(), start.policy.actor.parameters()))
    assert any(not torch.equal(a, b) for a, b in zip(fast.log_ent_coef.parameters(), start.log_ent_coef.parameters()))
    assert_numpy_actor_sees(fast.policy.actor, fast.policy.numpy_actor)


def test_memory_keeps_the_torch_path():
    hp = SACHyperparams(hidden_units=8, memory_size=4, sequence_length=2)
    trainer = SACTrainer("M", BehaviorSpec((vec(3, "a"),), ActionSpec(1, ())), hp, seed=0)
    assert not numpy_step.supports(trainer) and trainer._numpy_step is None


@pytest.mark.parametrize("numpy", [True, False], ids=["numpy", "torch"])
def test_policy_entropy_is_reported_from_each_gradient_step(numpy):
    """Policy/Entropy (the reference writes it for every trainer): with the heads' weights zeroed,
    the policy is known by hand. Hybrid (2 continuous, branches 4 and 2): log sigma = -0.5 in
    both dimensions gives the Gaussian's 0.5 log(2 pi e) - 0.5 = 0.9189; the uniform branches
    log 4 + log 2 = 2.0794 (masked rows: log 3 + log 2 = 1.7918, every other row)."""
    trainer = make(ActionSpec(2, (4, 2)), (), numpy)
    feed([trainer], masked=True)
    actor = trainer.policy.actor
    with torch.no_grad():
        for head in (actor.log_sigma_head, *actor.discrete_branches):
            head.weight.zero_()
            head.bias.zero_()
        actor.log_sigma_head.bias.fill_(-0.5)
    batch = trainer.buffer.sample(32, torch.Generator().manual_seed(2))
    masked_rows = batch["action_masks"][:, 1].mean()
    gaussian = 0.5 * np.log(2 * np.pi * np.e) - 0.5
    expected = gaussian + masked_rows * np.log(3 * 2) + (1 - masked_rows) * np.log(4 * 2)
    assert 0 < masked_rows < 1
    assert trainer.gradient_step(batch)["Policy/Entropy"] == pytest.approx(expected, rel=1e-5)
