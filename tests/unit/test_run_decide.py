"""One batched forward pass per behavior across simulators, and each simulator gets its own rows back."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from protos.types import (
    ActionSpec, ActionTuple, BehaviorSpec, DecisionSteps, DimensionProperty, ObservationSpec, ObservationType,
    StepResult, TerminalSteps,
)
from trainer.artifacts.timers import TimerTree
from trainer.run import RunState

SPEC = BehaviorSpec(
    (ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vec"),),
    ActionSpec(1, (3,)),
)


def decision_steps(ids):
    ids = np.asarray(ids, dtype=np.int64)
    n = len(ids)
    # each agent's observation encodes its id, so an action can be traced back to the agent
    return DecisionSteps(obs=[np.stack([ids * 1.0, -ids * 1.0], axis=1).astype(np.float32).reshape(n, 2)],
                         reward=np.zeros(n, np.float32), agent_id=ids,
                         action_mask=[np.zeros((n, 3), bool)], group_id=np.zeros(n, np.int32),
                         group_reward=np.zeros(n, np.float32))


def no_terminals():
    return TerminalSteps(obs=[np.zeros((0, 2), np.float32)], reward=np.zeros(0, np.float32),
                         interrupted=np.zeros(0, bool), agent_id=np.zeros(0, np.int64),
                         group_id=np.zeros(0, np.int32), group_reward=np.zeros(0, np.float32))


class TracingPolicy:
    """Continuous action = the agent's id / 100, discrete = id mod 3; records every call."""

    memory_size = 0

    def __init__(self):
        self.calls = []

    def act(self, obs, masks=None, deterministic=False, memories=None):
        self.calls.append((obs[0].copy(), None if masks is None else masks.copy()))
        ids = obs[0][:, 0]
        continuous = (ids / 100.0).astype(np.float32)[:, None]
        discrete = (ids.astype(np.int32) % 3)[:, None]
        return SimpleNamespace(env_actions=ActionTuple(continuous, discrete))


def test_one_forward_pass_per_behavior_and_rows_go_back_to_their_simulator():
    policy = TracingPolicy()
    runner = SimpleNamespace(spec=SPEC, trainer=SimpleNamespace(policy=policy),
                             settings=SimpleNamespace(network_settings=SimpleNamespace(deterministic=False)),
                             policy_for=lambda team: policy)  # BehaviorRunner.policy_for without self-play
    state = RunState(options=None, run_dir="", pool=None, params=None, reporter=None, status=None,
                     timers=TimerTree(), progress=None, routers=[], runners={"Ball": runner})
    ids = {0: [5, 9], 1: [], 2: [40, 41, 42], 3: [7]}
    results = [StepResult(steps={"Ball?team=0": (decision_steps(ids[e]), no_terminals())}) for e in range(4)]

    actions, decided = state.decide(results)

    assert len(policy.calls) == 1  # every deciding agent of the behavior, all simulators, one pass
    np.testing.assert_array_equal(policy.calls[0][0][:, 0], [5, 9, 40, 41, 42, 7])
    assert policy.calls[0][1].shape == (6, 3)
    assert "Ball?team=0" not in actions[1]  # nobody decided there: no actions for that simulator
    for env in (0, 2, 3):
        got = actions[env]["Ball?team=0"]
        np.testing.assert_allclose(got.continuous[:, 0], np.asarray(ids[env]) / 100.0, rtol=1e-6)
        np.testing.assert_array_equal(got.discrete[:, 0], np.asarray(ids[env]) % 3)
    (_, behavior, steps, _, masks, _), = decided
    assert behavior == "Ball?team=0"
    assert [(env, rows.start, rows.stop) for env, _, _, rows in steps] == [(0, 0, 2), (1, 2, 2), (2, 2, 5), (3, 5, 6)]


def test_an_episode_whose_terminal_step_was_dropped_for_nan_ends_in_the_run_loop():
    """The codec reports agent 9's terminal step on simulator 1 as dropped (NaN): the run loop
    counts it and ends that episode in simulator 1's tracker (a done, interrupted trajectory of
    its two rewarded decisions); simulator 0's agent 9, another episode, is untouched."""
    from trainer.protocol.codec import NON_FINITE_STAT, Dropped
    from trainer.rollout import AgentTracker

    added = []
    runner = SimpleNamespace(spec=SPEC, brain="Ball")
    reporter = SimpleNamespace(add=lambda brain, key, value, how: added.append((brain, key, value)))
    state = RunState(options=None, run_dir="", pool=None, params=None, reporter=reporter, status=None,
                     timers=TimerTree(), progress=None, routers=[], runners={"Ball": runner})
    for env in (0, 1):
        tracker = state.trackers[(env, "Ball?team=0")] = AgentTracker(SPEC, time_horizon=10)
        for step in range(3):  # three decisions: the last awaits its reward
            slots = tracker.on_decision(decision_steps([9]), lambda t: None)
            tracker.on_actions(slots, np.zeros((1, 1), np.float32), np.zeros((1, 1), np.int32),
                               np.zeros((1, 2), np.float32), None)
    lost = Dropped(count=1, deciding=0, kept=np.zeros(0, np.int64), ended=np.array([9]))
    results = [StepResult(steps={}), StepResult(steps={}, dropped={"Ball?team=0": lost})]
    trajectories: list = []
    state.count_dropped(results, trajectories)
    assert added == [("Ball", NON_FINITE_STAT, 1)]
    (got_runner, traj), = trajectories
    assert got_runner is runner and traj.done and traj.interrupted and len(traj.rewards) == 2
    assert state.trackers[(1, "Ball?team=0")].num_agents == 0
    assert state.trackers[(0, "Ball?team=0")].num_agents == 1
