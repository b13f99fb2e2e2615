"""Experience assembly against a hand-written three-agent schedule (time_horizon 3)."""
import numpy as np
import pytest

from protos.types import (
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
    assert eps.group_rewards == [0.0, 0.5, 0.0]  # kept apart, for Policy/Extrinsic Reward
    assert tr.num_agents == 0


def test_an_episode_whose_last_step_was_dropped_for_nan_ends_interrupted_without_its_pending_decision():
    """The codec dropped agent 5's terminal step (NaN): the decision awaiting its reward is
    discarded, the two experiences before it go out done + interrupted with that decision's
    observation as next_obs, the episode leaves no slot and no episode statistics; agent 9 (two
    decisions) and agent 11 (one pending decision, no experience) are handled alike."""
    out = []
    tr = AgentTracker(SPEC, time_horizon=5)
    for step, (r5, r9) in enumerate([(0.0, 0.0), (1.0, 2.0), (3.0, 4.0)]):  # first rewards dropped
        slots = tr.on_decision(ds([5, 9], [[0, step], [1, step]], [r5, r9]), out.append)
        act(tr, slots, [step, step])
    act(tr, tr.on_decision(ds([11], [[2, 0]], [0.0]), out.append), [2])
    before = tr.num_agents
    assert tr.on_lost_terminal(np.array([5, 11, 77]), out.append) == 2  # 77: never seen, ignored
    assert tr.num_agents == before - 2 and len(out) == 1
    t5 = out[0]
    np.testing.assert_array_equal(t5.obs[0], [[0, 0], [0, 1]])  # step 2's decision discarded
    np.testing.assert_array_equal(t5.next_obs[0], [0, 2])  # ...its observation bootstraps
    np.testing.assert_allclose(t5.rewards, [1.0, 3.0])
    np.testing.assert_array_equal(t5.discrete_actions[:, 0], [0, 1])
    assert t5.done and t5.interrupted and t5.episode[1] == 5
    assert tr.drain_episodes().rewards == []  # an unknown return is not reported
    # agent 9 goes on untouched: its next reward (5) pairs with its step-2 action
    act(tr, tr.on_decision(ds([9], [[1, 3]], [5.0]), out.append), [0])
    tr.on_terminal(ts([9], [[1, 4]], [6.0], [False]), out.append)
    assert len(out) == 2 and out[1].done and not out[1].interrupted
    np.testing.assert_allclose(out[1].rewards, [2.0, 4.0, 5.0, 6.0])
    assert tr.drain_episodes().rewards == [2.0 + 4.0 + 5.0 + 6.0]
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


# ------------------------------------------------------------------ against a per-agent oracle
HYBRID = BehaviorSpec(
    (ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "a"),
     ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "b")),
    ActionSpec(2, (3, 2)),
)


class Oracle:
    """The module's rules, one Python list per agent, as ML-Agents' AgentProcessor keeps them."""

    def __init__(self, horizon):
        self.horizon, self.agents, self.out, self.episodes = horizon, {}, [], []

    def _close(self, agent, reward, ep_reward, ep_group_reward):
        state = self.agents[agent]
        if state["pending"] is not None:
            state["rows"].append((*state["pending"], reward))
            state["pending"] = None
            state["ep"][0] += ep_reward
            state["ep"][1] += 1
            state["ep"][2] += ep_group_reward

    def _emit(self, agent, next_obs, done, interrupted):
        rows = self.agents[agent]["rows"]
        if rows:
            # rows: (obs, continuous, discrete, log-probs, mask, reward)
            self.out.append(([np.stack([r[0][i] for r in rows]) for i in range(2)], [o.copy() for o in next_obs],
                             np.array([r[5] for r in rows], np.float32),
                             *(np.stack([r[j] for r in rows]) for j in (1, 2, 3, 4)), done, interrupted))
        self.agents[agent]["rows"] = []

    def terminal(self, t):
        for k, agent in enumerate(t.agent_id.tolist()):
            if agent not in self.agents:
                continue
            self._close(agent, t.reward[k] + t.group_reward[k], float(t.reward[k]), float(t.group_reward[k]))
            self._emit(agent, [o[k] for o in t.obs], True, bool(t.interrupted[k]))
            self.episodes.append(tuple(self.agents.pop(agent)["ep"]))

    def decision(self, d):
        for k, agent in enumerate(d.agent_id.tolist()):
            state = self.agents.setdefault(agent, {"pending": None, "rows": [], "ep": [0.0, 0, 0.0]})
            had = state["pending"] is not None
            self._close(agent, d.reward[k] + d.group_reward[k], float(d.reward[k]), float(d.group_reward[k]))
            if had and len(state["rows"]) >= self.horizon:
                self._emit(agent, [o[k] for o in d.obs], False, False)
            state["obs"] = [o[k].copy() for o in d.obs]

    def actions(self, agents, cont, disc, logp, mask):
        for k, agent in enumerate(agents):
            self.agents[agent]["pending"] = (self.agents[agent]["obs"], cont[k], disc[k], logp[k], mask[k])


@pytest.mark.parametrize("mostly_one", [False, True])
def test_random_schedules_give_what_a_per_agent_list_gives(mostly_one):
    """Agents that start, skip decisions, hit the time horizon, finish (done or interrupted),
    terminate without ever deciding, and more agents than the initial capacity. ``mostly_one``:
    most messages carry a single deciding agent (the tracker's scalar path)."""
    rng = np.random.default_rng(11)
    for horizon in (1, 2, 5):
        tracker, oracle = AgentTracker(HYBRID, time_horizon=horizon, capacity=2), Oracle(horizon)
        emitted, stats, next_id, alive = [], [], 0, []
        for step in range(300):
            if rng.random() < 0.3 or not alive:  # new agents join
                alive += list(range(next_id, next_id + int(rng.integers(1, 4))))
                next_id = alive[-1] + 1
            ending = [a for a in alive if rng.random() < 0.1]
            if rng.random() < 0.05:
                ending.append(next_id + 1000)  # an agent that ends before it ever decided
            if ending:
                n = len(ending)
                t = TerminalSteps(obs=[rng.normal(size=(n, 2)).astype(np.float32), rng.normal(size=(n, 3)).astype(np.float32)],
                                  reward=rng.normal(size=n).astype(np.float32), interrupted=rng.random(n) < 0.5,
                                  agent_id=np.array(ending, np.int64), group_id=np.zeros(n, np.int32),
                                  group_reward=rng.normal(size=n).astype(np.float32))
                tracker.on_terminal(t, emitted.append)
                oracle.terminal(t)
                alive = [a for a in alive if a not in ending]
            deciding = [a for a in alive if rng.random() < 0.8]  # some skip this decision
            if mostly_one and rng.random() < 0.8:
                deciding = deciding[-1:]
            n = len(deciding)
            d = DecisionSteps(obs=[rng.normal(size=(n, 2)).astype(np.float32), rng.normal(size=(n, 3)).astype(np.float32)],
                              reward=rng.normal(size=n).astype(np.float32), agent_id=np.array(deciding, np.int64),
                              action_mask=None, group_id=np.zeros(n, np.int32),
                              group_reward=(rng.normal(size=n) * (rng.random(n) < 0.3)).astype(np.float32))
            slots = tracker.on_decision(d, emitted.append)
            oracle.decision(d)
            cont = rng.normal(size=(n, 2)).astype(np.float32)
            disc = rng.integers(0, 2, size=(n, 2)).astype(np.int32)
            logp = rng.normal(size=(n, 4)).astype(np.float32)
            mask = rng.random((n, 5)) < 0.3
            tracker.on_actions(slots, cont, disc, logp, mask)
            oracle.actions(deciding, cont, disc, logp, mask)
            episodes = tracker.drain_episodes()
            stats += list(zip(episodes.rewards, episodes.lengths, episodes.group_rewards))
        assert len(emitted) == len(oracle.out) > 50
        assert stats == oracle.episodes and len(stats) > 20
        for traj, (obs, next_obs, rewards, cont, disc, logp, mask, done, interrupted) in zip(emitted, oracle.out):
            for got, want in zip(traj.obs + traj.next_obs, obs + next_obs):
                np.testing.assert_array_equal(got, want)
            np.testing.assert_array_equal(traj.rewards, rewards)
            np.testing.assert_array_equal(traj.continuous_actions, cont)
            np.testing.assert_array_equal(traj.discrete_actions, disc)
            np.testing.assert_array_equal(traj.log_probs, logp)
            np.testing.assert_array_equal(traj.action_masks, mask)
            assert (traj.done, traj.interrupted) == (done, interrupted)
            assert len(traj) <= horizon or done


def test_slots_follow_episode_ids_in_any_order_and_are_reused():
    tracker = AgentTracker(SPEC, time_horizon=3, capacity=2)
    first = tracker._slots(np.array([70, 5, 300]))  # unsorted, more than the capacity
    assert len(set(first.tolist())) == 3 and tracker.num_agents == 3
    # known ids in another order and a subset map to the same slots, whatever the order
    assert tracker._slots(np.array([300, 70])).tolist() == [first[2], first[0]]
    assert tracker._slots(np.array([5, 70, 300])).tolist() == [first[1], first[0], first[2]]
    # 5's episode ends: its slot is freed and the next new episode (id 900) takes it
    act(tracker, tracker.on_decision(ds([70, 5, 300], np.zeros(6), [0, 0, 0]), lambda t: None), [0, 1, 2])
    tracker.on_terminal(ts([5], [0, 0], [1.0], [False]), lambda t: None)
    assert tracker.num_agents == 2
    mixed = tracker._slots(np.array([900, 300, 70]))
    assert mixed.tolist() == [first[1], first[2], first[0]]
    # an id seen again after its episode ended is a new agent (fresh slot state), not a stale entry
    tracker.on_terminal(ts([900], [0, 0], [1.0], [False]), lambda t: None)
    tracker._slots(np.array([900]))
    assert tracker.num_agents == 3 and tracker.length[first[1]] == 0
    tracker.drop_all()
    assert tracker.num_agents == 0 and len(set(tracker._slots(np.array([1, 2, 3])).tolist())) == 3
