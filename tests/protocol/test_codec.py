"""Codec: hand-built protos in, exact numpy values out (expected values written by hand)."""
from __future__ import annotations

import struct

import numpy as np
import pytest
from PIL import PngImagePlugin

from protos.communicator_objects import (
    agent_action_pb2,
    brain_parameters_pb2,
    command_pb2,
    observation_pb2,
    unity_message_pb2,
    unity_output_pb2,
)
from protos.errors import ProtocolError
from protos.types import (
    ActionSpec,
    ActionTuple,
    BehaviorSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
)
from protos.versions import all_true_capabilities
from tests.protocol import reference
from tests.protocol.conftest import Message, agent_info, brain_params, png_bytes
from trainer.errors import UnityVersionError
from trainer.protocol import codec
from trainer.protocol.png import split_concatenated_pngs

P = DimensionProperty


def output_with(infos: dict, params=()) -> unity_output_pb2.UnityOutputProto:
    out = unity_output_pb2.UnityOutputProto()
    for name, agent_infos in infos.items():
        out.rl_output.agentInfos[name].value.extend(agent_infos)
    out.rl_initialization_output.brain_parameters.extend(params)
    return unity_output_pb2.UnityOutputProto.FromString(out.SerializeToString())


def visual_info(agent_id: int, shape, data: bytes, mapping=(), compressed=True):
    info = agent_info(agent_id)
    obs = info.observations.add()
    obs.shape.extend(shape)
    if compressed:
        obs.compression_type = observation_pb2.PNG
        obs.compressed_data = data
    obs.compressed_channel_mapping.extend(mapping)
    return info


# ------------------------------------------------------------------ float observations, splitting
def test_float_observations_are_stacked_and_split_by_done_keeping_order():
    infos = [
        agent_info(3, obs=[[1, 2, 3], [10, 20]], reward=0.5),
        agent_info(4, obs=[[4, 5, 6], [30, 40]], reward=-1.0, done=True, max_step=True),
        agent_info(5, obs=[[7, 8, 9], [50, 60]], reward=0.25),
        agent_info(6, obs=[[0, 0, 1], [70, 80]], reward=2.0, done=True),
    ]
    result = codec.decode_rl_output(output_with({"Ball?team=0": infos}, [brain_params("Ball?team=0", 2)]), {})
    decision, terminal = result.steps["Ball?team=0"]
    assert decision.obs[0].dtype == np.float32
    np.testing.assert_array_equal(decision.obs[0], [[1, 2, 3], [7, 8, 9]])
    np.testing.assert_array_equal(decision.obs[1], [[10, 20], [50, 60]])
    np.testing.assert_array_equal(decision.reward, [0.5, 0.25])
    np.testing.assert_array_equal(decision.agent_id, [3, 5])
    assert decision.action_mask is None
    np.testing.assert_array_equal(terminal.obs[0], [[4, 5, 6], [0, 0, 1]])
    np.testing.assert_array_equal(terminal.obs[1], [[30, 40], [70, 80]])
    np.testing.assert_array_equal(terminal.reward, [-1.0, 2.0])
    np.testing.assert_array_equal(terminal.agent_id, [4, 6])
    # done + max_step_reached = interrupted (bootstrap); done alone = true terminal
    np.testing.assert_array_equal(terminal.interrupted, [True, False])


def test_rank2_variable_length_observation_is_reshaped_row_major():
    info = agent_info(1)
    obs = info.observations.add()
    obs.shape.extend([2, 3])
    obs.dimension_properties.extend([P.VARIABLE_SIZE, P.NONE])
    obs.float_data.data.extend([1, 2, 3, 4, 5, 6])
    result = codec.decode_rl_output(output_with({"E": [info]}, [brain_params("E", 1)]), {})
    spec = result.specs["E"]
    assert spec.observation_specs[0].dimension_property == (P.VARIABLE_SIZE, P.NONE)
    np.testing.assert_array_equal(result.steps["E"][0].obs[0], [[[1, 2, 3], [4, 5, 6]]])


def test_large_float_observation_survives_multibyte_length_prefix():
    # 40 floats = 160 bytes: the packed length needs a 2-byte varint
    values = [float(i) / 4 for i in range(40)]
    infos = [agent_info(i, obs=[[v + i for v in values]]) for i in range(3)]
    result = codec.decode_rl_output(output_with({"B": infos}, [brain_params("B", 1)]), {})
    expected = np.array([[v + i for v in values] for i in range(3)], dtype=np.float32)
    np.testing.assert_array_equal(result.steps["B"][0].obs[0], expected)


def test_agent_with_wrong_observation_size_is_a_protocol_error_naming_the_agent():
    infos = [agent_info(1, obs=[[1, 2, 3]]), agent_info(9, obs=[[1, 2]])]
    with pytest.raises(ProtocolError, match="agent id 9"):
        codec.decode_rl_output(output_with({"B": infos}, [brain_params("B", 1)]), {})


def test_group_ids_and_group_rewards():
    infos = [
        agent_info(1, obs=[[0]], group_id=7, group_reward=1.5),
        agent_info(2, obs=[[0]], group_id=0, group_reward=0.0, done=True),
        agent_info(3, obs=[[0]], group_id=7, group_reward=-0.5),
    ]
    decision, terminal = codec.decode_rl_output(output_with({"B": infos}, [brain_params("B", 1)]), {}).steps["B"]
    np.testing.assert_array_equal(decision.group_id, [7, 7])
    np.testing.assert_array_equal(decision.group_reward, [1.5, -0.5])
    np.testing.assert_array_equal(terminal.group_id, [0])
    np.testing.assert_array_equal(terminal.group_reward, [0.0])


@pytest.mark.parametrize("agents", [3, 70])  # the protobuf path and the records path
@pytest.mark.parametrize(
    "kwargs",
    [dict(reward=float("nan")), dict(group_reward=float("inf")), dict(obs=[[1.0, float("nan")]]),
     dict(obs=[[float("-inf"), 0.0]], done=True)],
)
def test_agents_with_nan_or_inf_are_left_out_and_counted(kwargs, agents):
    """They never reach the networks; the simulator is still owed their actions (by position)."""
    kwargs.setdefault("obs", [[1.0, 2.0]])
    infos = [agent_info(k, obs=[[float(k), 0.0]]) for k in range(agents - 2)]
    infos[1:1] = [agent_info(42, **kwargs)]
    infos.append(agent_info(7, obs=[[7.0, 7.0]], done=True))
    message = Message()
    message.header.status = 200
    message.unity_output.CopyFrom(output_with({"Walker?team=0": infos}, [brain_params("Walker?team=0", 1)]))
    result = codec.decode_message(message.SerializeToString(), {}).result
    decision, terminal = result.steps["Walker?team=0"]
    assert decision.agent_id.tolist() == list(range(agents - 2)) and terminal.agent_id.tolist() == [7]
    assert np.isfinite(decision.obs[0]).all() and np.isfinite(decision.reward).all()
    dropped = result.dropped["Walker?team=0"]
    deciding = agents - 2 + (0 if kwargs.get("done") else 1)
    assert (dropped.count, dropped.deciding) == (1, deciding)
    assert dropped.kept.tolist() == [p for p in range(deciding) if p != 1 or kwargs.get("done")]
    assert dropped.ended.tolist() == ([42] if kwargs.get("done") else [])  # its episode ends unseen


# ------------------------------------------------------------------ action masks
def test_action_masks_split_per_branch_true_means_masked():
    infos = [
        agent_info(1, obs=[[0]], mask=[False, True, True, False, False]),
        agent_info(2, obs=[[0]], mask=[True, True], done=True),  # terminal: its mask is never used
        agent_info(4, obs=[[0]]),  # empty: nothing masked
        agent_info(5, obs=[[0]], mask=[False, False, False, True, True]),
    ]
    decision, _ = codec.decode_rl_output(output_with({"D": infos}, [brain_params("D", 0, (2, 3))]), {}).steps["D"]
    branch0, branch1 = decision.action_mask
    np.testing.assert_array_equal(branch0, [[False, True], [False, False], [False, False]])
    np.testing.assert_array_equal(branch1, [[True, False, False], [False, False, False], [False, True, True]])
    assert branch0.dtype == bool


@pytest.mark.parametrize("agents", [1, 70])  # the protobuf path and the records path
@pytest.mark.parametrize("mask, fault", [
    ([True, False], "action mask of 2 entries; its discrete branches have 5 options"),
    ([False] * 6, "action mask of 6 entries"),
    ([True, True, False, False, False], "masked every action of discrete branch 0 (size 2)"),
    ([False, False, True, True, True], "masked every action of discrete branch 1 (size 3)"),
])
def test_a_mask_of_the_wrong_length_or_masking_a_whole_branch_is_refused_naming_the_agent(agents, mask, fault):
    infos = [agent_info(i, obs=[[0.5]]) for i in range(agents - 1)] + [agent_info(99, obs=[[0.5]], mask=mask)]
    message = Message()
    message.header.status = 200
    message.unity_output.CopyFrom(output_with({"D": infos}, [brain_params("D", 0, (2, 3))]))
    with pytest.raises(ProtocolError, match=r"Agent id 99 .*" if "masked every" not in fault else "Agent id 99") as error:
        codec.decode_message(message.SerializeToString(), {})
    assert fault in str(error.value)


# ------------------------------------------------------------------ behaviors, specs
def test_behaviors_appearing_mid_run_and_missing_behaviors():
    known = {"A": BehaviorSpec((ObservationSpec((1,), (P.NONE,), ObservationType.DEFAULT, "a"),), ActionSpec(1, ()))}
    out = output_with({"B": [agent_info(1, obs=[[1, 2]])]}, [brain_params("B", 0, (3,))])
    result = codec.decode_rl_output(out, known)
    assert set(result.specs) == {"B"}  # only specs first seen in this message
    assert result.specs["B"].action_spec == ActionSpec(0, (3,))
    assert result.specs["B"].observation_specs[0].shape == (2,)
    assert set(known) == {"A"}  # not modified
    a_decision, a_terminal = result.steps["A"]
    assert len(a_decision) == 0 and len(a_terminal) == 0 and a_decision.obs[0].shape == (0, 1)
    np.testing.assert_array_equal(result.steps["B"][0].obs[0], [[1, 2]])


def test_brain_parameters_without_agent_infos_register_nothing():
    out = output_with({}, [brain_params("Later", 1)])
    assert codec.decode_rl_output(out, {}).specs == {}


def test_agents_of_an_unknown_behavior_are_a_protocol_error():
    with pytest.raises(ProtocolError, match="Ghost"):
        codec.decode_rl_output(output_with({"Ghost": [agent_info(1, obs=[[0]])]}), {})


def test_behavior_spec_observations_and_empty_dimension_properties():
    info = agent_info(1)
    vec = info.observations.add()
    vec.shape.append(4)
    vec.name = "VectorSensor"
    vec.observation_type = observation_pb2.GOAL_SIGNAL
    cam = info.observations.add()
    cam.shape.extend([3, 8, 6])
    cam.dimension_properties.extend([P.NONE, P.TRANSLATIONAL_EQUIVARIANCE, P.TRANSLATIONAL_EQUIVARIANCE])
    cam.name = "Camera"
    spec = codec.behavior_spec_from_proto(brain_params("B", 2, (3, 2)), info)
    assert spec.action_spec == ActionSpec(2, (3, 2))
    assert spec.observation_specs == (
        ObservationSpec((4,), (P.UNSPECIFIED,), ObservationType.GOAL_SIGNAL, "VectorSensor"),
        ObservationSpec((3, 8, 6), (P.NONE, P.TRANSLATIONAL_EQUIVARIANCE, P.TRANSLATIONAL_EQUIVARIANCE), ObservationType.DEFAULT, "Camera"),
    )


@pytest.mark.parametrize(
    "space_type, sizes, expected",
    [(1, [4], ActionSpec(4, ())), (0, [3, 2], ActionSpec(0, (3, 2)))],
)
def test_deprecated_action_fields_are_used_when_action_spec_is_empty(space_type, sizes, expected):
    bp = brain_parameters_pb2.BrainParametersProto(brain_name="Old")
    bp.vector_action_space_type_deprecated = space_type
    bp.vector_action_size_deprecated.extend(sizes)
    assert codec.behavior_spec_from_proto(bp, agent_info(1, obs=[[0]])).action_spec == expected


@pytest.mark.parametrize(
    "shape, props",
    [((2, 2), ()), ((3,), (P.VARIABLE_SIZE,)), ((3, 4, 4), (P.NONE, P.NONE, P.NONE)), ((1, 2, 3, 4), ())],
)
def test_unsupported_sensors_are_rejected(shape, props):
    info = agent_info(1)
    obs = info.observations.add()
    obs.shape.extend(shape)
    obs.dimension_properties.extend(props)
    with pytest.raises(ProtocolError, match="Unsupported sensor"):
        codec.behavior_spec_from_proto(brain_params("B", 1), info)


# ------------------------------------------------------------------ PNG observations
RGB = np.array(  # 2×3 image, HWC
    [[[255, 0, 0], [0, 255, 0], [0, 0, 255]], [[30, 60, 90], [255, 255, 255], [0, 0, 0]]], dtype=np.uint8
)
RGB2 = np.array([[[51, 102, 153], [0, 0, 0], [255, 0, 51]], [[0, 51, 0], [102, 0, 0], [0, 0, 204]]], dtype=np.uint8)


def decode_visual(shape, data, mapping=()):
    out = output_with({"V": [visual_info(1, shape, data, mapping)]}, [brain_params("V", 1)])
    return codec.decode_rl_output(out, {}).steps["V"][0].obs[0][0]


def test_single_png_becomes_chw_over_255():
    got = decode_visual((3, 2, 3), png_bytes(RGB))
    np.testing.assert_allclose(got[0], [[1, 0, 0], [30 / 255, 1, 0]], rtol=1e-6)  # red plane
    np.testing.assert_allclose(got[1], [[0, 1, 0], [60 / 255, 1, 0]], rtol=1e-6)
    np.testing.assert_allclose(got[2], [[0, 0, 1], [90 / 255, 1, 0]], rtol=1e-6)


def test_legacy_grayscale_is_mean_of_first_image_channels():
    got = decode_visual((1, 2, 3), png_bytes(RGB))
    # (255+0+0)/3 = 85, (30+60+90)/3 = 60, white 255, black 0
    np.testing.assert_allclose(got[0], [[85 / 255, 85 / 255, 85 / 255], [60 / 255, 1, 0]], rtol=1e-6)


def test_concatenated_pngs_legacy_keeps_first_channels():
    got = decode_visual((5, 2, 3), png_bytes(RGB) + png_bytes(RGB2))
    np.testing.assert_allclose(got[3], [[51 / 255, 0, 1], [0, 102 / 255, 0]], rtol=1e-6)  # RGB2 red
    np.testing.assert_allclose(got[4], [[102 / 255, 0, 0], [51 / 255, 0, 0]], rtol=1e-6)  # RGB2 green


def test_channel_mapping_averages_shared_targets_and_drops_minus_one():
    # decoded channels: R1 G1 B1 R2 G2 B2 → out0 = mean(R1, G1), out1 = mean(B1, R2, G2), B2 dropped
    got = decode_visual((2, 2, 3), png_bytes(RGB) + png_bytes(RGB2), mapping=[0, 0, 1, 1, 1, -1])
    out0 = np.array([[255 + 0, 0 + 255, 0 + 0], [30 + 60, 255 + 255, 0]]) / 2 / 255
    out1 = np.array([[0 + 51 + 102, 0 + 0 + 0, 255 + 255 + 0], [90 + 0 + 51, 255 + 102 + 0, 0 + 0 + 0]]) / 3 / 255
    np.testing.assert_allclose(got[0], out0, rtol=1e-6)
    np.testing.assert_allclose(got[1], out1, rtol=1e-6)


def test_grayscale_mapping_000():
    got = decode_visual((1, 2, 3), png_bytes(RGB), mapping=[0, 0, 0])
    np.testing.assert_allclose(got[0], [[85 / 255, 85 / 255, 85 / 255], [60 / 255, 1, 0]], rtol=1e-6)


def test_png_signature_inside_a_chunk_does_not_split_the_file():
    info = PngImagePlugin.PngInfo()
    info.add_text("note", "\x89PNG\r\n\x1a\n inside text")
    first = png_bytes(RGB, pnginfo=info)
    assert first.count(b"\x89PNG\r\n\x1a\n") == 2
    assert split_concatenated_pngs(first + png_bytes(RGB2)) == [first, png_bytes(RGB2)]


@pytest.mark.parametrize(
    "shape, mapping",
    [((3, 3, 2), ()), ((2, 2, 3), [0, 0]), ((2, 2, 3), [0, 2, 2])],
)
def test_png_shape_or_mapping_mismatch_is_a_protocol_error(shape, mapping):
    with pytest.raises(ProtocolError):
        decode_visual(shape, png_bytes(RGB), mapping)


def test_uncompressed_visual_observation():
    info = agent_info(1)
    obs = info.observations.add()
    obs.shape.extend([2, 1, 2])
    obs.float_data.data.extend([0.1, 0.2, 0.3, 0.4])
    got = codec.decode_rl_output(output_with({"V": [info]}, [brain_params("V", 1)]), {}).steps["V"][0].obs[0]
    np.testing.assert_array_equal(got, np.array([[[[0.1, 0.2]], [[0.3, 0.4]]]], dtype=np.float32))


# ------------------------------------------------------------------ trainer → Unity
def _rl_input(payload: bytes):
    message = unity_message_pb2.UnityMessageProto.FromString(payload)
    assert message.header.status == 200
    return message.unity_input.rl_input


def test_hybrid_actions_are_encoded_field_by_field_and_byte_exact():
    actions = {"H?team=0": ActionTuple(np.array([[0.5, -1.0], [0.25, 0.0]], np.float32), np.array([[2, 0], [1, 1]], np.int32))}
    rl_input = _rl_input(codec.encode_answer(actions, b"\x01\x02"))
    assert rl_input.command == command_pb2.STEP and rl_input.side_channel == b"\x01\x02"
    first, second = rl_input.agent_actions["H?team=0"].value
    assert list(first.continuous_actions) == [0.5, -1.0]
    assert list(first.discrete_actions) == [2, 0]
    assert list(first.vector_actions_deprecated) == [0.5, -1.0, 2.0, 0.0]
    assert list(second.vector_actions_deprecated) == [0.25, 0.0, 1.0, 1.0]
    assert first.value == 0.0
    expected = (
        b"\x0a\x10" + struct.pack("<4f", 0.5, -1.0, 2.0, 0.0)  # field 1 packed floats, 16 bytes
        + b"\x32\x08" + struct.pack("<2f", 0.5, -1.0)  # field 6 packed floats
        + b"\x3a\x02\x02\x00"  # field 7 packed varints 2, 0
    )
    assert first.SerializeToString() == expected


def test_behaviors_without_rows_are_left_out_and_reset_has_no_actions():
    actions = {
        "C": ActionTuple(np.array([[0.5]], np.float32), np.zeros((1, 0), np.int32)),
        "Idle": ActionTuple(np.zeros((0, 1), np.float32), np.zeros((0, 0), np.int32)),
    }
    step = _rl_input(codec.encode_answer(actions, b""))
    assert list(step.agent_actions) == ["C"]
    only = step.agent_actions["C"].value[0]
    assert list(only.continuous_actions) == [0.5] and list(only.discrete_actions) == []
    assert isinstance(only, agent_action_pb2.AgentActionProto)
    reset_bytes = codec.encode_answer(actions, b"sc", command=codec.RESET)
    reset = _rl_input(reset_bytes)
    assert reset.command == command_pb2.RESET and len(reset.agent_actions) == 0 and reset.side_channel == b"sc"
    assert reset_bytes == reference.answer({}, b"sc", command_pb2.RESET)


def _as_pairs(actions):
    return {name: (a.continuous, a.discrete) for name, a in actions.items()}


def test_step_answer_for_basic_is_written_byte_for_byte():
    """One agent choosing option 2 of Basic's branch: the bytes worked out by hand."""
    actions = {"Basic?team=0": ActionTuple(np.zeros((1, 0), np.float32), np.array([[2]], np.int32))}
    agent = b"\x0a\x04" + struct.pack("<f", 2.0) + b"\x3a\x01\x02"  # deprecated [2.0], discrete [2]
    value = b"\x0a" + bytes([len(agent)]) + agent  # ListAgentActionProto.value
    entry = b"\x0a\x0cBasic?team=0" + b"\x12" + bytes([len(value)]) + value
    rl_input = b"\x0a" + bytes([len(entry)]) + entry
    unity_input = b"\x0a" + bytes([len(rl_input)]) + rl_input
    expected = b"\x0a\x03\x08\xc8\x01" + b"\x1a" + bytes([len(unity_input)]) + unity_input
    assert codec.encode_answer(actions, b"") == expected == reference.answer(_as_pairs(actions))


@pytest.mark.parametrize("agents", [1, 3, 7, 8, 20])
@pytest.mark.parametrize("continuous, branches", [(2, 0), (0, 1), (0, 3), (3, 2), (0, 0)])
@pytest.mark.parametrize("side_channel", [b"", b"\x05" * 300])
def test_step_answer_bytes_are_what_the_protobuf_objects_serialize(agents, continuous, branches, side_channel):
    rng = np.random.default_rng(agents * 31 + continuous * 7 + branches)
    cont = rng.uniform(-1, 1, (agents, continuous)).astype(np.float32)
    cont[0, :1] = -0.0  # signed zeros and packed zeros are written like any other value
    disc = rng.integers(0, 130, (agents, branches)).astype(np.int32)  # 128+ : two-byte varints
    actions = {"A?team=0": ActionTuple(cont, disc)}
    assert codec.encode_answer(actions, side_channel) == reference.answer(_as_pairs(actions), side_channel)


def test_step_answer_with_several_behaviors_parses_to_the_same_message():
    actions = {
        "B?team=0": ActionTuple(np.zeros((1, 0), np.float32), np.array([[1]], np.int32)),
        "Idle?team=0": ActionTuple(np.zeros((0, 2), np.float32), np.zeros((0, 0), np.int32)),
        "C?team=1": ActionTuple(np.array([[0.5, -0.25], [1.0, 0.0]], np.float32), np.zeros((2, 0), np.int32)),
    }
    direct = unity_message_pb2.UnityMessageProto.FromString(codec.encode_answer(actions, b"sc"))
    assert direct == unity_message_pb2.UnityMessageProto.FromString(reference.answer(_as_pairs(actions), b"sc"))
    assert sorted(direct.unity_input.rl_input.agent_actions) == ["B?team=0", "C?team=1"]


@pytest.mark.parametrize("agents", [1, 8])
def test_negative_discrete_actions_are_ten_byte_varints_as_protobuf_writes_them(agents):
    disc = np.full((agents, 2), -1, np.int32)
    disc[:, 1] = -(2**31)
    actions = {"A": ActionTuple(np.zeros((agents, 0), np.float32), disc)}
    written = codec.encode_answer(actions, b"")
    assert written == reference.answer(_as_pairs(actions))
    assert b"\xff" * 9 + b"\x01" in written  # -1 as the varint of 2**64 - 1


# ------------------------------------------------------------------ version check
@pytest.mark.parametrize(
    "version, ok",
    [
        ("1.5.0", True), ("1.0.0", True), ("1.9.3", True), ("1.5", True),
        ("2.0.0", False), ("0.15.0", False), ("0.5.0", False),
        ("1.5.0-preview", False), ("", False), ("one.two", False),
    ],
)
def test_communication_version_table(version, ok):
    if ok:
        codec.check_communication_version(version)
    else:
        with pytest.raises(UnityVersionError) as err:
            codec.check_communication_version(version)
        assert repr(version)[1:-1] in str(err.value) and "1.5.0" in str(err.value)
        assert "Release 22" in str(err.value)


def test_capabilities_all_true():
    caps = all_true_capabilities()
    assert [getattr(caps, f.name) for f in caps.DESCRIPTOR.fields] == [True] * 7


# ------------------------------------------------------------------ a few agents, agent by agent
def test_a_few_agents_decode_to_their_hand_written_values():
    spec = BehaviorSpec((ObservationSpec((3,), (P.NONE,), ObservationType.DEFAULT, "a"),
                         ObservationSpec((2,), (P.NONE,), ObservationType.DEFAULT, "b")), ActionSpec(1, (2, 3)))
    infos = [agent_info(7, obs=[[1, 2, 3], [4, 5]], reward=0.5, mask=[False, True, True, False, False]),
             agent_info(-3, obs=[[0.25, 0, -1], [9, 8]], reward=-1.5, group_id=4, group_reward=2.0),
             agent_info(2**31 - 1, obs=[[7, 7, 7], [6, 6]])]  # no mask: nothing masked
    decision, terminal = codec.steps_from_agent_infos("B", infos, spec)
    assert decision.agent_id.tolist() == [7, -3, 2**31 - 1] and decision.reward.tolist() == [0.5, -1.5, 0.0]
    assert decision.obs[0].tolist() == [[1, 2, 3], [0.25, 0, -1], [7, 7, 7]]
    assert decision.obs[1].tolist() == [[4, 5], [9, 8], [6, 6]]
    assert decision.group_id.tolist() == [0, 4, 0] and decision.group_reward.tolist() == [0.0, 2.0, 0.0]
    assert decision.action_mask[0].tolist() == [[False, True], [False, False], [False, False]]
    assert decision.action_mask[1].tolist() == [[True, False, False], [False] * 3, [False] * 3]
    assert len(terminal) == 0


@pytest.mark.parametrize("case", ["short_obs"])
def test_a_bad_agent_among_few_is_named(case):
    spec = BehaviorSpec((ObservationSpec((3,), (P.NONE,), ObservationType.DEFAULT, "a"),), ActionSpec(1, ()))
    kwargs = {"nan_reward": {"reward": float("nan")}, "inf_group_reward": {"group_reward": float("-inf")},
              "inf_obs": {"obs": [[1, float("inf"), 3]]}, "short_obs": {"obs": [[1, 2]]}}[case]
    kwargs.setdefault("obs", [[1, 2, 3]])
    infos = [agent_info(1, obs=[[0, 0, 0]]), agent_info(42, **kwargs)]
    with pytest.raises(ProtocolError, match="agent id 42"):
        codec.steps_from_agent_infos("B", infos, spec)


def test_no_agents_decode_to_empty_steps_of_the_spec_shapes():
    spec = BehaviorSpec((ObservationSpec((3,), (P.NONE,), ObservationType.DEFAULT, "a"),), ActionSpec(0, (2,)))
    decision, terminal = codec.steps_from_agent_infos("B", [], spec)
    assert len(decision) == len(terminal) == 0
    assert decision.obs[0].shape == (0, 3) and decision.action_mask[0].shape == (0, 2)


@pytest.mark.parametrize("matrix_from", [1, 10**9])  # every count through the byte matrix, then the loop
@pytest.mark.parametrize("agents", [1, 5, 8, 20])
def test_both_action_writers_write_protobufs_bytes(monkeypatch, matrix_from, agents):
    from protos import wire
    from protos.communicator_objects import unity_rl_input_pb2

    monkeypatch.setattr(wire, "MIN_MATRIX_ROWS", matrix_from)
    rng = np.random.default_rng(agents)
    for c, b in [(2, 0), (0, 3), (3, 2), (0, 0)]:
        continuous = rng.normal(size=(agents, c)).astype(np.float32)
        discrete = rng.integers(0, 127, size=(agents, b)).astype(np.int32)
        if b:
            discrete[0, 0] = 200 if matrix_from == 1 else -7  # a 2-byte varint takes the loop; so does a negative
        expected = unity_rl_input_pb2.UnityRLInputProto.ListAgentActionProto()
        for cont_row, disc_row in zip(continuous.tolist(), discrete.tolist()):
            agent = expected.value.add()
            agent.vector_actions_deprecated.extend(cont_row + [float(d) for d in disc_row])
            agent.continuous_actions.extend(cont_row)
            agent.discrete_actions.extend(disc_row)
        assert codec.agent_actions_bytes(continuous, discrete) == expected.SerializeToString()
