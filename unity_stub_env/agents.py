"""Agent-side bookkeeping as Unity's ``Agent`` does it: episode ids and AgentInfoProto building.

Episode ids come from one process-wide counter (Unity's ``EpisodeIdCounter``): every episode
start, for any agent, takes the next integer, so an id never repeats within one connection.
"""
from __future__ import annotations

import functools
import io
from typing import Sequence

import numpy as np

from protos import wire
from protos.communicator_objects import (
    agent_info_pb2,
    brain_parameters_pb2,
    space_type_pb2,
)
from protos.types import ActionSpec, ObservationSpec


# AgentInfoProto fields (docs/protocol.md, "Message schema") in number order: reward 7 (float), done 8, max_step_reached 9,
# id 10 (varints), action_mask 11 (packed bools), observations 13
_REWARD, _ID = wire.tag(7, wire.I32), wire.tag(10, wire.VARINT)
_DONE_TRUE, _MAX_STEP_TRUE = wire.tag(8, wire.VARINT) + b"\x01", wire.tag(9, wire.VARINT) + b"\x01"
_GROUP_ID = wire.tag(14, wire.VARINT)
_GROUP_REWARD = wire.tag(15, wire.I32)
_PNG = 1  # ObservationProto.compression_type


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
    compressions: Sequence[str] | None = None,
    group_ids: np.ndarray | None = None,
    group_rewards: np.ndarray | None = None,
) -> EncodedInfos:
    """AgentInfoProtos as Unity's ``PutObservations`` fills them, serialized as Unity's C#
    protobuf writes them: fields in number order, the proto3 defaults left out (a zero reward,
    done and max_step_reached when false, episode id 0), varints in their shortest form. Each
    agent's ObservationProtos are shape, float_data, dimension_properties, observation_type, name.

    All records are laid out as one byte matrix (protos.wire) with every field and id
    byte that any of them needs; when records differ (a zero reward beside others, ids of
    several varint lengths, some agents interrupted), a byte mask then drops what each record
    leaves out, which also joins the records of different lengths.

    ``compressions`` (per observation, "none" or "png") and ``group_ids`` (int [count], 0 = no
    group) are what the ``mirror`` task needs: PNG cameras and agent groups (AgentInfoProto
    field 14). Records with them are joined one by one (``_encode_few``): a PNG's length differs
    from agent to agent. ``group_rewards`` (float [count]) is field 15, left out where zero.
    """
    count = len(episode_ids)
    if count == 0:
        return EncodedInfos()
    rewards = np.ascontiguousarray(np.asarray(rewards, dtype="<f4").reshape(count))
    ids = np.asarray(episode_ids, dtype=np.int64).reshape(count)
    max_step = (np.asarray(interrupted, dtype=bool).reshape(count) if done and interrupted is not None
                else None)
    masks = (np.asarray(action_mask, dtype=bool).reshape(count, -1).astype(np.uint8)
             if action_mask is not None else None)
    pngs = tuple(c == "png" for c in compressions) if compressions is not None and "png" in compressions else None
    if group_rewards is not None and not np.any(group_rewards):
        group_rewards = None
    if count < wire.MIN_MATRIX_ROWS or pngs is not None or group_ids is not None or group_rewards is not None:
        return _encode_few(observation_specs, observations, rewards, ids, done, max_step, masks, pngs,
                           group_ids, group_rewards)
    parts: list = []
    keep: list = []  # per part: None (every record has it), bool [count] or bool [count, width]

    def add(part, part_keep=None) -> None:
        parts.append(part)
        keep.append(part_keep)

    has_reward = None if rewards.all() else rewards != 0
    if has_reward is None or has_reward.any():
        add(_REWARD, has_reward)
        add(wire.float_columns(rewards, count), has_reward)
    if done:
        add(_DONE_TRUE)
    if max_step is not None and max_step.any():
        add(_MAX_STEP_TRUE, None if max_step.all() else max_step)
    has_id = None if ids.all() else ids != 0
    if has_id is None or has_id.any():
        id_columns, id_used = wire.varint_columns(ids)
        add(_ID, has_id)
        if id_used is None:
            add(id_columns, has_id)
        else:
            add(id_columns, id_used if has_id is None else id_used & has_id[:, None])
    if masks is not None and masks.shape[1]:
        add(wire.len_prefix(11, masks.shape[1]))
        add(masks)
    for spec, obs in zip(observation_specs, observations):
        head, tail = _observation_frame(spec)
        add(head)
        add(wire.float_columns(obs, count))
        add(tail)
    if all(k is None for k in keep):  # the usual message: every record has the same layout
        return EncodedInfos(wire.repeated_rows(1, parts, count), count)
    content = wire.rows(parts, count)
    present = np.ones(content.shape, dtype=bool)  # which bytes of the widest layout a record has
    column = 0
    for part, k in zip(parts, keep):
        w = wire.width(part)
        if k is not None:
            present[:, column:column + w] = k if k.ndim == 2 else k[:, None]
        column += w
    length_columns, length_used = wire.varint_columns(present.sum(axis=1))
    header_present = np.ones(length_columns.shape, dtype=bool) if length_used is None else length_used
    records = wire.rows([wire.tag(1, wire.LEN), length_columns, content], count)
    present = np.concatenate([np.ones((count, 1), dtype=bool), header_present, present], axis=1)
    return EncodedInfos(records[present].tobytes(), count)


def _encode_few(observation_specs, observations, rewards, ids, done, max_step, masks, pngs=None,
                group_ids=None, group_rewards=None) -> EncodedInfos:
    """``encode_agent_infos`` for a handful of agents (or with PNG cameras or groups): each
    record's bytes joined in a loop."""
    pngs = pngs or (False,) * len(observation_specs)
    frames = [None if png else _observation_frame(spec) for spec, png in zip(observation_specs, pngs)]
    flat_obs = [_png_fields(spec, obs) if png else
                np.ascontiguousarray(np.asarray(obs, dtype="<f4").reshape(len(ids), -1))
                for spec, obs, png in zip(observation_specs, observations, pngs)]
    mask_prefix = wire.len_prefix(11, masks.shape[1]) if masks is not None and masks.shape[1] else None
    flags = max_step.tolist() if max_step is not None else [False] * len(ids)
    groups = [0] * len(ids) if group_ids is None else np.asarray(group_ids, dtype=np.int64).tolist()
    group_rewards = (np.zeros(len(ids), dtype="<f4") if group_rewards is None
                     else np.ascontiguousarray(np.asarray(group_rewards, dtype="<f4").reshape(len(ids))))
    records = []
    for row, (reward, episode_id, interrupted) in enumerate(zip(rewards.tolist(), ids.tolist(), flags)):
        parts = [_REWARD, rewards[row].tobytes()] if reward != 0 else []
        if done:
            parts.append(_DONE_TRUE)
        if interrupted:
            parts.append(_MAX_STEP_TRUE)
        if episode_id:
            parts += [_ID, wire.varint(episode_id)]
        if mask_prefix is not None:
            parts += [mask_prefix, masks[row].tobytes()]
        for frame, obs in zip(frames, flat_obs):
            parts += [obs[row]] if frame is None else [frame[0], obs[row].tobytes(), frame[1]]
        if groups[row]:
            parts += [_GROUP_ID, wire.varint(groups[row])]
        if group_rewards[row] != 0:
            parts += [_GROUP_REWARD, group_rewards[row].tobytes()]
        records.append(wire.field(1, b"".join(parts)))
    return EncodedInfos(b"".join(records), len(ids))


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


def _png_fields(spec: ObservationSpec, observations: np.ndarray) -> list[bytes]:
    """One serialized PNG ObservationProto (field 13) per agent for a C x H x W camera in [0, 1]
    (docs/protocol.md, "Observation payloads"): 1 channel as a gray RGB PNG, 3 as RGB, any other count as RGB PNGs
    of 3 channels each, concatenated, with ``compressed_channel_mapping`` (-1 for padding)."""
    channels = spec.shape[0]
    mapping = [] if channels in (1, 3) else [c if c < channels else -1 for c in range(3 * -(-channels // 3))]
    shape = b"".join(wire.varint(int(d)) for d in spec.shape)
    props = b"".join(wire.varint(int(p)) for p in spec.dimension_property)
    before = wire.len_prefix(1, len(shape)) + shape + wire.tag(2, wire.VARINT) + wire.varint(_PNG)
    after = b""
    if mapping:
        packed = b"".join(wire.varint(m) for m in mapping)  # packed int32: -1 takes 10 bytes
        after += wire.len_prefix(5, len(packed)) + packed
    if props:
        after += wire.len_prefix(6, len(props)) + props
    if int(spec.observation_type):
        after += wire.tag(7, wire.VARINT) + wire.varint(int(spec.observation_type))
    if spec.name:
        after += wire.field(8, spec.name.encode())
    pixels = np.clip(np.rint(np.asarray(observations, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)
    fields = []
    for agent in pixels:
        data = b"".join(_png_bytes(agent[c:c + 3]) for c in range(0, channels, 3))
        fields.append(wire.field(13, before + wire.field(3, data) + after))
    return fields


def _png_bytes(chw: np.ndarray) -> bytes:
    """One RGB PNG file of uint8 [c <= 3, H, W], as Unity's EncodeToPNG writes cameras: one
    channel is repeated in all three (readers average them back to gray), missing channels of a
    group are zero (the mapping drops them)."""
    from PIL import Image

    if chw.shape[0] == 1:
        rgb = np.repeat(chw, 3, axis=0)
    else:
        rgb = np.zeros((3, *chw.shape[1:]), dtype=np.uint8)
        rgb[: chw.shape[0]] = chw
    image = Image.fromarray(np.ascontiguousarray(np.moveaxis(rgb, 0, -1)), mode="RGB")
    out = io.BytesIO()
    image.save(out, format="PNG", compress_level=1)
    return out.getvalue()


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
