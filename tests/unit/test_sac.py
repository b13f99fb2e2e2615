"""SAC's pure pieces against hand-computed numbers, the replay buffer's ring and file, and the
trainer's update cadence, checkpoint round trip and ONNX export (checked with onnxruntime)."""
from __future__ import annotations

import math

import numpy as np
import onnxruntime as ort
import pytest
import torch
from torch import nn

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.common import distributions
from trainer.common.trajectory import Trajectory
from trainer.sac import losses
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.replay_buffer import ReplayBuffer
from trainer.sac.trainer import SACTrainer


def vector(size: int) -> ObservationSpec:
    return ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector")


# ---------------------------------------------------------------------------- pure pieces
def test_target_entropies():
    continuous, discrete = losses.target_entropies(3, (2, 5))
    assert continuous == -3.0
    assert discrete == pytest.approx([0.2 * 0.6931471805599453, 0.2 * 1.6094379124341003])


def test_soft_update_by_hand():
    source, target = nn.Linear(1, 1), nn.Linear(1, 1)
    with torch.no_grad():
        source.weight.fill_(2.0), source.bias.fill_(-1.0)
        target.weight.fill_(10.0), target.bias.fill_(0.0)
    losses.soft_update(source, target, 0.1)  # 0.1 * 2 + 0.9 * 10 = 9.2 ; 0.1 * -1 + 0 = -0.1
    assert target.weight.item() == pytest.approx(9.2) and target.bias.item() == pytest.approx(-0.1)
    losses.soft_update(source, target, 1.0)
    assert target.weight.item() == 2.0 and target.bias.item() == -1.0


def test_q_backup_masks_done():
    rewards = torch.tensor([1.0, 0.5, -1.0])
    dones = torch.tensor([0.0, 1.0, 0.0])
    next_values = torch.tensor([2.0, 100.0, 4.0])
    # 1 + 0.9 * 2 = 2.8 ; 0.5 (episode over: no bootstrap) ; -1 + 0.9 * 4 = 2.6
    assert losses.q_backup(rewards, dones, next_values, 0.9).tolist() == pytest.approx([2.8, 0.5, 2.6])
    assert losses.q_backup(rewards, dones, next_values, 0.9, use_dones=False).tolist() == pytest.approx(
        [2.8, 90.5, 2.6])


def test_squashed_log_prob_is_the_change_of_variables():
    # raw = 0.5 ~ N(0, 1): log N = -0.125 - 0.9189385 ; log |d tanh/dx| = log(1 - tanh(0.5)^2)
    raw, mu, log_sigma = torch.tensor([[0.5]]), torch.zeros(1, 1), torch.zeros(1, 1)
    expected = -0.125 - 0.5 * math.log(2 * math.pi) - math.log(1 - math.tanh(0.5) ** 2)
    assert distributions.squashed_log_prob(raw, mu, log_sigma).item() == pytest.approx(expected, abs=1e-5)
    # stable where 1 - tanh^2 underflows: log(4) - 2|x| for large |x|
    assert distributions.tanh_log_abs_det_jacobian(torch.tensor([30.0])).item() == pytest.approx(math.log(4) - 60, rel=1e-6)


def test_chosen_q_and_branch_sums():
    q = torch.tensor([[1.0, 2.0, 3.0, 10.0, 20.0]])  # branches of 3 and 2 options
    actions = torch.tensor([[2, 0]])
    assert losses.chosen_q(q, actions, (3, 2)).item() == pytest.approx((3.0 + 10.0) / 2)
    assert losses.branch_sums(q, (3, 2)).tolist() == [[6.0, 30.0]]


def test_value_target_continuous_and_discrete_by_hand():
    q1, q2 = torch.tensor([1.0, 5.0]), torch.tensor([2.0, 4.0])
    log_probs = torch.tensor([[-1.0, -0.5], [0.0, 0.2]])
    alpha = torch.tensor([0.5])
    # min(1, 2) - 0.5 * (-1.5) = 1.75 ; min(5, 4) - 0.5 * 0.2 = 3.9
    target = losses.value_target(q1, q2, log_probs, alpha, None, None, None, ())
    assert target.tolist() == pytest.approx([1.75, 3.9])
    # one branch of two options, pi = (0.25, 0.75): E[Q1] = 0.25*1 + 0.75*3 = 2.5, E[Q2] = 0.25*2 + 0.75*2 = 2
    probs = torch.tensor([[0.25, 0.75]])
    log_p = torch.log(probs)
    neg_entropy = 0.25 * math.log(0.25) + 0.75 * math.log(0.75)
    target = losses.value_target(torch.tensor([[1.0, 3.0]]), torch.tensor([[2.0, 2.0]]), None, None,
                                 probs, log_p, torch.tensor([0.1]), (2,))
    assert target.item() == pytest.approx(2.0 - 0.1 * neg_entropy, abs=1e-6)


def test_policy_and_entropy_losses_by_hand():
    log_probs = torch.tensor([[-1.0], [-3.0]])
    q1 = torch.tensor([2.0, 1.0])
    # mean(0.5 * -1 - 2, 0.5 * -3 - 1) = mean(-2.5, -2.5)
    loss = losses.policy_loss(q1, log_probs, torch.tensor([0.5]), None, None, None, ())
    assert loss.item() == pytest.approx(-2.5)
    log_alpha = torch.tensor([math.log(0.5)], requires_grad=True)
    # target -1: gaps (-1 - 1, -3 - 1) = (-2, -4): loss = -log 0.5 * mean(-2, -4) = 3 log 0.5
    entropy = losses.entropy_loss(log_alpha, log_probs, -1.0, None, None, None, [], ())
    assert entropy.item() == pytest.approx(3 * math.log(0.5))
    entropy.backward()
    assert log_alpha.grad.item() == pytest.approx(3.0)  # d/d log alpha = -mean(gap) > 0: alpha shrinks


# ---------------------------------------------------------------------------- replay buffer
def rows(start: int, n: int) -> dict[str, np.ndarray]:
    values = np.arange(start, start + n, dtype=np.float32)
    return {"x": values, "pair": np.stack([values, -values], axis=1)}


def test_replay_buffer_ring_overwrites_the_oldest():
    buffer = ReplayBuffer(5)
    buffer.add(rows(0, 3))
    assert (len(buffer), buffer.cursor) == (3, 3)
    buffer.add(rows(3, 4))  # 3, 4 fill rows 3, 4; 5, 6 overwrite rows 0, 1
    assert (len(buffer), buffer.cursor) == (5, 2)
    assert buffer.fields["x"].tolist() == [5, 6, 2, 3, 4]
    assert buffer.chronological()["x"].tolist() == [2, 3, 4, 5, 6]
    buffer.add(rows(10, 12))  # longer than the capacity: only the newest 5 stay
    assert sorted(buffer.fields["x"].tolist()) == [17, 18, 19, 20, 21]
    assert buffer.chronological()["pair"][:, 1].tolist() == [-17, -18, -19, -20, -21]


def test_replay_buffer_samples_filled_rows_uniformly():
    buffer = ReplayBuffer(100)
    buffer.add(rows(0, 10))
    generator = torch.Generator().manual_seed(0)
    batch = buffer.sample(5000, generator)
    assert set(batch["x"].tolist()) == set(range(10))  # never an empty row
    counts = np.bincount(batch["x"].astype(int), minlength=10)
    assert counts.min() > 400 and counts.max() < 600  # 500 expected each
    assert np.array_equal(batch["pair"][:, 0], batch["x"])  # fields stay aligned


def test_replay_buffer_file_round_trip(tmp_path):
    buffer = ReplayBuffer(5)
    buffer.add(rows(0, 7))
    path = tmp_path / "buffer.npz"
    buffer.save(path)
    same = ReplayBuffer(5)
    same.load(path)
    assert (same.cursor, len(same)) == (buffer.cursor, len(buffer))
    for key in buffer.fields:
        assert np.array_equal(same.fields[key], buffer.fields[key])
    g1, g2 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    assert np.array_equal(same.sample(8, g1)["x"], buffer.sample(8, g2)["x"])
    smaller = ReplayBuffer(3)  # another capacity keeps the newest
    smaller.load(path)
    assert smaller.chronological()["x"].tolist() == [4, 5, 6]
    with np.load(path, allow_pickle=False) as archive:  # plain arrays only
        assert sorted(archive.files) == ["__capacity__", "__cursor__", "__size__", "pair", "x"]


# ---------------------------------------------------------------------------- trainer
def trajectory(trainer: SACTrainer, length: int, seed: int, done: bool = False) -> Trajectory:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(length, 4)).astype(np.float32)
    out = trainer.policy.act([obs])
    return Trajectory(obs=[obs], next_obs=[rng.normal(size=4).astype(np.float32)],
                      rewards=rng.normal(size=length).astype(np.float32),
                      continuous_actions=out.continuous_raw, discrete_actions=out.discrete,
                      log_probs=out.log_probs, action_masks=None, done=done, interrupted=False)


def make_trainer(**kw) -> SACTrainer:
    hyper = SACHyperparams(**{"batch_size": 8, "buffer_size": 100, "hidden_units": 8, "normalize": True, **kw})
    return SACTrainer("B", BehaviorSpec([vector(4)], ActionSpec(2, (3,))), hyper, seed=0)


def test_update_cadence_follows_steps_per_update_and_buffer_init_steps():
    trainer = make_trainer(steps_per_update=4.0, buffer_init_steps=20)
    trainer.process_trajectory(trajectory(trainer, 16, 0))
    assert not trainer.ready_to_update()  # 16 < buffer_init_steps
    trainer.process_trajectory(trajectory(trainer, 16, 1))
    # step 32: steps (32 - 20) / update_steps > 4 while update_steps < 3: two gradient steps
    assert trainer.ready_to_update()
    stats = trainer.update()
    assert trainer.update_steps == 3 and not trainer.ready_to_update()
    for key in ("Losses/Q1 Loss", "Losses/Q2 Loss", "Losses/Value Loss", "Losses/Policy Loss",
                "Policy/Continuous Entropy Coeff", "Policy/Discrete Entropy Coeff"):
        assert math.isfinite(stats[key])


def test_target_network_trails_the_value_network_by_tau():
    trainer = make_trainer(tau=0.25)
    target_before = [p.detach().clone() for p in trainer.target_network.parameters()]
    trainer.process_trajectory(trajectory(trainer, 16, 0))
    trainer.gradient_step(trainer.buffer.sample(8, trainer.sample_generator))
    for before, value, after in zip(target_before, trainer.critic.parameters(), trainer.target_network.parameters()):
        assert torch.allclose(after, 0.75 * before + 0.25 * value.detach(), atol=1e-6)


def test_checkpoint_round_trip_continues_identically():
    trainer, copy = make_trainer(), make_trainer()
    for seed in range(3):
        trainer.process_trajectory(trajectory(trainer, 16, seed))
    trainer.update()
    state = trainer.state_dict()
    saved = torch.load(_saved(state), weights_only=True)
    copy.load_state_dict(saved)
    copy.buffer = ReplayBuffer(100)
    copy.buffer.add(trainer.buffer.chronological())
    assert copy.step == trainer.step and copy.update_steps == trainer.update_steps
    batch = trainer.buffer.sample(8, torch.Generator().manual_seed(5))
    a, b = trainer.gradient_step(batch), copy.gradient_step(batch)
    assert a == pytest.approx(b, rel=1e-5)
    for p, q in zip(trainer.policy.actor.parameters(), copy.policy.actor.parameters()):
        assert torch.allclose(p, q, atol=1e-6)


def _saved(state):
    import io

    stream = io.BytesIO()
    torch.save(state, stream)
    stream.seek(0)
    return stream


def test_onnx_export_matches_the_policy(tmp_path):
    trainer = make_trainer()
    trainer.process_trajectory(trajectory(trainer, 16, 0))
    trainer.update()
    path = tmp_path / "B.onnx"
    trainer.export_onnx(str(path))
    session = ort.InferenceSession(str(path))
    names = [o.name for o in session.get_outputs()]
    assert names == ["version_number", "memory_size", "continuous_actions", "continuous_action_output_shape",
                     "deterministic_continuous_actions", "discrete_actions", "discrete_action_output_shape",
                     "deterministic_discrete_actions"]
    obs = np.random.default_rng(1).normal(size=(6, 4)).astype(np.float32)
    masks = np.ones((6, 3), np.float32)
    result = dict(zip(names, session.run(None, {"obs_0": obs, "action_masks": masks})))
    expected = trainer.policy.act([obs], None, deterministic=True)
    np.testing.assert_allclose(result["deterministic_continuous_actions"], expected.env_actions.continuous, atol=1e-5)
    np.testing.assert_array_equal(result["deterministic_discrete_actions"][:, 0], expected.discrete[:, 0])
    sampled = result["continuous_actions"]
    assert sampled.shape == (6, 2) and np.all(np.abs(sampled) < 1.0)  # tanh: inside (-1, 1), no clamp
    assert result["version_number"].tolist() == [3.0]


def test_numpy_and_torch_acting_agree():
    trainer = make_trainer()
    obs = np.random.default_rng(2).normal(size=(5, 4)).astype(np.float32)
    mask = np.array([[False, True, False]] * 5)
    fast = trainer.policy.act([obs], mask, deterministic=True)
    trainer.policy._numpy_actor = None  # the torch path (visual observations, GPUs)
    slow = trainer.policy.act([obs], mask, deterministic=True)
    np.testing.assert_allclose(fast.env_actions.continuous, slow.env_actions.continuous, atol=1e-6)
    np.testing.assert_array_equal(fast.discrete, slow.discrete)
    assert not np.any(fast.discrete == 1)  # the masked option is never chosen
    np.testing.assert_allclose(fast.log_probs, slow.log_probs, atol=1e-5)
