"""The stub's vectorized AgentInfoProto bytes against protobuf's own one-message-at-a-time
encoding, and the fixed-width wire helpers against hand-computed bytes."""
from __future__ import annotations

import numpy as np
import pytest

from protos.communicator_objects import unity_rl_output_pb2
from trainer.protocol import wire
from unity_stub_env import agents
from unity_stub_env.agents import build_agent_infos, encode_agent_infos
from unity_stub_env.tasks import make_task

ListAgentInfo = unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto


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


@pytest.mark.parametrize("task_name,areas", [("basic", 3), ("ball3d", 1)])
@pytest.mark.parametrize("done", [False, True])
@pytest.mark.parametrize("small_batch", [0, 10_000], ids=["byte-matrix", "per-agent"])
def test_encoded_infos_equal_protobufs_own_encoding(task_name, areas, done, small_batch, monkeypatch):
    monkeypatch.setattr(agents, "SMALL_BATCH", small_batch)  # force one of the two encoders
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
