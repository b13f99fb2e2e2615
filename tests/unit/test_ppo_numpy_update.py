"""The numpy minibatch steps (hand-written gradients + Adam) against autograd on the same torch
modules, and against the torch path (autograd + the same Adam) from identical trainers fed
identical trajectories; the critic's half in a child process, its timeout and fallback."""
from __future__ import annotations

import logging
import os
import sys
import time

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.ppo import numpy_update
from trainer.common.adam import Adam
from trainer.common.trajectory import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer, normalize_advantages


def vec(n: int, name: str = "v") -> ObservationSpec:
    return ObservationSpec((n,), (DimensionProperty.NONE,), ObservationType.DEFAULT, name)


def feed(trainers: list, masked: bool, lengths: tuple[int, ...], done, episodes: bool = False) -> None:
    """The same random trajectories (acted by the first trainer) into every trainer (PPO's or
    SAC's): observations N(1, 2^2), rewards N(0, 1), with ``masked`` option 1 of branch 0
    forbidden on every other step; trajectory k of ``length`` steps ends its episode if
    ``done(k, length)``, and with ``episodes`` it is episode k."""
    rng = np.random.default_rng(11)
    spec = trainers[0].behavior_spec
    branches = spec.action_spec.discrete_branches
    for k, length in enumerate(lengths):
        obs = [(rng.standard_normal((length, o.shape[0])) * 2 + 1).astype(np.float32) for o in spec.observation_specs]
        mask = None
        if branches:
            mask = np.zeros((length, sum(branches)), dtype=bool)
            if masked:
                mask[::2, 1] = True
        out = trainers[0].policy.act(obs, mask)
        rewards = rng.standard_normal(length).astype(np.float32)
        for trainer in trainers:
            trainer.process_trajectory(Trajectory(obs, [o[-1] + 0.5 for o in obs], rewards, out.continuous_raw,
                                                  out.discrete, out.log_probs, mask, done(k, length), False,
                                                  episode=k if episodes else None))


def trained_pair(spec: BehaviorSpec, num_epoch: int, masked: bool):
    hp = PPOHyperparams(batch_size=32, buffer_size=200, num_epoch=num_epoch, normalize=True,
                        hidden_units=24, num_layers=2, beta=5e-3, learning_rate=3e-3,
                        reward_signals={"extrinsic": (0.99, 0.5)})
    trainers = [PPOTrainer("B", spec, hp, seed=5), PPOTrainer("B", spec, hp, seed=5)]
    trainers[0].numpy_update, trainers[1].numpy_update = True, False
    feed(trainers, masked, (70, 90, 60), done=lambda k, length: length == 90)  # 220 experiences > buffer_size
    assert numpy_update.supports(trainers[0])
    stats = [trainer.update() for trainer in trainers]
    return trainers, stats


@pytest.mark.parametrize("action_spec,masked", [
    (ActionSpec(2, ()), False),
    (ActionSpec(0, (3, 2)), True),
    (ActionSpec(2, (4,)), True),
])
def test_numpy_gradients_equal_autograd_on_the_same_modules(action_spec, masked):
    """The hand-written backward against autograd through networks.py's modules, for every
    parameter, on a minibatch where the policy has moved (some ratios clipped, some not)."""
    spec = BehaviorSpec((vec(5), vec(3, "w")), action_spec)
    trainer = _filled_trainer(spec, masked)
    with torch.no_grad():  # move the actor away from the one that acted: ratios != 1
        generator = torch.Generator().manual_seed(1)
        for p in trainer.policy.actor.parameters():
            if p.requires_grad:
                p.add_(0.3 * torch.randn(p.shape, generator=generator))
    beta, epsilon = 0.05, 0.2
    data = trainer.buffer.concatenated()
    data["advantages"] = normalize_advantages(data["advantages"])
    masks = data.pop("action_masks")
    if action_spec.discrete_branches:
        data["allowed"] = (~masks).astype(np.float32)
    obs = [data.pop(f"obs_{i}") for i in range(2)]
    stepper = numpy_update.NumpyPPO(trainer.policy.numpy_actor, trainer._numpy_critic, trainer.optimizer)
    actor_in, critic_in = stepper.prepare(obs)
    index = np.arange(3, 67)
    batch = {k: v[index] for k, v in data.items()}
    actor_grads, policy_term, entropy = stepper.actor_gradients(batch, actor_in[index], beta, epsilon)
    critic_grads, value_term = stepper.critic_gradients(batch, critic_in[index])

    tensors = trainer._buffer_tensors()
    loss, stats = trainer._minibatch_loss({k: v[torch.from_numpy(index)] for k, v in tensors.items()}, beta, epsilon)
    trainer.optimizer.zero_grad()
    loss.backward()
    assert stats["Losses/Policy Loss"] == pytest.approx(abs(policy_term), rel=1e-5)
    assert stats["Losses/Value Loss"] == pytest.approx(value_term, rel=1e-5)
    assert stats["Policy/Entropy"] == pytest.approx(entropy, rel=1e-5)
    grads = {**actor_grads, **critic_grads}
    assert set(grads) == {id(p) for p in trainer.optimizer.params}
    for p in trainer.optimizer.params:
        scale = float(p.grad.abs().max())
        assert scale > 0
        np.testing.assert_allclose(grads[id(p)], p.grad.numpy(), rtol=1e-4, atol=1e-5 * scale)
    # the case is not trivial: some ratios are clipped
    with torch.no_grad():
        log_probs, _ = trainer.policy.evaluate(
            [torch.from_numpy(o[index]) for o in obs],
            torch.from_numpy(data["allowed"][index]) if "allowed" in data else None,
            torch.from_numpy(batch["continuous_actions"]), torch.from_numpy(batch["discrete_actions"]))
    ratio = torch.exp(log_probs - torch.from_numpy(batch["log_probs"]))
    assert 0 < int(((ratio - 1).abs() > epsilon).sum()) < ratio.numel()


@pytest.mark.parametrize("action_spec,masked", [
    (ActionSpec(2, ()), False),
    (ActionSpec(0, (3, 2)), True),
    (ActionSpec(2, (4,)), True),
])
def test_numpy_steps_match_autograd_and_adam(action_spec, masked):
    spec = BehaviorSpec((vec(5), vec(3, "w")), action_spec)
    (fast, slow), (fast_stats, slow_stats) = trained_pair(spec, num_epoch=3, masked=masked)
    assert fast.optimizer.step_count == slow.optimizer.step_count == 3 * (220 // 32)
    for name in ("Losses/Policy Loss", "Losses/Value Loss", "Policy/Entropy"):
        assert fast_stats[name] == pytest.approx(slow_stats[name], rel=1e-4, abs=1e-6), name
    for module in ("actor", "critic"):
        a = getattr(fast.policy, "actor") if module == "actor" else fast.critic
        b = getattr(slow.policy, "actor") if module == "actor" else slow.critic
        for (key, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items()):
            np.testing.assert_allclose(x.numpy(), y.numpy(), rtol=1e-4, atol=2e-5, err_msg=f"{module}.{key}")
    np.testing.assert_allclose(fast.optimizer.exp_avg_sq, slow.optimizer.exp_avg_sq, rtol=1e-3, atol=1e-9)
    # the weights moved, and the numpy actor used for deciding sees the new ones
    assert_numpy_actor_sees(fast.policy.actor, fast.policy._numpy_actor)


def assert_numpy_actor_sees(actor: torch.nn.Module, numpy_actor) -> None:
    """The numpy actor that decides gives the torch actor's heads (obs 5 + 3 wide, 4 rows): it reads
    the weights an update changed in place (PPO's and SAC's numpy steps)."""
    obs = [np.ones((4, 5), np.float32), np.zeros((4, 3), np.float32)]
    with torch.no_grad():
        mu, logits = actor.heads([torch.from_numpy(o) for o in obs], None)
    fast_mu, fast_logits, _ = numpy_actor.heads(obs, None)
    if mu is not None:
        np.testing.assert_allclose(fast_mu, mu.numpy(), rtol=1e-5, atol=1e-6)
    for x, y in zip(fast_logits, logits):
        np.testing.assert_allclose(x, y.numpy(), rtol=1e-5, atol=1e-5)


def test_visual_observations_keep_the_autograd_path():
    visual = ObservationSpec((3, 36, 36), (DimensionProperty.NONE, DimensionProperty.TRANSLATIONAL_EQUIVARIANCE,
                                           DimensionProperty.TRANSLATIONAL_EQUIVARIANCE), ObservationType.DEFAULT, "cam")
    trainer = PPOTrainer("V", BehaviorSpec((visual,), ActionSpec(1, ())), PPOHyperparams(hidden_units=8), seed=0)
    assert not numpy_update.supports(trainer)


def _filled_trainer(spec: BehaviorSpec, masked: bool) -> PPOTrainer:
    hp = PPOHyperparams(batch_size=32, buffer_size=200, num_epoch=2, normalize=True, hidden_units=24,
                        num_layers=2, beta=5e-3, learning_rate=3e-3, reward_signals={"extrinsic": (0.99, 0.5)})
    trainer = PPOTrainer("B", spec, hp, seed=7)
    rng = np.random.default_rng(3)
    branches = spec.action_spec.discrete_branches
    for length in (120, 100):
        obs = [rng.standard_normal((length, o.shape[0])).astype(np.float32) for o in spec.observation_specs]
        mask = np.zeros((length, sum(branches)), dtype=bool) if branches else None
        if masked:
            mask[1::3, 0] = True
        out = trainer.policy.act(obs, mask)
        trainer.process_trajectory(Trajectory(obs, [o[-1] for o in obs], rng.standard_normal(length).astype(np.float32),
                                              out.continuous_raw, out.discrete, out.log_probs, mask, False, True))
    return trainer


def _state(trainer: PPOTrainer) -> list[np.ndarray]:
    tensors = [*trainer.policy.actor.state_dict().values(), *trainer.critic.state_dict().values()]
    return [t.numpy().copy() for t in tensors] + [trainer.optimizer.exp_avg.copy(), trainer.optimizer.exp_avg_sq.copy()]


@pytest.mark.skipif(not numpy_update.fork_pays_off(float("inf")), reason="needs Linux, fork and two CPUs")
@pytest.mark.parametrize("action_spec,masked", [(ActionSpec(2, ()), False), (ActionSpec(1, (3, 2)), True)])
def test_critic_in_a_child_process_gives_the_same_bits(action_spec, masked, monkeypatch):
    spec = BehaviorSpec((vec(6), vec(2, "w")), action_spec)
    collected = []  # what the children handed back (None would mean the parent redid their work)
    collect = numpy_update._CriticChild.collect
    monkeypatch.setattr(numpy_update._CriticChild, "collect",
                        lambda self, timeout: collected.append(collect(self, timeout)) or collected[-1])
    results = []
    for min_work in (float("inf"), 0.0):  # sequential, then the critic's half in a child
        monkeypatch.setattr(numpy_update, "FORK_MIN_WORK", min_work)
        trainer = _filled_trainer(spec, masked)
        stats = trainer.update()
        results.append((stats, _state(trainer), trainer.optimizer.step_count))
    (seq_stats, seq_state, seq_steps), (par_stats, par_state, par_steps) = results
    assert seq_steps == par_steps == 2 * (220 // 32)
    assert len(collected) == 1 and collected[0][1] is None and len(collected[0][0]) == seq_steps
    assert seq_stats == par_stats  # exactly: the same float operations in the same order
    assert len(seq_state) == len(par_state)
    for x, y in zip(seq_state, par_state):
        assert x.tobytes() == y.tobytes()
    assert any(not np.array_equal(x, y) for x, y in zip(seq_state, _state(_filled_trainer(spec, masked))))


@pytest.mark.skipif(not numpy_update.fork_pays_off(float("inf")), reason="needs Linux, fork and two CPUs")
def test_critic_child_runs_elsewhere_and_a_failed_child_changes_nothing():
    param = torch.nn.Parameter(torch.arange(6, dtype=torch.float32).reshape(2, 3))
    adam = Adam([param])
    part = adam.stretch([param])

    def step_in_child(k: int, index: np.ndarray) -> float:
        part.arrays[0][...] += float(index.sum())  # written in the child, copied back by collect
        part.exp_avg[:] = k + 1
        return float(os.getpid())

    child = numpy_update._CriticChild.start(part, step_in_child, [np.array([1, 2]), np.array([3])])
    values, failure = child.collect(timeout=60.0)
    assert failure is None
    assert len(values) == 2 and all(v != os.getpid() for v in values)  # another process computed them
    np.testing.assert_array_equal(param.detach().numpy(), np.arange(6).reshape(2, 3) + 3.0 + 3.0)  # torch sees it
    np.testing.assert_array_equal(adam.exp_avg, np.full(6, 2.0))

    def fail_in_child(k: int, index: np.ndarray) -> float:
        part.arrays[0][...] = -1.0
        raise RuntimeError("boom")

    before = param.detach().clone()
    values, failure = numpy_update._CriticChild.start(part, fail_in_child, [np.array([0])]).collect(timeout=60.0)
    assert values is None and failure == "wait status 256"  # exit code 1
    assert torch.equal(param, before)  # the parent's critic is untouched


def _misbehaving_child(how: str):
    """A critic_step that, in a child process only, hangs or dies on its second minibatch."""
    parent, step = os.getpid(), numpy_update.NumpyPPO.critic_step

    def critic_step(self, batch, critic_in, t):
        if os.getpid() != parent and t - self.optimizer.step_count == 2:
            if how == "hang":
                time.sleep(3600)
            os.kill(os.getpid(), 9)
        return step(self, batch, critic_in, t)
    return critic_step


@pytest.mark.skipif(not numpy_update.fork_pays_off(float("inf")), reason="needs Linux, fork and two CPUs")
@pytest.mark.parametrize("how", ["hang", "die"])
def test_a_child_that_hangs_or_dies_is_reaped_and_the_parent_steps_the_critic(how, monkeypatch, caplog):
    spec = BehaviorSpec((vec(6),), ActionSpec(2, ()))
    monkeypatch.setattr(numpy_update, "FORK_MIN_WORK", float("inf"))
    sequential = _filled_trainer(spec, False)
    sequential.update()
    monkeypatch.setattr(numpy_update, "FORK_MIN_WORK", 0.0)
    monkeypatch.setattr(numpy_update, "FORK_TIMEOUT_MIN", 1.0 if how == "hang" else 120.0)  # a dying child: no timeout
    monkeypatch.setattr(numpy_update, "FORK_TIMEOUT_FACTOR", 0.0)
    monkeypatch.setattr(numpy_update.NumpyPPO, "critic_step", _misbehaving_child(how))
    children = []
    start = numpy_update._CriticChild.start
    monkeypatch.setattr(numpy_update._CriticChild, "start",
                        lambda *args: children.append(start(*args)) or children[-1])
    trainer = _filled_trainer(spec, False)
    with caplog.at_level(logging.WARNING, logger=numpy_update.__name__):
        trainer.update()
    assert len(children) == 1
    with pytest.raises(ProcessLookupError):
        os.kill(children[0].pid, 0)  # killed and reaped: no zombie left
    for x, y in zip(_state(sequential), _state(trainer)):  # the parent stepped the critic itself
        assert x.tobytes() == y.tobytes()
    failure = "no result after 1.0 s" if how == "hang" else "wait status 9"
    assert [r.getMessage() for r in caplog.records] == [
        f"The critic's update in a child process failed ({failure}); the trainer steps the critic "
        "itself from now on."]
    # the next update stays in this process, and says nothing more
    rng = np.random.default_rng(5)
    for length in (120, 100):
        obs = [rng.standard_normal((length, 6)).astype(np.float32)]
        out = trainer.policy.act(obs)
        trainer.process_trajectory(Trajectory(obs, [o[-1] for o in obs], rng.standard_normal(length).astype(np.float32),
                                              out.continuous_raw, out.discrete, out.log_probs, None, False, True))
    trainer.update()
    assert len(children) == 1 and len(caplog.records) == 1


@pytest.mark.skipif(not (sys.platform.startswith("linux") and hasattr(os, "fork")), reason="needs Linux and fork")
def test_the_fork_is_kept_for_updates_worth_it(monkeypatch):
    # basic: 3 epochs x 8 minibatches x 32 rows, 20x20 + 20 + 21 critic parameters; ball3d:
    # 3 x 187 x 64 rows, 8x128 + 128 + 128x128 + 128 + 129 parameters
    basic = 3 * 8 * 32 * (20 * 20 + 20 + 21)
    ball3d = 3 * 187 * 64 * (8 * 128 + 128 + 128 * 128 + 128 + 129)
    # the machine as the decision sees it: CPUs in the affinity mask, Python threads alive
    cpus, threads = [2], [1]
    monkeypatch.setattr(numpy_update, "usable_cpus", lambda: cpus[0])
    monkeypatch.setattr(numpy_update.threading, "active_count", lambda: threads[0])
    assert (numpy_update.fork_pays_off(basic), numpy_update.fork_pays_off(ball3d)) == (False, True)
    cpus[0] = 1  # no CPU for the child
    assert not numpy_update.fork_pays_off(ball3d)
    cpus[0], threads[0] = 2, 2  # another thread could hold a lock across the fork
    assert not numpy_update.fork_pays_off(ball3d)
