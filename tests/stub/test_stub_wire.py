"""The stub's vectorized AgentInfoProto bytes against protobuf's own one-message-at-a-time
encoding, and the fixed-width wire helpers against hand-computed bytes."""
from __future__ import annotations

from typing import Sequence

import numpy as np
import pytest

from protos.communicator_objects import agent_info_pb2, observation_pb2, unity_rl_output_pb2
from trainer.protocol import wire
from trainer.protocol.types import ObservationSpec
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


def test_varints_and_fixed_width_varints_by_hand():
    assert wire.varint(0) == b"\x00" and wire.varint(127) == b"\x7f"
    assert wire.varint(300) == b"\xac\x02"  # the protobuf documentation's example
    # 300 in five bytes: 0xac, then 0x02 with continuation bits up to the last byte
    assert wire.varint5_columns(np.array([300, 0])).tolist() == [[0xAC, 0x82, 0x80, 0x80, 0x00],
                                                                 [0x80, 0x80, 0x80, 0x80, 0x00]]
    with pytest.raises(ValueError):
        wire.varint5_columns(np.array([-1]))
    assert wire.tag(13, wire.LEN) == b"\x6a" and wire.len_prefix(1, 4) == b"\x0a\x04"


def test_repeated_messages_prefix_each_row():
    content = np.array([[1, 2], [3, 4]], dtype=np.uint8)
    assert wire.repeated_messages(1, content) == b"\x0a\x02\x01\x02\x0a\x02\x03\x04"
    assert wire.repeated_messages(1, np.zeros((0, 3), np.uint8)) == b""


def test_rows_from_a_cached_layout_take_each_calls_values():
    ids = np.array([[7], [9]], dtype=np.uint8)
    first = wire.rows([b"\x08", ids, bytearray(b"\x10\x01")], 2)
    assert first.tolist() == [[8, 7, 16, 1], [8, 9, 16, 1]]
    again = wire.rows([b"\x08", ids + 1, b"\x10\x01"], 2)  # same layout, new values
    assert again.tolist() == [[8, 8, 16, 1], [8, 10, 16, 1]] and first.tolist() == [[8, 7, 16, 1], [8, 9, 16, 1]]
    assert wire.rows([b"\x08\x00", ids], 2).tolist() == [[8, 0, 7], [8, 0, 9]]  # another layout
    # a record header as one more constant part: the same bytes as rows + repeated_messages
    assert wire.repeated_rows(1, [b"\x08", ids], 2) == b"\x0a\x02\x08\x07\x0a\x02\x08\x09"
    assert wire.repeated_rows(1, [], 2) == b"\x0a\x00\x0a\x00" and wire.repeated_rows(1, [ids], 0) == b""


@pytest.mark.parametrize("task_name,areas", [("basic", 3), ("ball3d", 1)])
@pytest.mark.parametrize("done", [False, True])
@pytest.mark.parametrize("small_batch", [0, 10_000], ids=["byte-matrix", "per-agent"])
def test_encoded_infos_equal_protobufs_own_encoding(task_name, areas, done, small_batch, monkeypatch):
    monkeypatch.setattr(wire, "MIN_MATRIX_ROWS", small_batch)  # force one of the two encoders
    task = make_task(task_name, num_areas=areas, seed=0)
    task.reset()
    n = task.num_agents
    obs = task.observe()
    rewards = np.linspace(-1, 1, n).astype(np.float32)
    ids = np.array([0, 127, 128, 16383, 16384, 2**31 - 1] * 3)[:n]  # every varint length
    interrupted = (np.arange(n) % 2 == 0) if done else None
    mask = task.action_mask()
    slow = ListAgentInfo()
    slow.value.extend(build_agent_infos(task.observation_specs, obs, rewards, ids, done, interrupted, mask))
    encoded = encode_agent_infos(task.observation_specs, obs, rewards, ids, done, interrupted, mask)
    fast = ListAgentInfo.FromString(encoded.data)
    assert len(encoded) == n == len(fast.value)
    assert fast.SerializeToString() == slow.SerializeToString()
    assert [info.id for info in fast.value] == ids.tolist()
