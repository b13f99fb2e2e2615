"""mlagents_like_envs.base_env and .exception: mlagents_envs 1.1.0's types and classes, by hand-made values."""
from __future__ import annotations

import numpy as np
import pytest

from mlagents_like_envs import exception
from mlagents_like_envs.base_env import (
    ActionSpec,
    ActionTuple,
    BaseEnv,
    BehaviorMapping,
    BehaviorSpec,
    DecisionStep,
    DecisionSteps,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
    TerminalStep,
    TerminalSteps,
)

SPEC = BehaviorSpec((ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                    ActionSpec(1, (3, 2)))


def decision_steps() -> DecisionSteps:
    return DecisionSteps(
        obs=[np.array([[0, 1, 2], [3, 4, 5]], np.float32)], reward=np.array([0.5, -1.0], np.float32),
        agent_id=np.array([7, 9]), action_mask=[np.array([[False, True, False], [True, False, False]]),
                                                np.array([[False, False], [False, True]])],
        group_id=np.array([0, 4], np.int32), group_reward=np.array([0.0, 2.5], np.float32))


def test_action_tuple_parts_given_later_and_converted():
    empty = ActionTuple()
    assert empty.continuous is None and empty.discrete is None
    action = ActionTuple()
    action.add_discrete(np.array([[1, 2], [0, 1], [2, 0]], dtype=np.int64))
    assert action.discrete.dtype == np.int32 and action.discrete.tolist() == [[1, 2], [0, 1], [2, 0]]
    assert action.continuous.shape == (3, 0) and action.continuous.dtype == np.float32
    action.add_continuous(np.array([[0.25], [0.5], [1.0]]))  # float64 in, float32 kept
    assert action.continuous.dtype == np.float32 and action.continuous[:, 0].tolist() == [0.25, 0.5, 1.0]
    assert ActionTuple(continuous=np.zeros((2, 4))).discrete.shape == (2, 0)
    assert ActionTuple.discrete_dtype is np.int32


def test_action_spec_helpers():
    assert ActionSpec.create_continuous(3) == ActionSpec(3, ())
    assert ActionSpec.create_discrete((3, 2)) == ActionSpec(0, (3, 2))
    assert ActionSpec.create_hybrid(2, (4,)) == ActionSpec(2, (4,))
    assert ActionSpec(2, ()).is_continuous() and not ActionSpec(2, ()).is_discrete()
    assert ActionSpec(0, (2,)).is_discrete() and not ActionSpec(1, (2,)).is_discrete()
    assert ActionSpec(1, (3, 2)).discrete_size == 2
    assert str(ActionSpec(1, (3, 2))) == "Continuous: 1, Discrete: (3, 2)"
    empty = ActionSpec(1, (3, 2)).empty_action(4)
    assert empty.continuous.shape == (4, 1) and empty.discrete.shape == (4, 2)
    assert not empty.continuous.any() and not empty.discrete.any()


def test_random_action_follows_numpy_global_seed():
    spec = ActionSpec(2, (3, 5))
    np.random.seed(11)
    first = spec.random_action(500)
    np.random.seed(11)
    again = spec.random_action(500)
    assert np.array_equal(first.continuous, again.continuous) and np.array_equal(first.discrete, again.discrete)
    assert first.continuous.dtype == np.float32 and first.discrete.dtype == np.int32
    assert first.continuous.min() >= -1.0 and first.continuous.max() < 1.0
    # every option of each branch is drawn, none outside it
    assert set(first.discrete[:, 0].tolist()) == {0, 1, 2} and set(first.discrete[:, 1].tolist()) == {0, 1, 2, 3, 4}
    # the draw order is mlagents_envs': uniform continuous first, then one randint per branch
    np.random.seed(11)
    continuous = np.random.uniform(-1.0, 1.0, size=(500, 2)).astype(np.float32)
    branch0 = np.random.randint(0, 3, size=500, dtype=np.int32)
    assert np.array_equal(first.continuous, continuous) and np.array_equal(first.discrete[:, 0], branch0)


def test_decision_steps_by_agent_id():
    steps = decision_steps()
    assert len(steps) == 2 and list(steps) == [7, 9] and 9 in steps and 8 not in steps
    assert steps.agent_id_to_index == {7: 0, 9: 1}
    one = steps[9]
    assert isinstance(one, DecisionStep)
    assert one.obs[0].tolist() == [3, 4, 5] and one.reward == pytest.approx(-1.0) and one.agent_id == 9
    assert [m.tolist() for m in one.action_mask] == [[True, False, False], [False, True]]
    assert one.group_id == 4 and one.group_reward == pytest.approx(2.5)
    assert steps[np.int64(7)].reward == pytest.approx(0.5)  # numpy ids index too
    with pytest.raises(KeyError, match="agent_id 8 is not present in the DecisionSteps"):
        steps[8]


def test_terminal_steps_by_agent_id_and_empty():
    steps = TerminalSteps(obs=[np.array([[1, 1, 1]], np.float32)], reward=np.array([3.0], np.float32),
                          interrupted=np.array([True]), agent_id=np.array([5]),
                          group_id=np.array([1], np.int32), group_reward=np.array([0.0], np.float32))
    one = steps[5]
    assert isinstance(one, TerminalStep) and one.interrupted and one.reward == pytest.approx(3.0)
    with pytest.raises(KeyError, match="TerminalSteps"):
        steps[6]
    empty = TerminalSteps.empty(SPEC)
    assert len(empty) == 0 and empty.obs[0].shape == (0, 3) and list(empty) == []
    assert DecisionSteps.empty(SPEC).action_mask is None


def test_behavior_mapping_is_read_only():
    mapping = BehaviorMapping({"A?team=0": SPEC})
    assert dict(mapping) == {"A?team=0": SPEC} and len(mapping) == 1
    with pytest.raises(TypeError):
        mapping["B"] = SPEC  # type: ignore[index]


def test_base_env_is_abstract():
    with pytest.raises(TypeError):
        BaseEnv()  # type: ignore[abstract]

    class OnlyStep(BaseEnv):
        def step(self):
            pass

    with pytest.raises(TypeError, match="reset"):
        OnlyStep()  # type: ignore[abstract]


def test_exception_hierarchy():
    for name in ("UnityEnvironmentException", "UnityCommunicationException", "UnityCommunicatorStoppedException",
                 "UnityObservationException", "UnityActionException", "UnityTimeOutException",
                 "UnitySideChannelException", "UnityWorkerInUseException", "UnityPolicyException"):
        assert issubclass(getattr(exception, name), exception.UnityException)
    in_use = exception.UnityWorkerInUseException(3)
    assert "worker number 3 is still in use" in str(in_use) and in_use.worker_id == 3
