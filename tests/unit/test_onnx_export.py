"""ONNX export checked with onnxruntime against the contract of docs/outputs.md, "The ONNX model" and the torch policy."""
from __future__ import annotations

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from protos.types import (
    ActionSpec,
    BehaviorSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
)
from trainer.artifacts.onnx_export import export_policy
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.policy import Policy

HYPER = PPOHyperparams(hidden_units=16, num_layers=2, normalize=True)
CONTINUOUS_OUTPUTS = ["continuous_actions", "continuous_action_output_shape", "deterministic_continuous_actions"]
DISCRETE_OUTPUTS = ["discrete_actions", "discrete_action_output_shape", "deterministic_discrete_actions"]


def vector(size: int) -> ObservationSpec:
    return ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector")


def camera(shape: tuple[int, int, int]) -> ObservationSpec:
    return ObservationSpec(shape, (DimensionProperty.NONE,) * 3, ObservationType.DEFAULT, "camera")


def export(tmp_path, spec: BehaviorSpec, hyper: PPOHyperparams = HYPER):
    policy = Policy(spec, hyper, seed=0)
    # give the normalisers non-trivial statistics so the in-graph normalisation is exercised
    rng = np.random.default_rng(0)
    batch = [torch.from_numpy(rng.normal(2.0, 3.0, size=(50, *o.shape)).astype(np.float32))
             for o in spec.observation_specs]
    policy.actor.update_normalization(batch)
    path = tmp_path / "Ball.onnx"
    export_policy(policy, path)
    return policy, onnx.load(str(path)), ort.InferenceSession(str(path))


def random_inputs(spec: BehaviorSpec, n: int, seed: int = 1) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.normal(1.0, 4.0, size=(n, *o.shape)).astype(np.float32) for o in spec.observation_specs]


def dims(value_info) -> list:
    return [d.dim_param or d.dim_value for d in value_info.type.tensor_type.shape.dim]


def torch_deterministic(policy: Policy, obs: list[np.ndarray], mask: np.ndarray | None):
    out = policy.act(obs, mask, deterministic=True)
    return out.env_actions.continuous, out.discrete


def test_continuous_policy(tmp_path):
    spec = BehaviorSpec((vector(5), vector(2)), ActionSpec(3, ()))
    policy, model, session = export(tmp_path, spec)
    assert model.opset_import[0].version == 9 and model.opset_import[0].domain == ""
    assert [i.name for i in model.graph.input] == ["obs_0", "obs_1"]  # no action_masks
    assert dims(model.graph.input[0]) == ["batch", 5]
    assert [o.name for o in model.graph.output] == ["version_number", "memory_size"] + CONTINUOUS_OUTPUTS
    assert dims(model.graph.output[2]) == ["batch", 3]
    assert {"RandomNormalLike", "Clip", "Sigmoid", "Gemm"} <= {n.op_type for n in model.graph.node}
    obs = random_inputs(spec, 7)
    version, memory, sampled, shape, deterministic = session.run(None, {"obs_0": obs[0], "obs_1": obs[1]})
    assert version.dtype == np.float32 and version.tolist() == [3.0]
    assert memory.tolist() == [0.0] and shape.dtype == np.float32 and shape.tolist() == [3.0]
    assert sampled.shape == (7, 3) and sampled.dtype == np.float32 and np.abs(sampled).max() <= 1.0
    expected, _ = torch_deterministic(policy, obs, None)
    np.testing.assert_allclose(deterministic, expected, atol=1e-5)


def test_discrete_policy_with_masks(tmp_path):
    spec = BehaviorSpec((vector(4),), ActionSpec(0, (3, 2)))
    policy, model, session = export(tmp_path, spec)
    assert [i.name for i in model.graph.input] == ["obs_0", "action_masks"]
    assert dims(model.graph.input[1]) == ["batch", 5]
    assert model.graph.input[1].type.tensor_type.elem_type == onnx.TensorProto.FLOAT
    assert [o.name for o in model.graph.output] == ["version_number", "memory_size"] + DISCRETE_OUTPUTS
    assert model.graph.output[2].type.tensor_type.elem_type == onnx.TensorProto.INT64
    assert dims(model.graph.output[2]) == ["batch", 2]
    assert "Multinomial" in {n.op_type for n in model.graph.node}
    n = 256
    obs = random_inputs(spec, n)
    allowed = np.ones((n, 5), np.float32)
    allowed[:, 1] = 0.0  # branch 0, option 1 is masked for every agent
    allowed[:, 3] = 0.0  # branch 1, option 0 masked: only option 1 remains
    _, _, sampled, shape, deterministic = session.run(None, {"obs_0": obs[0], "action_masks": allowed})
    assert shape.shape == (1, 2) and shape.dtype == np.float32 and shape.tolist() == [[3.0, 2.0]]
    assert sampled.dtype == np.int64 and deterministic.dtype == np.int64
    _, expected = torch_deterministic(policy, obs, allowed == 0.0)
    np.testing.assert_array_equal(deterministic, expected)
    seen = set()
    for _ in range(4):  # 4 x 256 = 1024 samples of the masked branch
        sampled = session.run(["discrete_actions"], {"obs_0": obs[0], "action_masks": allowed})[0]
        assert not np.any(sampled[:, 0] == 1)
        assert np.all(sampled[:, 1] == 1)
        seen |= set(sampled[:, 0].tolist())
    assert seen == {0, 2}


def test_hybrid_visual_policy(tmp_path):
    spec = BehaviorSpec((camera((3, 36, 36)), vector(4)), ActionSpec(2, (3,)))
    policy, model, session = export(tmp_path, spec, PPOHyperparams(hidden_units=16, num_layers=1,
                                                                   vis_encode_type="simple", normalize=True))
    assert [i.name for i in model.graph.input] == ["obs_0", "obs_1", "action_masks"]
    assert dims(model.graph.input[0]) == ["batch", 3, 36, 36]
    assert [o.name for o in model.graph.output] == (
        ["version_number", "memory_size"] + CONTINUOUS_OUTPUTS + DISCRETE_OUTPUTS)
    assert {"Conv", "LeakyRelu"} <= {n.op_type for n in model.graph.node}
    n = 9
    obs = random_inputs(spec, n)
    obs[0] = np.random.default_rng(2).random((n, 3, 36, 36), dtype=np.float32)
    allowed = np.ones((n, 3), np.float32)
    allowed[:, 0] = 0.0
    outputs = dict(zip([o.name for o in model.graph.output],
                       session.run(None, {"obs_0": obs[0], "obs_1": obs[1], "action_masks": allowed})))
    continuous, discrete = torch_deterministic(policy, obs, allowed == 0.0)
    np.testing.assert_allclose(outputs["deterministic_continuous_actions"], continuous, atol=1e-5)
    np.testing.assert_array_equal(outputs["deterministic_discrete_actions"], discrete)
    assert outputs["continuous_actions"].shape == (n, 2) and outputs["discrete_actions"].shape == (n, 1)
    assert outputs["discrete_action_output_shape"].tolist() == [[3.0]]


def test_export_is_atomic_and_leaves_no_temp_files(tmp_path, monkeypatch):
    spec = BehaviorSpec((vector(2),), ActionSpec(1, ()))
    policy = Policy(spec, HYPER, seed=0)
    path = tmp_path / "Ball.onnx"
    path.write_bytes(b"previous model")
    import trainer.artifacts.onnx_export as module

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(module.os, "fsync", broken)
    with pytest.raises(RuntimeError):
        export_policy(policy, path)
    assert path.read_bytes() == b"previous model"
    assert [p.name for p in tmp_path.iterdir()] == ["Ball.onnx"]
