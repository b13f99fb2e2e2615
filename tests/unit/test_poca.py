"""MA-POCA's pure pieces: the attention critic (order of teammates, absent slots), group trajectory
assembly (teammates' columns, the group's end, an agent that leaves early) and the lambda returns,
baselines and bootstraps against hand-computed values (docs/poca.md)."""
import numpy as np
import pytest
import torch

from protos.types import (
    ActionSpec, BehaviorSpec, DecisionSteps, DimensionProperty, ObservationSpec, ObservationType, TerminalSteps,
)
from trainer.poca.networks import POCACritic
from trainer.poca.trainer import POCATrainer
from trainer.common.trajectory import GroupColumns, Trajectory
from trainer.common.gae import gae
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.rollout import GroupTracker

SPEC = BehaviorSpec(
    (ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vec"),),
    ActionSpec(1, (3,)),
)


def critic():
    torch.manual_seed(0)
    return POCACritic(SPEC.observation_specs, SPEC.action_spec, ["extrinsic"],
                      PPOHyperparams(hidden_units=16, num_layers=2, normalize=True))


# ------------------------------------------------------------------------------ critic
def test_value_ignores_the_order_of_members_and_whatever_sits_in_absent_slots():
    net = critic()
    obs = torch.randn(6, 4, 2)
    present = torch.tensor([[True, True, True, False]] * 3 + [[True, False, True, False]] * 3)
    value = net.value([obs], present)["extrinsic"]
    shuffled = obs[:, [2, 1, 0, 3]]
    shuffled_present = present[:, [2, 1, 0, 3]]
    assert torch.allclose(net.value([shuffled], shuffled_present)["extrinsic"], value, atol=1e-6)
    garbage = obs.clone()
    garbage[~present] = 1e6
    assert torch.allclose(net.value([garbage], present)["extrinsic"], value, atol=1e-6)
    # ...but a present member's observation does matter
    moved = obs.clone()
    moved[:, 2] += 1.0
    assert not torch.allclose(net.value([moved], present)["extrinsic"], value, atol=1e-4)


def test_baseline_ignores_teammate_order_and_padding_and_sees_teammates_actions():
    net = critic()
    own, mates = torch.randn(5, 2), torch.randn(5, 3, 2)
    cont, disc = torch.randn(5, 3, 1), torch.randint(0, 3, (5, 3, 1))
    present = torch.tensor([[True, True, False]] * 5)
    base = net.baseline([own], [mates], cont, disc, present)["extrinsic"]
    order = [1, 0, 2]
    assert torch.allclose(net.baseline([own], [mates[:, order]], cont[:, order], disc[:, order], present[:, order])
                          ["extrinsic"], base, atol=1e-6)
    padded = net.baseline([own], [torch.cat([mates, torch.randn(5, 2, 2)], 1)], torch.cat([cont, torch.randn(5, 2, 1)], 1),
                          torch.cat([disc, torch.randint(0, 3, (5, 2, 1))], 1),
                          torch.cat([present, torch.zeros(5, 2, dtype=torch.bool)], 1))["extrinsic"]
    assert torch.allclose(padded, base, atol=1e-6)
    other = disc.clone()
    other[:, 0, 0] = (other[:, 0, 0] + 1) % 3
    assert not torch.allclose(net.baseline([own], [mates], cont, other, present)["extrinsic"], base, atol=1e-5)
    alone = net.baseline([own], [mates[:, :0]], cont[:, :0], disc[:, :0], present[:, :0])["extrinsic"]
    assert alone.shape == (5,) and torch.isfinite(alone).all()


# ------------------------------------------------------------------------------ assembly
def ds(ids, obs, groups, group_reward=0.0, reward=None):
    n = len(ids)
    reward = np.zeros(n, np.float32) if reward is None else np.array(reward, np.float32)
    return DecisionSteps(obs=[np.array(obs, np.float32).reshape(n, 2)], reward=reward,
                         agent_id=np.array(ids, np.int64), action_mask=None, group_id=np.array(groups, np.int32),
                         group_reward=np.full(n, group_reward, np.float32))


def ts(ids, obs, groups, group_reward=0.0, interrupted=False):
    n = len(ids)
    return TerminalSteps(obs=[np.array(obs, np.float32).reshape(n, 2)], reward=np.zeros(n, np.float32),
                         interrupted=np.full(n, interrupted), agent_id=np.array(ids, np.int64),
                         group_id=np.array(groups, np.int32), group_reward=np.full(n, group_reward, np.float32))


NONE = ts([], [], [])


def act(tracker, slots, choices):
    n = len(slots)
    tracker.on_actions(slots, np.array(choices, np.float32).reshape(n, 1) / 10, np.array(choices, np.int32).reshape(n, 1),
                       np.zeros((n, 2), np.float32), None)


def test_teammates_columns_and_an_agent_that_leaves_before_its_group():
    out = []
    tr = GroupTracker(SPEC, time_horizon=10)
    # step 0: agents 1 and 2 of group 7 decide; agent 3 has no group
    act(tr, tr.on_step(NONE, ds([1, 2, 3], [[1, 0], [2, 0], [3, 0]], [7, 7, 0]), out.append), [1, 2, 0])
    # step 1: all continue (group reward 0.5; agent 2's own reward 0.3)
    act(tr, tr.on_step(NONE, ds([1, 2, 3], [[1, 1], [2, 1], [3, 1]], [7, 7, 0], 0.5, [0, 0.3, 0]), out.append),
        [0, 1, 2])
    # step 2: agent 2 leaves (its episode ends, group 7 goes on with agent 1)
    act(tr, tr.on_step(ts([2], [[2, 2]], [7], 0.25), ds([1, 3], [[1, 2], [3, 2]], [7, 0], 0.25), out.append), [2, 1])
    assert len(out) == 1
    left = out.pop()
    assert left.done and not left.interrupted and len(left) == 2
    g = left.group
    # at each of its steps its teammate was agent 1, with the observation and action of that step
    np.testing.assert_array_equal(g.present, [[True], [True]])
    np.testing.assert_array_equal(g.obs[0][:, 0], [[1, 0], [1, 1]])
    np.testing.assert_array_equal(g.discrete_actions[:, 0, 0], [1, 0])
    np.testing.assert_allclose(g.continuous_actions[:, 0, 0], [0.1, 0.0])
    # the group goes on without it: bootstrap from agent 1's observation now
    assert not g.all_done
    np.testing.assert_array_equal(g.next_obs[0], [[1, 2]])
    assert tr.episodes.group_returns == []  # its group had not finished
    # step 3: the group ends (agent 1 alone), agent 3 (no group) is cut by its own end too
    tr.on_step(ts([1, 3], [[1, 3], [3, 3]], [7, 0], 1.0), ds([], [], []), out.append)
    last, lonely = out
    assert last.done and last.group.all_done and len(last) == 3
    # agent 2 was its teammate for steps 0 and 1 only (it acted at step 1, then it was gone)
    np.testing.assert_array_equal(last.group.present, [[True], [True], [False]])
    np.testing.assert_array_equal(last.group.obs[0][:, 0], [[2, 0], [2, 1], [0, 0]])
    np.testing.assert_allclose(last.group.rewards[:, 0], [0.3, 0, 0])  # agent 2's own rewards
    np.testing.assert_allclose(left.group.rewards[:, 0], [0, 0])
    assert lonely.group.width == 0 and lonely.group.all_done
    # group rewards 0.5 + 0.25 + 1.0 of agent 1 (the only one there when its group finished); agent 3
    # without a group counts as a finished group of its own, as in the reference
    assert tr.episodes.group_returns == [pytest.approx(1.75)] * 2
    np.testing.assert_allclose(last.rewards, [0.5, 0.25, 1.0])


# ------------------------------------------------------------------------------ returns
def test_lambda_returns_are_gae_returns_by_hand():
    # G_t = r_t + gamma ((1 - lambda) V_{t+1} + lambda G_{t+1}), G_T = V_next; gamma 0.9, lambda 0.8
    _, returns = gae(np.array([1.0, 0.0, 2.0]), np.array([0.5, 1.0, 1.5]), 2.0, 0.9, 0.8)
    g2 = 2 + 0.9 * 2
    g1 = 0 + 0.9 * (0.2 * 1.5 + 0.8 * g2)
    g0 = 1 + 0.9 * (0.2 * 1.0 + 0.8 * g1)
    np.testing.assert_allclose(returns, [g0, g1, g2], rtol=1e-6)
    assert g0 == pytest.approx(3.34432)


def trajectory(done, interrupted, all_done):
    n = 3
    group = GroupColumns([np.zeros((n, 1, 2), np.float32)], np.zeros((n, 1, 1), np.float32), np.zeros((n, 1, 1), np.int32),
                         np.ones((n, 1), bool), np.array([[0.5], [0.0], [0.0]], np.float32),
                         [np.zeros((1, 2), np.float32)], np.ones(1, bool), all_done)
    return Trajectory(obs=[np.zeros((n, 2), np.float32)], next_obs=[np.zeros(2, np.float32)],
                      rewards=np.array([1.0, 0.0, 2.0], np.float32), continuous_actions=np.zeros((n, 1), np.float32),
                      discrete_actions=np.zeros((n, 1), np.int64), log_probs=np.zeros((n, 2), np.float32),
                      action_masks=None, done=done, interrupted=interrupted, episode="e", group=group)


@pytest.mark.parametrize("done, interrupted, all_done, bootstrap", [
    (False, False, False, 2.0),  # cut at time_horizon
    (True, False, False, 2.0),  # left before its group: the group's value after it left is its credit
    (True, True, True, 2.0),  # the group was interrupted (max_step)
    (True, False, True, 0.0),  # the group's episode is over
])
def test_returns_advantages_and_the_group_bootstrap(monkeypatch, done, interrupted, all_done, bootstrap):
    trainer = POCATrainer("B", SPEC, PPOHyperparams(hidden_units=8, num_layers=1, lambd=0.8,
                                                    reward_signals={"extrinsic": (0.9, 1.0)}), seed=0)
    values, baselines = np.array([0.5, 1.0, 1.5], np.float32), np.array([0.25, 0.5, 1.0], np.float32)
    monkeypatch.setattr(trainer, "estimates", lambda traj, group: (
        {"extrinsic": values}, {"extrinsic": baselines}, {"extrinsic": 2.0}))
    trainer.process_trajectory(trajectory(done, interrupted, all_done))
    fields = trainer.buffer.concatenated()
    # rewards 1, 0, 2 plus the teammate's own 0.5 at step 0
    g2 = 2 + 0.9 * bootstrap
    g1 = 0.9 * (0.2 * 1.5 + 0.8 * g2)
    g0 = 1.5 + 0.9 * (0.2 * 1.0 + 0.8 * g1)
    np.testing.assert_allclose(fields["returns:extrinsic"], [g0, g1, g2], rtol=1e-6)
    np.testing.assert_allclose(fields["advantages"], np.array([g0, g1, g2]) - baselines, rtol=1e-6)
    assert fields["mates_present"].shape == (3, 1)


def test_poca_updates_and_its_checkpoint_round_trips():
    spec = SPEC
    hp = PPOHyperparams(hidden_units=8, num_layers=1, batch_size=4, buffer_size=4, num_epoch=2)
    trainer = POCATrainer("B", spec, hp, seed=0)
    rng = np.random.default_rng(0)
    for width in (1, 2):  # a wider group later: the buffered experiences are padded
        traj = trajectory(False, False, False)
        traj.group = GroupColumns([rng.normal(size=(3, width, 2)).astype(np.float32)], np.zeros((3, width, 1), np.float32),
                                  np.zeros((3, width, 1), np.int32), np.ones((3, width), bool),
                                  np.zeros((3, width), np.float32), [np.zeros((width, 2), np.float32)],
                                  np.ones(width, bool), False)
        trainer.process_trajectory(traj)
    assert trainer.ready_to_update() and trainer.group_width == 2
    before = [p.detach().clone() for p in trainer.critic.parameters()]
    stats = trainer.update()
    assert {"Losses/Baseline Loss", "Losses/Value Loss", "Losses/Policy Loss"} <= set(stats)
    assert any(not torch.equal(a, b) for a, b in zip(before, trainer.critic.parameters()))
    again = POCATrainer("B", spec, hp, seed=5)
    again.load_state_dict(trainer.state_dict())
    for a, b in zip(again.critic.state_dict().values(), trainer.critic.state_dict().values()):
        assert torch.equal(a, b)


def test_agents_without_a_group_train_with_a_critic_of_one():
    """group id 0 (soccer's players; no GroupColumns): the value and the baseline see the agent
    alone, both the same function of its observations, so the advantage is PPO's (return - V)."""
    trainer = POCATrainer("B", SPEC, PPOHyperparams(hidden_units=8, num_layers=1, batch_size=3, buffer_size=3,
                                                    num_epoch=1), seed=0)
    traj = trajectory(True, False, True)
    traj.group = None
    traj.obs = [np.random.default_rng(0).normal(size=(3, 2)).astype(np.float32)]
    trainer.process_trajectory(traj)
    fields = trainer.buffer.concatenated()
    assert trainer.group_width == 0 and fields["mates_present"].shape == (3, 0)
    assert np.all(np.isfinite(fields["advantages"])) and np.all(np.isfinite(fields["returns:extrinsic"]))
    with torch.inference_mode():
        obs = [torch.as_tensor(traj.obs[0])]
        value = trainer.critic.value([obs[0].unsqueeze(1)], torch.ones((3, 1), dtype=torch.bool))["extrinsic"]
        baseline = trainer.critic.baseline(obs, [torch.zeros(3, 0, 2)], torch.zeros(3, 0, 1),
                                           torch.zeros(3, 0, 1, dtype=torch.int64),
                                           torch.zeros(3, 0, dtype=torch.bool))["extrinsic"]
    torch.testing.assert_close(value, baseline)
    np.testing.assert_allclose(fields["baselines:extrinsic"], value.numpy(), rtol=1e-6)
    stats = trainer.update()
    assert np.isfinite(stats["Losses/Value Loss"]) and np.isfinite(stats["Losses/Baseline Loss"])


# ------------------------------------------------------------------------------ memory
MEMORY = PPOHyperparams(hidden_units=8, num_layers=1, memory_size=6, sequence_length=4, batch_size=8,
                        buffer_size=8, num_epoch=1, normalize=False, reward_signals={"extrinsic": (0.9, 1.0)})


def group_trajectory(length, done, episode, seed, width=1):
    rng = np.random.default_rng(seed)
    group = GroupColumns([rng.normal(size=(length, width, 2)).astype(np.float32)],
                         rng.normal(size=(length, width, 1)).astype(np.float32),
                         rng.integers(0, 3, (length, width, 1)).astype(np.int32), np.ones((length, width), bool),
                         np.zeros((length, width), np.float32), [rng.normal(size=(width, 2)).astype(np.float32)],
                         np.ones(width, bool), done)
    return Trajectory(obs=[rng.normal(size=(length, 2)).astype(np.float32)],
                      next_obs=[rng.normal(size=2).astype(np.float32)],
                      rewards=rng.normal(size=length).astype(np.float32),
                      continuous_actions=rng.normal(size=(length, 1)).astype(np.float32),
                      discrete_actions=rng.integers(0, 3, (length, 1)), log_probs=np.zeros((length, 2), np.float32),
                      action_masks=None, done=done, interrupted=False, episode=episode,
                      memories=rng.normal(size=(length, 6)).astype(np.float32), group=group)


def test_memory_trajectories_become_padded_sequences_with_value_and_baseline_memories():
    trainer = POCATrainer("B", SPEC, MEMORY, seed=0)
    lstm = trainer.critic.lstm.lstm
    assert (lstm.input_size, lstm.hidden_size) == (8, 3) and trainer.critic.value_heads["extrinsic"].in_features == 3
    first = group_trajectory(7, False, "a", seed=1)
    trainer.process_trajectory(first)
    data = trainer.buffer.concatenated()
    assert len(trainer.buffer) == 8 and trainer.step == 7  # 2 sequences of 4, the last padded; 7 steps count
    assert data["masks"].tolist() == [1.0] * 7 + [0.0]
    np.testing.assert_array_equal(data["memory"][:7], first.memories)
    assert not data["memory"][7].any() and not data["mates_present"][7].any()
    # by hand: the value over the group and the baseline, each with its own memory, 4 then 3 steps
    g = first.group
    own, mates = torch.from_numpy(first.obs[0]), torch.from_numpy(g.obs[0])
    everyone, present = torch.cat([own[:, None], mates], 1), torch.ones((7, 2), dtype=torch.bool)
    cont, disc, mp = torch.from_numpy(g.continuous_actions), torch.from_numpy(g.discrete_actions), torch.from_numpy(g.present)
    zero = torch.zeros((1, 1, 6))
    with torch.no_grad():
        v1, vm1 = trainer.critic.value_memory([everyone[:4]], present[:4], zero, 4)
        v2, vm2 = trainer.critic.value_memory([everyone[4:]], present[4:], vm1, 3)
        b1, bm1 = trainer.critic.baseline_memory([own[:4]], [mates[:4]], cont[:4], disc[:4], mp[:4], zero, 4)
        b2, bm2 = trainer.critic.baseline_memory([own[4:]], [mates[4:]], cont[4:], disc[4:], mp[4:], bm1, 3)
    assert not torch.allclose(vm1, bm1)  # two memory streams through one LSTM
    assert not data["critic_memory"][:4].any() and not data["baseline_memory"][:4].any()
    np.testing.assert_allclose(data["critic_memory"][4:7], np.repeat(vm1[0].numpy(), 3, axis=0), atol=1e-6)
    np.testing.assert_allclose(data["baseline_memory"][4:7], np.repeat(bm1[0].numpy(), 3, axis=0), atol=1e-6)
    np.testing.assert_allclose(data["baselines:extrinsic"][:7], torch.cat([b1["extrinsic"], b2["extrinsic"]]),
                               atol=1e-6)
    # returns bootstrap from V of the group after the last step, read with the memory after step 7
    after = torch.cat([torch.from_numpy(first.next_obs[0])[None], torch.from_numpy(g.next_obs[0])])[None]
    with torch.no_grad():
        next_v, _ = trainer.critic.value_memory([after], torch.ones((1, 2), dtype=torch.bool), vm2, 1)
    rewards = first.rewards + g.rewards.sum(axis=1)
    _, returns = gae(rewards, torch.cat([v1["extrinsic"], v2["extrinsic"]]).numpy(), float(next_v["extrinsic"][0]),
                     0.9, MEMORY.lambd)
    np.testing.assert_allclose(data["returns:extrinsic"][:7], returns, rtol=1e-5, atol=1e-6)
    # the episode's next trajectory starts from both memories at the end of this one; its end drops them
    trainer.process_trajectory(group_trajectory(2, True, "a", seed=2, width=2))
    data = trainer.buffer.concatenated()
    np.testing.assert_allclose(data["critic_memory"][8:10], np.repeat(vm2[0].numpy(), 2, axis=0), atol=1e-6)
    np.testing.assert_allclose(data["baseline_memory"][8:10], np.repeat(bm2[0].numpy(), 2, axis=0), atol=1e-6)
    assert data["masks"][8:].tolist() == [1.0, 1.0, 0.0, 0.0] and data["mates_present"].shape == (12, 2)
    assert "a" not in trainer._critic_memory


def test_memory_update_ignores_padding_and_the_checkpoint_round_trips():
    trainer = POCATrainer("B", SPEC, MEMORY, seed=0)
    for seed in range(3):
        trainer.process_trajectory(group_trajectory(3, False, f"e{seed}", seed))
    assert trainer.ready_to_update()
    batch = {k: torch.as_tensor(v) for k, v in trainer._buffer_tensors().items()}
    loss, _ = trainer._minibatch_loss(batch, 0.01, 0.2)
    for key in ("obs_0", "mates_obs_0", "returns:extrinsic", "advantages"):  # what sits in padded rows is ignored
        changed = dict(batch)
        changed[key] = batch[key].clone()
        changed[key][batch["masks"] == 0] = 1e3
        torch.testing.assert_close(trainer._minibatch_loss(changed, 0.01, 0.2)[0], loss)
    before = [p.detach().clone() for p in trainer.critic.lstm.parameters()]
    stats = trainer.update()
    assert np.isfinite(stats["Losses/Baseline Loss"]) and np.isfinite(stats["Losses/Policy Loss"])
    assert any(not torch.equal(a, b) for a, b in zip(before, trainer.critic.lstm.parameters()))
    again = POCATrainer("B", SPEC, MEMORY, seed=5)
    again.load_state_dict(trainer.state_dict())
    assert any(k.startswith("lstm.") for k in again.critic.state_dict())
    for a, b in zip(again.critic.state_dict().values(), trainer.critic.state_dict().values()):
        assert torch.equal(a, b)
    moments, restored = trainer.optimizer.state_dict()["state"], again.optimizer.state_dict()["state"]
    trainable = [p for m in (trainer.policy.actor, trainer.critic) for p in m.parameters() if p.requires_grad]
    assert len(moments) == len(trainable)
    for index, state in moments.items():  # the Adam moments of every actor and critic weight, LSTMs included
        assert torch.equal(restored[index]["exp_avg"], state["exp_avg"]) and state["exp_avg"].abs().sum() > 0


RECALL = BehaviorSpec((ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                      ActionSpec(0, (2,)))


def group_recall_success(memory_size: int, rounds: int) -> float:
    """Groups of two: both agents see their group's cue (+-1) on the first of 4 steps only; at the
    end the group earns half a point per agent whose last action named the cue (a group reward:
    each agent's credit goes through POCA's baseline). Without memory the last step sees zeros:
    50 % at best. Runs through rollout.GroupTracker (each agent's memory kept there, as in a run);
    returns the success rate of the last 10 rounds."""
    hyper = PPOHyperparams(hidden_units=16, num_layers=1, memory_size=memory_size, sequence_length=4, batch_size=32,
                           buffer_size=120, num_epoch=3, learning_rate=3e-3, beta=1e-3, max_steps=10**6,
                           learning_rate_schedule="constant", normalize=False, reward_signals={"extrinsic": (0.99, 1.0)})
    trainer = POCATrainer("Recall", RECALL, hyper, seed=11)
    tracker = GroupTracker(RECALL, time_horizon=64, memory_size=memory_size)
    rng, agents, results = np.random.default_rng(5), 16, []
    groups = 1 + np.arange(agents) // 2
    for it in range(rounds):
        ids = it * agents + np.arange(agents)  # every episode a new agent id, as Unity's
        cue = rng.integers(0, 2, agents // 2)[groups - 1]
        emitted = []
        for t in range(4):
            obs = np.zeros((agents, 2), np.float32)
            if t == 0:
                obs[:, 0], obs[:, 1] = 2.0 * cue - 1.0, 1.0
            steps = DecisionSteps(obs=[obs], reward=np.zeros(agents, np.float32), agent_id=ids, action_mask=None,
                                  group_id=groups.astype(np.int32), group_reward=np.zeros(agents, np.float32))
            slots = tracker.on_step(TerminalSteps.empty(RECALL), steps, emitted.append)
            memories = tracker.memories_for(ids) if memory_size else None
            out = trainer.policy.act([obs], None, memories=memories)
            tracker.on_actions(slots, out.continuous_raw, out.discrete, out.log_probs, None, memories, out.memories)
        correct = out.discrete[:, 0] == cue
        results.append(correct.mean())
        score = np.array([correct[groups == g].mean() for g in groups], np.float32)
        tracker.on_step(TerminalSteps([np.zeros((agents, 2), np.float32)], np.zeros(agents, np.float32),
                                      np.zeros(agents, bool), ids, groups.astype(np.int32), score),
                        DecisionSteps.empty(RECALL), emitted.append)
        assert len(emitted) == agents and all(t.done and t.group.all_done and t.group.width == 1 for t in emitted)
        for traj in emitted:
            trainer.process_trajectory(traj)
        if trainer.ready_to_update():
            trainer.update()
    return float(np.mean(results[-10:]))


@pytest.fixture
def one_torch_thread():
    """As a run (trainer/run_setup.py configure_torch_threads): torch's thread pool on these tiny
    networks only costs hand-offs, and on a loaded machine a great deal (measured 20x here)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_memory_solves_a_group_task_that_needs_it(one_torch_thread):
    # measured (seed 11, 60 rounds): 0.99 with memory, 0.51 without (0.99 and 0.43 after 120)
    with_memory = group_recall_success(memory_size=16, rounds=60)
    without = group_recall_success(memory_size=0, rounds=60)
    assert with_memory >= 0.9 and without <= 0.7, (with_memory, without)


def test_poca_with_memory_passes_the_support_check():
    from trainer.config.settings import MemorySettings, NetworkSettings, POCASettings, TrainerSettings
    from trainer.config.support import unsupported

    settings = TrainerSettings(trainer_type="poca", hyperparameters=POCASettings(),
                               network_settings=NetworkSettings(memory=MemorySettings()))
    assert unsupported(settings) == []
