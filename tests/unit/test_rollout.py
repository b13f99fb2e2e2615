"""Experience assembly against a hand-written three-agent schedule (time_horizon 3)."""
import numpy as np

from trainer.protocol.types import (
    ActionSpec, BehaviorSpec, DecisionSteps, DimensionProperty, ObservationSpec, ObservationType, TerminalSteps,
)
from trainer.rollout import AgentTracker, concat_masks

SPEC = BehaviorSpec(
    (ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vec"),),
    ActionSpec(0, (3,)),
)


def ds(ids, obs, reward, group_reward=None, mask=None):
    n = len(ids)
    return DecisionSteps(
        obs=[np.array(obs, dtype=np.float32).reshape(n, 2)],
        reward=np.array(reward, dtype=np.float32),
        agent_id=np.array(ids, dtype=np.int64),
        action_mask=mask,
        group_id=np.zeros(n, np.int32),
        group_reward=np.array(group_reward if group_reward is not None else [0.0] * n, dtype=np.float32),
    )


def ts(ids, obs, reward, interrupted):
    n = len(ids)
    return TerminalSteps(
        obs=[np.array(obs, dtype=np.float32).reshape(n, 2)],
        reward=np.array(reward, dtype=np.float32),
        interrupted=np.array(interrupted, dtype=bool),
        agent_id=np.array(ids, dtype=np.int64),
        group_id=np.zeros(n, np.int32),
        group_reward=np.zeros(n, np.float32),
    )


def act(tracker, slots, disc):
    n = len(slots)
    tracker.on_actions(slots, np.zeros((n, 0), np.float32), np.array(disc, np.int32).reshape(n, 1),
                       np.array(disc, np.float32).reshape(n, 1) * -0.1, None)


def test_schedule_pairs_rewards_cuts_and_terminates():
    out = []
    tr = AgentTracker(SPEC, time_horizon=3, capacity=1)  # capacity 1 forces growth
    # step 0: first decisions; their rewards (0.5, 0.7) are dropped
    slots = tr.on_decision(ds([5, 9], [[0, 0], [1, 1]], [0.5, 0.7]), out.append)
    act(tr, slots, [1, 2])
    # step 1: rewards 1 and 2 (+ group reward 0.5 for agent 9)
    slots = tr.on_decision(ds([5, 9], [[0, 1], [1, 2]], [1, 2], [0, 0.5]), out.append)
    act(tr, slots, [0, 1])
    assert out == []
    # step 2: agent 5 ends (true terminal), agent 9 goes on, agent 11 starts (reward 9 dropped)
    tr.on_terminal(ts([5], [[0, 2]], [3], [False]), out.append)
    slots = tr.on_decision(ds([9, 11], [[1, 3], [2, 0]], [4, 9]), out.append)
    act(tr, slots, [2, 1])
    assert len(out) == 1
    t5 = out[0]
    np.testing.assert_array_equal(t5.obs[0], [[0, 0], [0, 1]])
    np.testing.assert_array_equal(t5.next_obs[0], [0, 2])
    np.testing.assert_allclose(t5.rewards, [1, 3])
    np.testing.assert_array_equal(t5.discrete_actions[:, 0], [1, 0])
    np.testing.assert_allclose(t5.log_probs[:, 0], [-0.1, 0.0])
    assert t5.done and not t5.interrupted
    # step 3: agent 9 reaches time_horizon 3 → cut, not done, next_obs = current obs
    slots = tr.on_decision(ds([9, 11], [[1, 4], [2, 1]], [5, 6]), out.append)
    assert len(out) == 2
    t9 = out[1]
    np.testing.assert_array_equal(t9.obs[0], [[1, 1], [1, 2], [1, 3]])
    np.testing.assert_array_equal(t9.next_obs[0], [1, 4])
    np.testing.assert_allclose(t9.rewards, [2.5, 4, 5])
    np.testing.assert_array_equal(t9.discrete_actions[:, 0], [2, 1, 2])
    assert not t9.done
    # agent 9's next trajectory starts empty; agent 11 has one experience (reward 6)
    act(tr, slots, [0, 0])
    tr.on_terminal(ts([9, 11], [[1, 5], [2, 2]], [7, 8], [True, False]), out.append)
    t9b, t11 = out[2], out[3]
    np.testing.assert_allclose(t9b.rewards, [7])
    np.testing.assert_array_equal(t9b.obs[0], [[1, 4]])
    assert t9b.done and t9b.interrupted
    np.testing.assert_allclose(t11.rewards, [6, 8])
    eps = tr.drain_episodes()
    # env reward only (group reward excluded), first-decision rewards dropped
    assert eps.rewards == [4.0, 2 + 4 + 5 + 7, 6 + 8]
    assert eps.lengths == [2, 4, 2]
    assert tr.num_agents == 0


def test_terminal_before_first_decision_is_ignored_and_drop_all_forgets():
    out = []
    tr = AgentTracker(SPEC, time_horizon=5)
    tr.on_terminal(ts([3], [[0, 0]], [1], [False]), out.append)
    assert out == [] and tr.drain_episodes().rewards == []
    slots = tr.on_decision(ds([1], [[0, 0]], [0]), out.append)
    act(tr, slots, [1])
    tr.drop_all()
    slots = tr.on_decision(ds([1], [[0, 1]], [2]), out.append)  # same id after a reset: new episode
    assert tr.pending[slots].tolist() == [False]
    assert out == []


def test_masks_are_concatenated_and_stored():
    spec = BehaviorSpec(SPEC.observation_specs, ActionSpec(0, (2, 3)))
    d = ds([1], [[0, 0]], [0], mask=[np.array([[False, True]]), np.array([[True, False, False]])])
    m = concat_masks(d, spec.action_spec.discrete_branches)
    assert m.tolist() == [[False, True, True, False, False]]
    assert concat_masks(ds([1], [[0, 0]], [0]), (2,)).tolist() == [[False, False]]
    out = []
    tr = AgentTracker(spec, time_horizon=1)
    slots = tr.on_decision(d, out.append)
    tr.on_actions(slots, np.zeros((1, 0), np.float32), np.array([[0, 1]], np.int32), np.zeros((1, 2), np.float32), m)
    tr.on_decision(ds([1], [[0, 1]], [1]), out.append)
    assert out[0].action_masks.tolist() == [[False, True, True, False, False]]
