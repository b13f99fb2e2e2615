"""SAC with network_settings.memory: memories through acting (numpy and torch alike), padded
sequences in the replay buffer sampled at sequence starts, padding that never reaches a loss,
the recurrent actor's ONNX export checked with onnxruntime, and a task that needs memory."""
from __future__ import annotations

import numpy as np
import onnxruntime as ort
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.artifacts.onnx_export import export_to_bytes
from trainer.common.trajectory import Trajectory
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.replay_buffer import ReplayBuffer
from trainer.sac.trainer import SACTrainer
from tests.unit.test_lstm import RECALL_SPEC, play_recall

SPEC = BehaviorSpec((ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                    ActionSpec(2, (3,)))


def make_trainer(**kw) -> SACTrainer:
    hyper = SACHyperparams(**{"hidden_units": 8, "num_layers": 1, "memory_size": 6, "sequence_length": 4,
                              "batch_size": 8, "buffer_size": 30, "normalize": True, **kw})
    return SACTrainer("B", SPEC, hyper, seed=0)


def trajectory(trainer: SACTrainer, length: int, seed: int, done: bool = False, episode="e") -> Trajectory:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(length, 3)).astype(np.float32)
    memory, outs, memories = np.zeros((1, 6), np.float32), [], []
    for t in range(length):
        out = trainer.policy.act([obs[t:t + 1]], None, memories=memory)
        memories.append(memory[0])
        outs.append(out)
        memory = out.memories
    return Trajectory(obs=[obs], next_obs=[rng.normal(size=3).astype(np.float32)],
                      rewards=rng.normal(size=length).astype(np.float32),
                      continuous_actions=np.concatenate([o.continuous_raw for o in outs]),
                      discrete_actions=np.concatenate([o.discrete for o in outs]),
                      log_probs=np.concatenate([o.log_probs for o in outs]), action_masks=None, done=done,
                      interrupted=False, episode=episode, memories=np.stack(memories))


def test_acting_carries_the_memory_and_numpy_matches_torch():
    trainer = make_trainer()
    obs = np.random.default_rng(1).normal(size=(5, 3)).astype(np.float32)
    memory = np.zeros((1, 6), np.float32)
    for t in range(5):
        fast = trainer.policy.act([obs[t:t + 1]], None, deterministic=True, memories=memory)
        numpy_actor, trainer.policy._numpy_actor = trainer.policy._numpy_actor, None
        slow = trainer.policy.act([obs[t:t + 1]], None, deterministic=True, memories=memory)
        trainer.policy._numpy_actor = numpy_actor
        np.testing.assert_allclose(fast.memories, slow.memories, atol=1e-6)
        np.testing.assert_allclose(fast.env_actions.continuous, slow.env_actions.continuous, atol=1e-6)
        memory = fast.memories
    with torch.no_grad():  # step by step = one sequence of 5 from zero
        _, final = trainer.policy.actor.network_body.forward_memory([torch.from_numpy(obs)], torch.zeros(1, 1, 6), 5)
    np.testing.assert_allclose(memory, final[0].numpy(), atol=1e-6)


def test_trajectories_are_stored_as_padded_sequences_and_sampled_at_their_starts():
    trainer = make_trainer()
    assert trainer.buffer.capacity == 32  # buffer_size 30 rounded up to whole sequences of 4
    first, second = trajectory(trainer, 7, 0, episode="a"), trajectory(trainer, 5, 1, episode="b")
    trainer.process_trajectory(first)
    with torch.no_grad():  # the critic's memory at each sequence start, carried within the episode
        _, after_first = trainer.critic.forward_memory([torch.from_numpy(first.obs[0][:4])], torch.zeros(1, 1, 6), 4)
    trainer.process_trajectory(second)
    assert len(trainer.buffer) == 16 and trainer.step == 12  # 7 -> 8 rows, 5 -> 8 rows
    data = trainer.buffer.chronological()
    assert data["masks"].tolist() == [1.0] * 7 + [0.0] + [1.0] * 5 + [0.0] * 3
    np.testing.assert_array_equal(data["memory"][:7], first.memories)
    assert not data["memory"][7].any() and data["done"].sum() == 0.0
    np.testing.assert_allclose(data["critic_memory"][4], after_first[0, 0].numpy(), atol=1e-6)
    assert not data["critic_memory"][:4].any()
    batch = trainer._sample()
    assert batch["obs_0"].shape == (8, 3)  # batch_size 8 = two sequences of 4
    for start in (0, 4):  # each sampled sequence is 4 consecutive stored rows from a multiple of 4
        row = int(np.flatnonzero((data["obs_0"] == batch["obs_0"][start]).all(axis=1))[0])
        assert row % 4 == 0
        np.testing.assert_array_equal(batch["obs_0"][start:start + 4], data["obs_0"][row:row + 4])


def test_sequences_stay_aligned_when_the_ring_wraps():
    buffer = ReplayBuffer(8)
    for start in (0, 4, 8):  # the third sequence overwrites the first
        buffer.add({"x": np.arange(start, start + 4, dtype=np.float32)})
    sample = buffer.sample_sequences(50, 4, torch.Generator().manual_seed(0))["x"].reshape(-1, 4)
    assert {tuple(row) for row in sample.tolist()} == {(4, 5, 6, 7), (8, 9, 10, 11)}


def test_padding_never_reaches_a_loss():
    trainer, twin = make_trainer(), make_trainer()
    trainer.process_trajectory(trajectory(trainer, 6, 0, done=True))
    twin.process_trajectory(trajectory(twin, 6, 0, done=True))
    batch = trainer.buffer.chronological()
    garbage = {k: v.copy() for k, v in batch.items()}
    pad = garbage["masks"] == 0
    assert pad.sum() == 2
    for key in ("obs_0", "next_obs_0", "continuous_actions", "rewards"):
        garbage[key][pad] = 1e3
    garbage["done"][pad] = 1.0
    a, b = trainer.gradient_step(batch), twin.gradient_step(garbage)
    assert a == pytest.approx(b, rel=1e-5)
    garbage["rewards"][~pad] += 1.0  # ...while the real rows do
    assert twin.gradient_step(garbage)["Losses/Q1 Loss"] != pytest.approx(a["Losses/Q1 Loss"], rel=1e-3)


def test_update_runs_and_a_checkpoint_continues_identically():
    trainer, copy = make_trainer(), make_trainer()
    for seed in range(3):
        trainer.process_trajectory(trajectory(trainer, 7, seed, done=seed == 1, episode=seed))
    stats = trainer.update()
    assert trainer.update_steps == 21 and all(np.isfinite(v) for v in stats.values())
    copy.load_state_dict(trainer.state_dict())
    copy.buffer.add(trainer.buffer.chronological())
    batch = trainer._sample()
    assert trainer.gradient_step(batch) == pytest.approx(copy.gradient_step(batch), rel=1e-5)


def test_onnx_recurrent_in_and_out_match_torch():
    trainer = make_trainer()
    for seed in range(2):
        trainer.process_trajectory(trajectory(trainer, 8, seed, episode=seed))
    trainer.update()
    session = ort.InferenceSession(export_to_bytes(trainer.policy))
    assert [i.name for i in session.get_inputs()] == ["obs_0", "action_masks", "recurrent_in"]
    names = [o.name for o in session.get_outputs()]
    assert names[-1] == "recurrent_out"
    rng = np.random.default_rng(4)
    mask = np.array([[0, 1, 0]] * 5, bool)
    memory = np.zeros((5, 6), np.float32)
    for t in range(3):  # Unity feeds recurrent_out back into recurrent_in
        obs = rng.normal(size=(5, 3)).astype(np.float32)
        result = dict(zip(names, session.run(None, {"obs_0": obs, "action_masks": (~mask).astype(np.float32),
                                                    "recurrent_in": memory[:, None, :]})))
        out = trainer.policy.act([obs], mask, deterministic=True, memories=memory)
        np.testing.assert_allclose(result["recurrent_out"][:, 0, :], out.memories, atol=1e-5)
        np.testing.assert_allclose(result["deterministic_continuous_actions"], out.env_actions.continuous, atol=1e-5)
        np.testing.assert_array_equal(result["deterministic_discrete_actions"], out.discrete)
        memory = out.memories
    assert result["memory_size"].tolist() == [6.0] and np.abs(memory).sum() > 0


def recall_success(memory_size: int, iterations: int) -> float:
    """test_lstm.py's recall task for SAC: a cue (+-1) shown only on the first of 4 steps, reward 1
    if the last action names it; without memory the last step sees zeros (50 % at best). 16
    agents, one gradient step per 16 agent steps. Returns the success rate of the last 10 rounds."""
    hyper = SACHyperparams(hidden_units=16, num_layers=1, memory_size=memory_size, sequence_length=4, batch_size=64,
                           buffer_size=2000, learning_rate=3e-3, steps_per_update=16.0, init_entcoef=0.05,
                           reward_signals={"extrinsic": (0.99, 1.0)})
    trainer = SACTrainer("Recall", RECALL_SPEC, hyper, seed=11)
    return play_recall(trainer, memory_size, iterations)


def test_memory_solves_a_task_that_needs_it():
    # measured: 0.99 with memory (0.50 -> 0.74 -> 0.96 by round 30), 0.54 without
    assert recall_success(memory_size=16, iterations=50) >= 0.9
    assert recall_success(memory_size=0, iterations=50) <= 0.7
