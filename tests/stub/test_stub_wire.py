"""The stub's vectorized AgentInfoProto bytes against protobuf's own one-message-at-a-time
encoding, and the fixed-width wire helpers against hand-computed bytes."""
from __future__ import annotations

from typing import Sequence

import numpy as np
import pytest

from protos import wire
from protos.communicator_objects import agent_info_pb2, observation_pb2, unity_rl_output_pb2
from protos.types import ObservationSpec
from unity_stub_env.agents import encode_agent_infos
from unity_stub_env.tasks import make_task

ListAgentInfo = unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto


def build_agent_infos(
    observation_specs: Sequence[ObservationSpec],
    observations: Sequence[np.ndarray],
    rewards: np.ndarray,
    episode_ids: np.ndarray,
    done: bool,
    interrupted: np.ndarray | None = None,
    action_mask: np.ndarray | None = None,
) -> list[agent_info_pb2.AgentInfoProto]:
    """The oracle: one AgentInfoProto object per row, as Unity's ``PutObservations`` writes them.

    observations[i]: float32 [k, *observation_specs[i].shape]; rewards float32 [k];
    episode_ids int [k]; interrupted bool [k] (max_step_reached, only with done);
    action_mask bool [k, sum(branches)] with True = forbidden, or None.
    """
    count = len(episode_ids)
    flat_obs = [np.asarray(obs, dtype=np.float32).reshape(count, -1).tolist() for obs in observations]
    reward_list = np.asarray(rewards, dtype=np.float32).tolist()
    id_list = np.asarray(episode_ids).tolist()
    interrupted_list = (np.asarray(interrupted, dtype=bool).tolist() if interrupted is not None
                        else [False] * count)
    mask_list = np.asarray(action_mask, dtype=bool).tolist() if action_mask is not None else None
    spec_fields = [(list(spec.shape), [int(p) for p in spec.dimension_property],
                    int(spec.observation_type), spec.name) for spec in observation_specs]
    infos = []
    for row in range(count):
        info = agent_info_pb2.AgentInfoProto(
            reward=reward_list[row], done=done, max_step_reached=done and interrupted_list[row],
            id=id_list[row],
        )
        if mask_list is not None:
            info.action_mask.extend(mask_list[row])
        for sensor, (shape, props, obs_type, name) in enumerate(spec_fields):
            obs = info.observations.add()
            obs.shape.extend(shape)
            obs.compression_type = observation_pb2.NONE
            obs.float_data.data.extend(flat_obs[sensor][row])
            obs.dimension_properties.extend(props)
            obs.observation_type = obs_type
            obs.name = name
        infos.append(info)
    return infos


def test_varints_varint_columns_and_interleaving_by_hand():
    assert wire.varint(0) == b"\x00" and wire.varint(127) == b"\x7f"
    assert wire.varint(300) == b"\xac\x02"  # the protobuf documentation's example
    # every length from 1 to 5 bytes, as many columns as the longest, continuation bits inside
    columns, used = wire.varint_columns(np.array([0, 127, 128, 16383, 16384, 2**21, 2**28, 2**31 - 1]))
    assert used.sum(axis=1).tolist() == [1, 1, 2, 2, 3, 4, 5, 5]
    assert [bytes(row[:k]) for row, k in zip(columns, used.sum(axis=1))] == [
        wire.varint(v) for v in (0, 127, 128, 16383, 16384, 2**21, 2**28, 2**31 - 1)]
    # 300 and 129 in two bytes each: low 7 bits with the continuation bit, then the rest
    columns, used = wire.varint_columns(np.array([300, 129]))
    assert columns.tolist() == [[0xAC, 0x02], [0x81, 0x01]] and used is None
    # lengths 1, 2 and 3 side by side: left-aligned, continuation bits only inside each varint
    columns, used = wire.varint_columns(np.array([5, 300, 16384]))
    assert columns.tolist() == [[5, 0, 0], [0xAC, 0x02, 0], [0x80, 0x80, 0x01]]
    assert used.tolist() == [[True, False, False], [True, True, False], [True, True, True]]
    for bad in ([-1], [2**31]):
        with pytest.raises(ValueError):
            wire.varint_columns(np.array(bad))
    assert wire.tag(13, wire.LEN) == b"\x6a" and wire.len_prefix(1, 4) == b"\x0a\x04"


def test_repeated_rows_prefix_each_row():
    content = np.array([[1, 2], [3, 4]], dtype=np.uint8)
    assert wire.repeated_rows(1, [content], 2) == b"\x0a\x02\x01\x02\x0a\x02\x03\x04"
    assert wire.repeated_rows(1, [np.zeros((0, 3), np.uint8)], 0) == b""


def test_rows_from_a_cached_layout_take_each_calls_values():
    ids = np.array([[7], [9]], dtype=np.uint8)
    first = wire.rows([b"\x08", ids, bytearray(b"\x10\x01")], 2)
    assert first.tolist() == [[8, 7, 16, 1], [8, 9, 16, 1]]
    again = wire.rows([b"\x08", ids + 1, b"\x10\x01"], 2)  # same layout, new values
    assert again.tolist() == [[8, 8, 16, 1], [8, 10, 16, 1]] and first.tolist() == [[8, 7, 16, 1], [8, 9, 16, 1]]
    assert wire.rows([b"\x08\x00", ids], 2).tolist() == [[8, 0, 7], [8, 0, 9]]  # another layout
    # constant parts and column blocks together, each row behind its record header
    assert wire.repeated_rows(1, [b"\x08", ids], 2) == b"\x0a\x02\x08\x07\x0a\x02\x08\x09"
    assert wire.repeated_rows(1, [], 2) == b"\x0a\x00\x0a\x00" and wire.repeated_rows(1, [ids], 0) == b""


@pytest.mark.parametrize("task_name,areas", [("basic", 3), ("ball3d", 1), ("dodge", 1)])
@pytest.mark.parametrize("done", [False, True])
@pytest.mark.parametrize("small_batch", [0, 10_000], ids=["byte-matrix", "per-agent"])
@pytest.mark.parametrize("mixed", [True, False], ids=["mixed-layouts", "one-layout"])
def test_encoded_infos_equal_protobufs_own_encoding(task_name, areas, done, small_batch, mixed, monkeypatch):
    monkeypatch.setattr(wire, "MIN_MATRIX_ROWS", small_batch)  # force one of the two encoders
    task = make_task(task_name, num_areas=areas, seed=0)
    task.reset()
    n = task.num_agents
    obs = task.observe()
    if mixed:  # zero rewards, id 0 and every varint length: records of several layouts
        rewards = np.linspace(-1, 1, n).astype(np.float32)
        ids = np.array([0, 127, 128, 16383, 16384, 2**31 - 1] * 3)[:n]
        interrupted = (np.arange(n) % 2 == 0) if done else None
    else:
        rewards = np.linspace(0.5, 1, n).astype(np.float32)
        ids = 200 + np.arange(n)
        interrupted = np.ones(n, bool) if done else None
    mask = task.action_mask()
    slow = ListAgentInfo()
    slow.value.extend(build_agent_infos(task.observation_specs, obs, rewards, ids, done, interrupted, mask))
    encoded = encode_agent_infos(task.observation_specs, obs, rewards, ids, done, interrupted, mask)
    fast = ListAgentInfo.FromString(encoded.data)
    assert len(encoded) == n == len(fast.value)
    assert encoded.data == slow.SerializeToString()  # protobuf's own (C#'s) bytes, exactly
    assert [info.id for info in fast.value] == ids.tolist()


@pytest.mark.parametrize("side_channel", [b"", b"\x01\x02side"])
@pytest.mark.parametrize("first_time", [False, True])
def test_step_message_bytes_equal_protobufs_own_encoding(side_channel, first_time):
    """The stub's directly written step message against the message built field by field:
    byte-equal for one behavior (also with an empty list), equal after parsing for two."""
    from protos.communicator_objects import header_pb2, unity_message_pb2
    from unity_stub_env.agents import build_brain_parameters
    from unity_stub_env.communicator import step_message_bytes

    lists = []
    for task_name, areas in (("ball3d", 1), ("basic", 3), ("basic", 0)):
        task = make_task(task_name, num_areas=max(areas, 1), seed=0)
        task.reset()
        n = task.num_agents if areas else 0
        encoded = encode_agent_infos(task.observation_specs, [o[:n] for o in task.observe()],
                                     np.ones(n, np.float32), np.arange(n), False)
        brain = build_brain_parameters(f"{task.behavior_name}?team=0", task.action_spec)
        lists.append((f"{task.behavior_name}{areas}?team=0", encoded.data, brain))
    for chosen in ([lists[0]], [lists[2]], lists):
        brains = [brain for _, _, brain in chosen] if first_time else []
        expected = unity_message_pb2.UnityMessageProto(header=header_pb2.HeaderProto(status=200))
        rl_output = expected.unity_output.rl_output
        for key, data, _ in chosen:
            rl_output.agentInfos[key].MergeFromString(data)
        rl_output.side_channel = side_channel
        expected.unity_output.rl_initialization_output.brain_parameters.extend(brains)
        if not brains:
            expected.unity_output.ClearField("rl_initialization_output")
        written = step_message_bytes([(key, data) for key, data, _ in chosen], side_channel, brains)
        parsed = unity_message_pb2.UnityMessageProto.FromString(written)
        assert parsed == expected
        where = [written.index(key.encode()) for key, _, _ in chosen]
        assert where == sorted(where)  # the map entries in the order given, as C# keeps them
        if len(chosen) == 1:
            assert written == expected.SerializeToString()
