"""UpdateBuffer: appending trajectories' arrays and concatenating them at update time."""
from __future__ import annotations

import numpy as np
import pytest

from trainer.common.trajectory import Trajectory
from trainer.ppo.update_buffer import UpdateBuffer


def test_append_concatenate_clear():
    buffer = UpdateBuffer()
    buffer.append({"a": np.array([1.0, 2.0]), "b": np.zeros((2, 3))})
    buffer.append({"a": np.array([3.0]), "b": np.ones((1, 3))})
    assert len(buffer) == 3
    data = buffer.concatenated()
    np.testing.assert_array_equal(data["a"], [1.0, 2.0, 3.0])
    assert data["b"].shape == (3, 3) and data["b"][2].tolist() == [1.0, 1.0, 1.0]
    buffer.clear()
    assert len(buffer) == 0 and buffer.concatenated() == {}


def test_mismatched_lengths_or_fields_are_refused():
    buffer = UpdateBuffer()
    with pytest.raises(ValueError, match="disagree on length"):
        buffer.append({"a": np.zeros(2), "b": np.zeros(3)})
    buffer.append({"a": np.zeros(2)})
    with pytest.raises(ValueError, match="differ"):
        buffer.append({"c": np.zeros(2)})


def test_trajectory_length():
    traj = Trajectory(obs=[np.zeros((4, 2))], next_obs=[np.zeros(2)], rewards=np.zeros(4),
                      continuous_actions=np.zeros((4, 1)), discrete_actions=np.zeros((4, 0)),
                      log_probs=np.zeros((4, 1)), action_masks=None, done=False, interrupted=False)
    assert len(traj) == 4
