"""Agent-side bookkeeping as Unity's ``Agent`` does it: episode ids and AgentInfoProto building.

Episode ids come from one process-wide counter (Unity's ``EpisodeIdCounter``): every episode
start, for any agent, takes the next integer, so an id never repeats within one connection.
"""
from __future__ import annotations

import functools
from typing import Sequence

import numpy as np

from protos.communicator_objects import (
    agent_info_pb2,
    brain_parameters_pb2,
    space_type_pb2,
)
from trainer.protocol import wire
from trainer.protocol.types import ActionSpec, ObservationSpec


# AgentInfoProto field tags (spec §2): reward 7 (float), done 8, max_step_reached 9, id 10 (varints)
_REWARD, _DONE, _MAX_STEP, _ID = (wire.tag(7, wire.I32), wire.tag(8, wire.VARINT),
                                  wire.tag(9, wire.VARINT), wire.tag(10, wire.VARINT))


class EncodedInfos:
    """Serialized ListAgentInfoProto content (repeated ``value`` records) for ``count`` agents.

    Concatenating two of them appends the agents of the second after the first's, as merging
    two serialized messages with a repeated field does.
    """

    __slots__ = ("data", "count")

    def __init__(self, data: bytes = b"", count: int = 0) -> None:
        self.data = data
        self.count = count

    def __len__(self) -> int:
        return self.count

    def __add__(self, other: "EncodedInfos") -> "EncodedInfos":
        return EncodedInfos(self.data + other.data, self.count + other.count)

    def protos(self) -> list[agent_info_pb2.AgentInfoProto]:
        from protos.communicator_objects import unity_rl_output_pb2

        parsed = unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto.FromString(self.data)
        return list(parsed.value)


def encode_agent_infos(
    observation_specs: Sequence[ObservationSpec],
    observations: Sequence[np.ndarray],
    rewards: np.ndarray,
    episode_ids: np.ndarray,
    done: bool,
    interrupted: np.ndarray | None = None,
    action_mask: np.ndarray | None = None,
) -> EncodedInfos:
    """AgentInfoProtos as Unity's ``PutObservations`` writes them, serialized for all rows at once.

    Every agent's record has the same layout: reward (7), done (8), max_step_reached (9), the
    action mask (11, packed), one ObservationProto per sensor (13: shape, float_data,
    dimension_properties, observation_type, name) and the episode id (10) last as a 5-byte
    varint, so the records form one byte matrix (see trainer.protocol.wire).
    """
    count = len(episode_ids)
    if count == 0:
        return EncodedInfos()
    if count < wire.MIN_MATRIX_ROWS:
        return _encode_few(observation_specs, observations, rewards, episode_ids, done, interrupted, action_mask)
    parts: list = [_REWARD, wire.float_columns(rewards, count), _DONE + (b"\x01" if done else b"\x00"),
                   _MAX_STEP]
    flags = np.zeros((count, 1), dtype=np.uint8)
    if done and interrupted is not None:
        flags[:, 0] = np.asarray(interrupted, dtype=bool)
    parts.append(flags)
    if action_mask is not None:
        mask = np.asarray(action_mask, dtype=bool).reshape(count, -1).astype(np.uint8)
        parts += [wire.len_prefix(11, mask.shape[1]), mask]
    for spec, obs in zip(observation_specs, observations):
        head, tail = _observation_frame(spec)
        parts += [head, wire.float_columns(obs, count), tail]
    parts += [_ID, wire.varint5_columns(episode_ids)]
    return EncodedInfos(wire.repeated_rows(1, parts, count), count)


def _varint5(value: int) -> bytes:
    """``wire.varint5_columns`` for one id (0 <= value < 2**32)."""
    if not 0 <= value < 1 << 32:
        raise ValueError("fixed-width varints hold 0 <= value < 2**32")
    return bytes(((value >> 7 * i) & 0x7F) | (0x80 if i < 4 else 0) for i in range(5))


@functools.lru_cache(maxsize=64)
def _observation_frame(spec: ObservationSpec) -> tuple[bytes, bytes]:
    """The bytes of one ObservationProto field (13) before and after its float payload."""
    size = int(np.prod(spec.shape, dtype=np.int64))
    shape = b"".join(wire.varint(int(d)) for d in spec.shape)
    float_data = wire.len_prefix(1, 4 * size)
    head = wire.len_prefix(1, len(shape)) + shape + wire.len_prefix(4, len(float_data) + 4 * size) + float_data
    props = b"".join(wire.varint(int(p)) for p in spec.dimension_property)
    tail = wire.len_prefix(6, len(props)) + props if props else b""
    if int(spec.observation_type):
        tail += wire.tag(7, wire.VARINT) + wire.varint(int(spec.observation_type))
    if spec.name:
        name = spec.name.encode()
        tail += wire.len_prefix(8, len(name)) + name
    return wire.len_prefix(13, len(head) + 4 * size + len(tail)) + head, tail


def _encode_few(observation_specs, observations, rewards, episode_ids, done, interrupted, action_mask
                ) -> EncodedInfos:
    """``encode_agent_infos`` for a handful of agents: the same record bytes, joined per agent."""
    count = len(episode_ids)
    frames = [_observation_frame(spec) for spec in observation_specs]
    flat_obs = [np.ascontiguousarray(np.asarray(obs, dtype="<f4").reshape(count, -1)) for obs in observations]
    reward_bytes = np.ascontiguousarray(np.asarray(rewards, dtype="<f4")).tobytes()
    flags = (np.asarray(interrupted, dtype=bool).tolist() if done and interrupted is not None
             else [False] * count)
    masks = (np.asarray(action_mask, dtype=bool).reshape(count, -1).astype(np.uint8) if action_mask is not None
             else None)
    ids = b"".join(map(_varint5, np.asarray(episode_ids).tolist()))
    done_field = _DONE + (b"\x01" if done else b"\x00")
    records = []
    for row in range(count):
        parts = [_REWARD, reward_bytes[4 * row:4 * row + 4], done_field, _MAX_STEP + (b"\x01" if flags[row] else b"\x00")]
        if masks is not None:
            parts += [wire.len_prefix(11, masks.shape[1]), masks[row].tobytes()]
        for (head, tail), obs in zip(frames, flat_obs):
            parts += [head, obs[row].tobytes(), tail]
        parts += [_ID, ids[5 * row:5 * row + 5]]
        content = b"".join(parts)
        records.append(wire.len_prefix(1, len(content)) + content)
    return EncodedInfos(b"".join(records), count)


class EpisodeIdCounter:
    """Hands out increasing episode ids, starting at 0 like Unity's counter."""

    def __init__(self) -> None:
        self._next = 0

    def take(self, count: int) -> np.ndarray:
        """int64 [count]: the next ``count`` ids, in agent order."""
        ids = np.arange(self._next, self._next + count, dtype=np.int64)
        self._next += count
        return ids


def build_brain_parameters(behavior_key: str, action_spec: ActionSpec) -> brain_parameters_pb2.BrainParametersProto:
    """BrainParametersProto for ``behavior_key`` (the full ``Name?team=0``, as Unity sends it).

    The deprecated vector_action_* fields are filled the way a Unity scene upgraded from the
    old API carries them (continuous: [size]; discrete: the branch sizes); trainers that
    understand ``action_spec`` (comm >= 1.3) ignore them.
    """
    proto = brain_parameters_pb2.BrainParametersProto(brain_name=behavior_key, is_training=True)
    proto.action_spec.num_continuous_actions = action_spec.continuous_size
    proto.action_spec.num_discrete_actions = len(action_spec.discrete_branches)
    proto.action_spec.discrete_branch_sizes.extend(action_spec.discrete_branches)
    if action_spec.continuous_size > 0:
        proto.vector_action_space_type_deprecated = space_type_pb2.continuous
        proto.vector_action_size_deprecated.append(action_spec.continuous_size)
    else:
        proto.vector_action_space_type_deprecated = space_type_pb2.discrete
        proto.vector_action_size_deprecated.extend(action_spec.discrete_branches)
    return proto
