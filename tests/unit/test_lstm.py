"""network_settings.memory: the LSTM body, memories through acting, trajectories, sequence
minibatches and ONNX, and a task that cannot be solved without memory."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import onnxruntime as ort
import pytest
import torch

from protos.types import (
    ActionSpec,
    BehaviorSpec,
    DecisionSteps,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
)
from trainer.artifacts.onnx_export import export_to_bytes
from trainer.common.trajectory import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.masked import masked_mean
from trainer.ppo.losses import policy_loss
from trainer.common.networks import Actor
from trainer.common.policy import Policy
from trainer.ppo.trainer import PPOTrainer
from trainer.rollout import AgentTracker

SPEC = BehaviorSpec((ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                    ActionSpec(2, (3,)))
HYPER = PPOHyperparams(hidden_units=8, num_layers=1, memory_size=6, sequence_length=4, batch_size=8,
                       buffer_size=8, num_epoch=1, normalize=True, reward_signals={"extrinsic": (0.9, 1.0)})


def test_lstm_layout_init_and_onnx_constant():
    actor = Actor(SPEC.observation_specs, SPEC.action_spec, HYPER)
    lstm = actor.network_body.lstm.lstm
    assert (lstm.input_size, lstm.hidden_size, lstm.batch_first) == (8, 3, True)
    for bias in (lstm.bias_ih_l0, lstm.bias_hh_l0):  # gates i, f, g, o: forget bias 1 in each
        assert bias.tolist() == [0.0] * 3 + [1.0] * 3 + [0.0] * 6
    assert actor.network_body.output_size == 3 and actor.memory_size_vector.tolist() == [6.0]


def test_acting_step_by_step_carries_the_memory_like_one_sequence():
    policy = Policy(SPEC, HYPER, seed=0)
    obs = np.random.default_rng(0).normal(size=(5, 3)).astype(np.float32)
    memory, steps = np.zeros((1, 6), np.float32), []
    for t in range(5):
        out = policy.act([obs[t:t + 1]], None, deterministic=True, memories=memory)
        steps.append(out.env_actions.continuous[0])
        memory = out.memories
    with torch.no_grad():
        mu, _, final = policy.actor.heads_with_memory([torch.from_numpy(obs)], None, torch.zeros((1, 1, 6)), 5)
    np.testing.assert_allclose(np.array(steps), torch.clamp(mu, -3, 3).numpy() / 3, atol=1e-6)
    np.testing.assert_allclose(memory, final[0].numpy(), atol=1e-6)
    fresh = policy.act([obs[:1]], None, deterministic=True)  # no memories given: a new episode (zeros)
    np.testing.assert_allclose(fresh.env_actions.continuous[0], steps[0], atol=1e-7)


def test_tracker_keeps_each_agents_memory_and_the_inputs_per_experience():
    tracker = AgentTracker(SPEC, time_horizon=3, memory_size=6)
    assert tracker.memories_for(np.array([7, 8])).tolist() == [[0.0] * 6] * 2  # unknown: new episodes
    emitted = []
    for t in range(3):
        ds = DecisionSteps(obs=[np.full((2, 3), t, np.float32)], reward=np.ones(2, np.float32),
                           agent_id=np.array([7, 8]), action_mask=None, group_id=np.zeros(2, np.int32),
                           group_reward=np.zeros(2, np.float32))
        memory_in = tracker.memories_for(ds.agent_id)
        slots = tracker.on_decision(ds, emitted.append)
        memory_out = memory_in + np.array([[1.0], [10.0]], np.float32)  # what a policy would return
        tracker.on_actions(slots, np.zeros((2, 2), np.float32), np.zeros((2, 1), np.int32),
                           np.zeros((2, 3), np.float32), None, memory_in, memory_out)
        assert tracker.memories_for(np.array([8, 7, 9]))[:, 0].tolist() == [10.0 * (t + 1), t + 1.0, 0.0]
    ds = DecisionSteps(obs=[np.zeros((1, 3), np.float32)], reward=np.ones(1, np.float32), agent_id=np.array([7]),
                       action_mask=None, group_id=np.zeros(1, np.int32), group_reward=np.zeros(1, np.float32))
    tracker.on_decision(ds, emitted.append)  # the 4th decision cuts agent 7's trajectory at time_horizon 3
    assert len(emitted) == 1 and emitted[0].memories[:, 0].tolist() == [0.0, 1.0, 2.0]  # each action's input


def trajectory(policy: Policy, length: int, done: bool, episode: str, seed: int) -> Trajectory:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(length, 3)).astype(np.float32)
    out = policy.act([obs], None)
    return Trajectory(obs=[obs], next_obs=[rng.normal(size=3).astype(np.float32)],
                      rewards=rng.normal(size=length).astype(np.float32), continuous_actions=out.continuous_raw,
                      discrete_actions=out.discrete, log_probs=out.log_probs, action_masks=None, done=done,
                      interrupted=False, episode=episode,
                      memories=rng.normal(size=(length, 6)).astype(np.float32))


def test_trajectories_become_padded_sequences_with_the_critics_memory():
    trainer = PPOTrainer("Ball", SPEC, replace(HYPER, normalize=False), seed=0)
    first = trajectory(trainer.policy, 7, False, "a", seed=1)
    trainer.process_trajectory(first)
    data = trainer.buffer.concatenated()
    assert len(trainer.buffer) == 8 and trainer.step == 7  # padded to 2 sequences of 4; steps count 7
    assert data["masks"].tolist() == [1.0] * 7 + [0.0]
    np.testing.assert_array_equal(data["memory"][:7], first.memories)
    assert not data["memory"][7].any() and data["log_probs"][7].tolist() == [0.0] * 3
    obs = torch.from_numpy(first.obs[0])
    with torch.no_grad():
        v1, m1 = trainer.critic.forward_memory([obs[:4]], torch.zeros((1, 1, 6)), 4)
        v2, m2 = trainer.critic.forward_memory([obs[4:]], m1, 3)
    assert not data["critic_memory"][:4].any()  # each step keeps the memory its sequence started from
    np.testing.assert_allclose(data["critic_memory"][4:7], np.repeat(m1[0].numpy(), 3, axis=0), atol=1e-6)
    np.testing.assert_allclose(data["values:extrinsic"][:7], torch.cat([v1["extrinsic"], v2["extrinsic"]]),
                               atol=1e-6)
    # the episode's next trajectory starts from the critic's memory at the end of this one ...
    second = trajectory(trainer.policy, 2, True, "a", seed=2)
    trainer.process_trajectory(second)
    data = trainer.buffer.concatenated()
    np.testing.assert_allclose(data["critic_memory"][8:10], np.repeat(m2[0].numpy(), 2, axis=0), atol=1e-6)
    assert data["masks"][8:].tolist() == [1.0, 1.0, 0.0, 0.0]
    assert "a" not in trainer._critic_memory  # ... and an ended episode's memory is dropped


def test_minibatches_are_whole_sequences_and_batch_size_rounds_down():
    trainer = PPOTrainer("Ball", SPEC, replace(HYPER, batch_size=10, num_epoch=2), seed=0)
    for seed in range(3):
        trainer.process_trajectory(trajectory(trainer.policy, 8, False, f"e{seed}", seed))
    batches = [b.tolist() for b in trainer._minibatch_indices()]
    assert len(batches) == 2 * (24 // 8) and all(len(b) == 8 for b in batches)  # 10 -> 8 = 2 sequences
    for batch in batches:
        for start in batch[::4]:
            assert start % 4 == 0 and batch[batch.index(start):batch.index(start) + 4] == list(range(start, start + 4))
    stats = trainer.update()
    assert np.isfinite(stats["Losses/Policy Loss"]) and np.isfinite(stats["Losses/Value Loss"])


def test_masked_losses_ignore_padding():
    values = torch.tensor([[1.0, 3.0], [5.0, 7.0], [100.0, 100.0]])
    assert masked_mean(values, torch.tensor([1.0, 1.0, 0.0])).item() == 4.0
    assert masked_mean(values, None).item() == pytest.approx(216.0 / 6)
    advantages, logp = torch.tensor([1.0, -2.0, 50.0]), torch.zeros((3, 1))
    assert policy_loss(advantages, logp, logp, 0.2, torch.tensor([1.0, 1.0, 0.0])).item() == pytest.approx(0.5)


def test_onnx_recurrent_in_and_out_match_torch():
    policy = Policy(SPEC, HYPER, seed=3)
    session = ort.InferenceSession(export_to_bytes(policy))
    assert [i.name for i in session.get_inputs()] == ["obs_0", "action_masks", "recurrent_in"]
    assert session.get_inputs()[2].shape[1:] == [1, 6]
    names = [o.name for o in session.get_outputs()]
    assert names[-1] == "recurrent_out"
    rng = np.random.default_rng(4)
    obs, memories = rng.normal(size=(5, 3)).astype(np.float32), rng.normal(size=(5, 6)).astype(np.float32)
    mask = np.array([[0, 1, 0]] * 5, bool)
    result = dict(zip(names, session.run(None, {"obs_0": obs, "action_masks": (~mask).astype(np.float32),
                                                "recurrent_in": memories[:, None, :]})))
    out = policy.act([obs], mask, deterministic=True, memories=memories)
    assert result["memory_size"].tolist() == [6.0]
    np.testing.assert_allclose(result["recurrent_out"][:, 0, :], out.memories, atol=1e-5)
    np.testing.assert_allclose(result["deterministic_continuous_actions"], out.env_actions.continuous, atol=1e-5)
    np.testing.assert_array_equal(result["deterministic_discrete_actions"], out.discrete)
    assert (result["discrete_actions"] != 1).all()  # the masked option is never sampled


RECALL_SPEC = BehaviorSpec((ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                           ActionSpec(0, (2,)))


def recall_success(memory_size: int, iterations: int) -> float:
    """A cue (+-1) shown only on the first of 4 steps; reward 1 if the last action names it.
    Without memory the last step sees only zeros: 50 % at best. Returns the final success rate."""
    hyper = PPOHyperparams(hidden_units=16, num_layers=1, memory_size=memory_size, sequence_length=4, batch_size=32,
                           buffer_size=120, num_epoch=3, learning_rate=3e-3, beta=1e-3, max_steps=10**6,
                           learning_rate_schedule="constant", reward_signals={"extrinsic": (0.99, 1.0)})
    trainer = PPOTrainer("Recall", RECALL_SPEC, hyper, seed=11)
    return play_recall(trainer, memory_size, iterations)


def play_recall(trainer, memory_size: int, iterations: int) -> float:
    """Rounds of the recall task for any trainer (PPO here, SAC in test_sac_memory.py): 16 agents
    per round, each round's 4-step episodes handed to the trainer, an update when it is ready.
    Returns the success rate of the last 10 rounds."""
    rng, agents, results = np.random.default_rng(5), 16, []
    for it in range(iterations):
        cue = rng.integers(0, 2, agents)
        obs = np.zeros((4, agents, 2), np.float32)
        obs[0, :, 0], obs[0, :, 1] = 2.0 * cue - 1.0, 1.0
        memory = np.zeros((agents, memory_size), np.float32)
        steps = []
        for t in range(4):
            out = trainer.policy.act([obs[t]], None, memories=memory if memory_size else None)
            steps.append((out, memory))
            memory = out.memories
        correct = steps[-1][0].discrete[:, 0] == cue
        results.append(correct.mean())
        for a in range(agents):
            trainer.process_trajectory(Trajectory(
                obs=[obs[:, a]], next_obs=[np.zeros(2, np.float32)],
                rewards=np.array([0, 0, 0, float(correct[a])], np.float32),
                continuous_actions=np.zeros((4, 0), np.float32),
                discrete_actions=np.stack([s[0].discrete[a] for s in steps]),
                log_probs=np.stack([s[0].log_probs[a] for s in steps]), action_masks=None, done=True,
                interrupted=False, episode=(it, a),
                memories=np.stack([s[1][a] for s in steps]) if memory_size else None))
        if trainer.ready_to_update():
            trainer.update()
    return float(np.mean(results[-10:]))


def test_memory_solves_a_task_that_needs_it():
    assert recall_success(memory_size=16, iterations=120) >= 0.9
    assert recall_success(memory_size=0, iterations=120) <= 0.7  # the same task without memory


def test_a_reset_forgets_the_unfinished_episodes():
    trainer = PPOTrainer("Ball", SPEC, HYPER, seed=0)
    trainer.process_trajectory(trajectory(trainer.policy, 3, False, "a", seed=1))
    assert set(trainer._critic_memory) == {"a"}
    trainer.forget_episodes()
    assert trainer._critic_memory == {} and trainer._episode_intrinsic == {}


def test_numpy_acting_steps_the_lstm_like_torch():
    fast, slow = Policy(SPEC, HYPER, seed=2), Policy(SPEC, HYPER, seed=2)
    assert fast._numpy_actor is not None
    slow._numpy_actor = None  # the torch path
    rng = np.random.default_rng(3)
    memory_fast = memory_slow = np.zeros((4, 6), np.float32)
    for _ in range(6):  # memories fed back (deterministic: the two paths sample discrete actions differently)
        obs, mask = rng.normal(size=(4, 3)).astype(np.float32), rng.random((4, 3)) < 0.3
        mask[:, 0] = False
        a = fast.act([obs], mask, deterministic=True, memories=memory_fast)
        b = slow.act([obs], mask, deterministic=True, memories=memory_slow)
        np.testing.assert_allclose(a.memories, b.memories, atol=1e-5)
        np.testing.assert_allclose(a.continuous_raw, b.continuous_raw, atol=1e-5)
        np.testing.assert_array_equal(a.discrete, b.discrete)
        np.testing.assert_allclose(a.log_probs, b.log_probs, atol=1e-5)
        memory_fast, memory_slow = a.memories, b.memories


def test_numpy_and_torch_critics_value_sequences_alike():
    fast, slow = (PPOTrainer("Ball", SPEC, HYPER, seed=0) for _ in range(2))
    assert fast._numpy_critic is not None
    slow._numpy_critic = None
    for trainer in (fast, slow):
        for seed, (length, done) in enumerate([(7, False), (5, False), (2, True)]):
            trainer.process_trajectory(trajectory(trainer.policy, length, done, "a", seed))
    a, b = fast.buffer.concatenated(), slow.buffer.concatenated()
    for key in ("values:extrinsic", "returns:extrinsic", "critic_memory", "advantages"):
        np.testing.assert_allclose(a[key], b[key], atol=1e-5)
