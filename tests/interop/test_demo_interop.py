""".demo files between us and the real ML-Agents 1.1.0 (its own venv and process): a file its
``write_demo`` writes reads here as its own ``demo_to_buffer`` reads it, and the stub's recorded
files read there as they read here (same spec, observations, actions, rewards, done flags)."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from protos.demo_file import read_demo
from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.demonstrations import load_demonstrations
from trainer.protocol.codec import behavior_spec_from_proto
from unity_stub_env import record_demo


def _ours(path: str):
    demo = read_demo(path)
    spec = behavior_spec_from_proto(demo.brain_parameters, demo.pairs[0].agent_info)
    return spec, load_demonstrations(path, spec, "demo_path")


def _same(reference: dict, spec: BehaviorSpec, ours) -> None:
    assert reference["observation_shapes"] == [list(o.shape) for o in spec.observation_specs]
    assert (reference["continuous"], reference["branches"]) == (spec.action_spec.continuous_size,
                                                                list(spec.action_spec.discrete_branches))
    for theirs, mine in zip(reference["obs"], ours.obs):
        np.testing.assert_array_equal(np.asarray(theirs, np.float32), mine)
    np.testing.assert_array_equal(np.asarray(reference["rewards"], np.float32), ours.rewards)
    np.testing.assert_array_equal(np.asarray(reference["done"], bool), ours.done)
    if spec.action_spec.continuous_size:
        np.testing.assert_array_equal(np.asarray(reference["continuous_actions"], np.float32), ours.continuous)
    if spec.action_spec.discrete_branches:
        np.testing.assert_array_equal(np.asarray(reference["discrete_actions"], np.int64), ours.discrete)


def test_a_file_written_by_the_reference_reads_here_as_there(run_peer, tmp_path):
    rng = np.random.default_rng(0)
    records = [{"obs": rng.normal(size=3).round(3).tolist(), "reward": float(i % 4) * 0.25, "done": i % 4 == 3,
                "max_step": i == 7, "continuous": rng.uniform(-1, 1, 2).round(3).tolist(),
                "discrete": [int(i % 3)]} for i in range(10)]
    path = str(tmp_path / "ref.demo")
    done, payload = run_peer("demo_files.py", {"mode": "write", "path": path, "records": records,
                                               "continuous": 2, "branches": [3]})
    assert done.returncode == 0, done.stderr
    done, reference = run_peer("demo_files.py", {"mode": "read", "path": path})
    assert done.returncode == 0, done.stderr
    spec, ours = _ours(path)
    assert spec == BehaviorSpec((ObservationSpec((3,), (DimensionProperty.NONE,), ObservationType.DEFAULT, ""),),
                                ActionSpec(2, (3,)))
    assert len(ours) == 9
    _same(reference, spec, ours)


@pytest.mark.parametrize("task, steps", [("basic", 40), ("ball3d", 300)])
def test_the_stubs_recordings_read_there_as_here(run_peer, tmp_path, task, steps):
    folder = tmp_path / "demos"
    record_demo.record(task, str(folder / "a.demo"), "scripted", steps=steps, seed=1)
    # a second, identical file: the reference reads a folder in os.listdir order, we in name order
    shutil.copy(folder / "a.demo", folder / "b.demo")
    for path in (str(folder / "a.demo"), str(folder)):  # one file, and a folder of two
        done, reference = run_peer("demo_files.py", {"mode": "read", "path": path})
        assert done.returncode == 0, done.stderr
        spec, ours = _ours(path)
        assert len(ours) == len(reference["rewards"]) > 0
        _same(reference, spec, ours)
