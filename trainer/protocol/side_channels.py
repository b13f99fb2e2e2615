"""Side channels: the ``side_channel`` bytes of ``UnityRLInputProto``/``UnityRLOutputProto``.

Pure encoders and decoders for both directions (trainer side and Unity side), so the trainer and
``unity_stub_env`` speak exactly the same bytes. Everything is little-endian.

Framing (spec §4.1): the field is a concatenation of messages, each
``16 bytes channel UUID (uuid.bytes_le, .NET Guid order) | int32 payload length n | n bytes payload``.

Payload primitives: bool (1 byte), int32, float32, string (int32 byte length + ASCII bytes),
float list (int32 count + that many float32).

Channels (spec §4.2): engine configuration and environment parameters (trainer → Unity), float
properties (both ways), stats (Unity → trainer) and training analytics (trainer → Unity, see
``trainer.protocol.training_analytics``). Unknown channel ids are warned about once and skipped.
"""
from __future__ import annotations

import enum
import logging
import struct
import uuid
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from trainer.errors import ProtocolError
from trainer.protocol.training_analytics import (  # re-exported: one import site for channels
    encode_training_behavior_initialized,
    encode_training_environment_initialized,
    hash_for_analytics,
)
from trainer.protocol.types import StatsAggregationMethod

logger = logging.getLogger("mlagents_like")

ENGINE_CONFIG_CHANNEL_ID = uuid.UUID("e951342c-4f7e-11ea-b238-784f4387d1f7")
ENVIRONMENT_PARAMETERS_CHANNEL_ID = uuid.UUID("534c891e-810f-11ea-a9d0-822485860400")
FLOAT_PROPERTIES_CHANNEL_ID = uuid.UUID("60ccf7d0-4f7e-11ea-b238-784f4387d1f7")
STATS_CHANNEL_ID = uuid.UUID("a1d8f7b7-cec8-50f9-b78b-d3e165a78520")
TRAINING_ANALYTICS_CHANNEL_ID = uuid.UUID("b664a4a9-d86f-5a5f-95cb-e8353a7e8356")

_HEADER = struct.Struct("<16si")


# --------------------------------------------------------------------------------------------
# Framing
# --------------------------------------------------------------------------------------------
def pack_messages(messages: Iterable[tuple[uuid.UUID, bytes]]) -> bytes:
    """Concatenate (channel id, payload) pairs into one ``side_channel`` field, in the given order."""
    parts = []
    for channel_id, payload in messages:
        parts.append(_HEADER.pack(channel_id.bytes_le, len(payload)))
        parts.append(bytes(payload))
    return b"".join(parts)


def unpack_messages(data: bytes) -> list[tuple[uuid.UUID, bytes]]:
    """Split a ``side_channel`` field into (channel id, payload) pairs, in wire order.

    Raises ProtocolError on a truncated header, a negative length or a payload that runs past the end.
    """
    messages: list[tuple[uuid.UUID, bytes]] = []
    offset = 0
    total = len(data)
    while offset < total:
        if total - offset < _HEADER.size:
            raise ProtocolError(
                f"Side channel data is truncated: a message header needs {_HEADER.size} bytes at "
                f"offset {offset} but only {total - offset} remain (buffer of {total} bytes). "
                "The simulator sent garbled side channel data; check the ML-Agents package version."
            )
        raw_id, length = _HEADER.unpack_from(data, offset)
        channel_id = uuid.UUID(bytes_le=raw_id)
        offset += _HEADER.size
        if length < 0:
            raise ProtocolError(
                f"Side channel message for channel {channel_id} has a negative payload length "
                f"{length} at offset {offset - 4}. The simulator sent garbled side channel data."
            )
        if offset + length > total:
            raise ProtocolError(
                f"Side channel message for channel {channel_id} is truncated: its payload of "
                f"{length} bytes starts at offset {offset} but only {total - offset} bytes remain."
            )
        messages.append((channel_id, bytes(data[offset : offset + length])))
        offset += length
    return messages


# --------------------------------------------------------------------------------------------
# Payload primitives
# --------------------------------------------------------------------------------------------
class PayloadWriter:
    """Builds one side channel payload from little-endian primitives."""

    def __init__(self) -> None:
        self._parts: list[bytes] = []

    def write_bool(self, value: bool) -> "PayloadWriter":
        self._parts.append(struct.pack("<?", bool(value)))
        return self

    def write_int32(self, value: int) -> "PayloadWriter":
        self._parts.append(struct.pack("<i", int(value)))
        return self

    def write_float32(self, value: float) -> "PayloadWriter":
        self._parts.append(struct.pack("<f", float(value)))
        return self

    def write_string(self, value: str) -> "PayloadWriter":
        try:
            encoded = value.encode("ascii")
        except UnicodeEncodeError:
            raise ValueError(
                f"Side channel strings must be ASCII (Unity decodes them as ASCII), got {value!r}; "
                "rename it using ASCII characters only."
            ) from None
        self._parts.append(struct.pack("<i", len(encoded)))
        self._parts.append(encoded)
        return self

    def write_float_list(self, values: Iterable[float]) -> "PayloadWriter":
        floats = np.asarray(list(values), dtype="<f4")
        self._parts.append(struct.pack("<i", len(floats)))
        self._parts.append(floats.tobytes())
        return self

    def write_raw_bytes(self, data: bytes) -> "PayloadWriter":
        self._parts.append(bytes(data))
        return self

    def getvalue(self) -> bytes:
        return b"".join(self._parts)


class PayloadReader:
    """Reads little-endian primitives from one payload; raises ProtocolError when it runs short."""

    def __init__(self, payload: bytes, what: str = "side channel payload") -> None:
        self._data = bytes(payload)
        self._offset = 0
        self._what = what

    @property
    def remaining(self) -> int:
        return len(self._data) - self._offset

    def _take(self, size: int, kind: str) -> bytes:
        if size < 0 or self._offset + size > len(self._data):
            raise ProtocolError(
                f"The {self._what} is too short: reading {kind} of {size} bytes at offset "
                f"{self._offset}, but the payload has {len(self._data)} bytes."
            )
        chunk = self._data[self._offset : self._offset + size]
        self._offset += size
        return chunk

    def read_bool(self) -> bool:
        return self._take(1, "a bool")[0] != 0

    def read_int32(self) -> int:
        return struct.unpack("<i", self._take(4, "an int32"))[0]

    def read_float32(self) -> float:
        return struct.unpack("<f", self._take(4, "a float32"))[0]

    def read_string(self) -> str:
        length = self.read_int32()
        raw = self._take(length, "a string")
        try:
            return raw.decode("ascii")
        except UnicodeDecodeError:
            raise ProtocolError(f"The {self._what} holds a non-ASCII string {raw!r}.") from None

    def read_float_list(self) -> list[float]:
        count = self.read_int32()
        raw = self._take(4 * count, f"a list of {count} float32")
        return [float(v) for v in np.frombuffer(raw, dtype="<f4")]

    def read_raw_bytes(self) -> bytes:
        return self._take(self.remaining, "the rest")


# --------------------------------------------------------------------------------------------
# Engine configuration (trainer → Unity)
# --------------------------------------------------------------------------------------------
class EngineConfigType(enum.IntEnum):
    SCREEN_RESOLUTION = 0
    QUALITY_LEVEL = 1
    TIME_SCALE = 2
    TARGET_FRAME_RATE = 3
    CAPTURE_FRAME_RATE = 4


def encode_engine_config(
    width: int,
    height: int,
    quality_level: int,
    time_scale: float,
    target_frame_rate: int,
    capture_frame_rate: int,
) -> list[bytes]:
    """The five engine configuration payloads, one per setting, in type order 0..4."""
    return [
        PayloadWriter().write_int32(EngineConfigType.SCREEN_RESOLUTION)
        .write_int32(width).write_int32(height).getvalue(),
        PayloadWriter().write_int32(EngineConfigType.QUALITY_LEVEL).write_int32(quality_level).getvalue(),
        PayloadWriter().write_int32(EngineConfigType.TIME_SCALE).write_float32(time_scale).getvalue(),
        PayloadWriter().write_int32(EngineConfigType.TARGET_FRAME_RATE)
        .write_int32(target_frame_rate).getvalue(),
        PayloadWriter().write_int32(EngineConfigType.CAPTURE_FRAME_RATE)
        .write_int32(capture_frame_rate).getvalue(),
    ]


def decode_engine_config(payload: bytes) -> tuple[str, object]:
    """One engine configuration payload → ("screen_resolution", (w, h)) or (setting name, value)."""
    reader = PayloadReader(payload, "engine configuration payload")
    kind = reader.read_int32()
    if kind == EngineConfigType.SCREEN_RESOLUTION:
        return "screen_resolution", (reader.read_int32(), reader.read_int32())
    if kind == EngineConfigType.QUALITY_LEVEL:
        return "quality_level", reader.read_int32()
    if kind == EngineConfigType.TIME_SCALE:
        return "time_scale", reader.read_float32()
    if kind == EngineConfigType.TARGET_FRAME_RATE:
        return "target_frame_rate", reader.read_int32()
    if kind == EngineConfigType.CAPTURE_FRAME_RATE:
        return "capture_frame_rate", reader.read_int32()
    raise ProtocolError(f"Unknown engine configuration type {kind} (expected 0..4).")


# --------------------------------------------------------------------------------------------
# Environment parameters (trainer → Unity)
# --------------------------------------------------------------------------------------------
_ENV_FLOAT, _ENV_SAMPLER = 0, 1
SAMPLER_TYPES = {"uniform": 0, "gaussian": 1, "multirangeuniform": 2}
_SAMPLER_NAMES = {code: name for name, code in SAMPLER_TYPES.items()}


def encode_env_float(key: str, value: float) -> bytes:
    """A constant environment parameter: string key, int32 0, float32 value."""
    return PayloadWriter().write_string(key).write_int32(_ENV_FLOAT).write_float32(value).getvalue()


def encode_env_sampler(key: str, sampler_type: str, seed: int, params) -> bytes:
    """A sampled environment parameter.

    params: uniform (min, max); gaussian (mean, st_dev); multirangeuniform a list of (min, max)
    pairs, sent flattened as a float list [min0, max0, min1, max1, ...].
    """
    if sampler_type not in SAMPLER_TYPES:
        raise ValueError(
            f"Unknown sampler type {sampler_type!r} for environment parameter {key!r}; "
            f"use one of {sorted(SAMPLER_TYPES)}."
        )
    writer = PayloadWriter().write_string(key).write_int32(_ENV_SAMPLER)
    writer.write_int32(seed).write_int32(SAMPLER_TYPES[sampler_type])
    if sampler_type == "multirangeuniform":
        writer.write_float_list(float(v) for pair in params for v in pair)
    else:
        first, second = params
        writer.write_float32(first).write_float32(second)
    return writer.getvalue()


@dataclass(frozen=True)
class EnvParameter:
    """A decoded environment parameter as Unity holds it.

    kind: "float" | "uniform" | "gaussian" | "multirangeuniform"; seed: None for "float";
    values: (value,) | (min, max) | (mean, st_dev) | flattened (min0, max0, min1, max1, ...).
    """

    kind: str
    seed: int | None
    values: tuple[float, ...]

    def sampler(self) -> Callable[[], float]:
        """A callable that draws a fresh value on each call, like Unity reading the parameter."""
        if self.kind == "float":
            value = self.values[0]
            return lambda: value
        rng = np.random.default_rng(self.seed)
        if self.kind == "uniform":
            low, high = self.values
            return lambda: float(rng.uniform(low, high))
        if self.kind == "gaussian":
            mean, st_dev = self.values
            return lambda: float(rng.normal(mean, st_dev))
        return _multirange_sampler(rng, self.values)


def _multirange_sampler(rng: np.random.Generator, flat: tuple[float, ...]) -> Callable[[], float]:
    """Pick an interval with probability proportional to its length, then a uniform value in it."""
    intervals = np.asarray(flat, dtype=np.float64).reshape(-1, 2)
    if len(intervals) == 0:
        raise ProtocolError("A multirangeuniform sampler arrived with no intervals.")
    lengths = intervals[:, 1] - intervals[:, 0]
    total = lengths.sum()
    weights = lengths / total if total > 0 else np.full(len(lengths), 1.0 / len(lengths))

    def draw() -> float:
        low, high = intervals[rng.choice(len(intervals), p=weights)]
        return float(rng.uniform(low, high))

    return draw


def decode_env_parameter(payload: bytes) -> tuple[str, EnvParameter]:
    """One environment parameters payload → (key, EnvParameter)."""
    reader = PayloadReader(payload, "environment parameters payload")
    key = reader.read_string()
    data_type = reader.read_int32()
    if data_type == _ENV_FLOAT:
        return key, EnvParameter("float", None, (reader.read_float32(),))
    if data_type != _ENV_SAMPLER:
        raise ProtocolError(f"Environment parameter {key!r} has unknown data type {data_type}.")
    seed = reader.read_int32()
    sampler_code = reader.read_int32()
    if sampler_code not in _SAMPLER_NAMES:
        raise ProtocolError(f"Environment parameter {key!r} has unknown sampler type {sampler_code}.")
    kind = _SAMPLER_NAMES[sampler_code]
    if kind == "multirangeuniform":
        values = tuple(reader.read_float_list())
        if len(values) % 2:
            raise ProtocolError(f"Multirange sampler {key!r} has an odd number of bounds {values}.")
    else:
        values = (reader.read_float32(), reader.read_float32())
    return key, EnvParameter(kind, seed, values)


# --------------------------------------------------------------------------------------------
# Float properties (both ways) and stats (Unity → trainer)
# --------------------------------------------------------------------------------------------
def encode_float_property(key: str, value: float) -> bytes:
    return PayloadWriter().write_string(key).write_float32(value).getvalue()


def decode_float_property(payload: bytes) -> tuple[str, float]:
    reader = PayloadReader(payload, "float properties payload")
    return reader.read_string(), reader.read_float32()


def encode_stat(key: str, value: float, aggregation: StatsAggregationMethod) -> bytes:
    return PayloadWriter().write_string(key).write_float32(value).write_int32(aggregation).getvalue()


def decode_stat(payload: bytes) -> tuple[str, float, StatsAggregationMethod]:
    reader = PayloadReader(payload, "stats payload")
    key = reader.read_string()
    value = reader.read_float32()
    code = reader.read_int32()
    try:
        aggregation = StatsAggregationMethod(code)
    except ValueError:
        raise ProtocolError(f"Stat {key!r} has unknown aggregation method {code} (expected 0..3).") from None
    return key, value, aggregation


# --------------------------------------------------------------------------------------------
# Trainer-side router
# --------------------------------------------------------------------------------------------
@dataclass
class IncomingSideChannelData:
    """What Unity sent in one message's side channel field, decoded.

    stats: (key, value, aggregation) in wire order; float_properties: last value per key;
    raw: payloads per registered raw channel id, in wire order.
    """

    stats: list[tuple[str, float, StatsAggregationMethod]] = field(default_factory=list)
    float_properties: dict[str, float] = field(default_factory=dict)
    raw: dict[uuid.UUID, list[bytes]] = field(default_factory=dict)


class SideChannelRouter:
    """Trainer side: queues outgoing messages and decodes incoming ones.

    Not thread-safe on its own; one router belongs to one simulator connection.
    """

    def __init__(self) -> None:
        self._outgoing: list[tuple[uuid.UUID, bytes]] = []
        self._raw_callbacks: dict[uuid.UUID, Callable[[bytes], None] | None] = {}
        self._warned_ids: set[uuid.UUID] = set()

    def queue(self, channel_id: uuid.UUID, payload: bytes) -> None:
        """Queue one message; it leaves with the next ``drain()``."""
        self._outgoing.append((channel_id, bytes(payload)))

    def drain(self) -> bytes:
        """All queued messages framed in queue order; the queue is then empty."""
        data = pack_messages(self._outgoing)
        self._outgoing = []
        return data

    def register_raw(self, channel_id: uuid.UUID, callback: Callable[[bytes], None] | None = None) -> None:
        """Accept raw messages on ``channel_id``: each payload goes to ``callback`` (if given) and
        into ``IncomingSideChannelData.raw``."""
        if channel_id in (STATS_CHANNEL_ID, FLOAT_PROPERTIES_CHANNEL_ID):
            raise ValueError(f"Channel {channel_id} is built in and cannot be registered as raw.")
        self._raw_callbacks[channel_id] = callback

    def dispatch(self, data: bytes) -> IncomingSideChannelData:
        """Decode a Unity → trainer ``side_channel`` field. Unknown ids are warned once and skipped."""
        incoming = IncomingSideChannelData()
        for channel_id, payload in unpack_messages(data):
            if channel_id == STATS_CHANNEL_ID:
                incoming.stats.append(decode_stat(payload))
            elif channel_id == FLOAT_PROPERTIES_CHANNEL_ID:
                key, value = decode_float_property(payload)
                incoming.float_properties[key] = value
            elif channel_id in self._raw_callbacks:
                incoming.raw.setdefault(channel_id, []).append(payload)
                callback = self._raw_callbacks[channel_id]
                if callback is not None:
                    callback(payload)
            elif channel_id not in self._warned_ids:
                self._warned_ids.add(channel_id)
                logger.warning(
                    "Unknown side channel id %s sent by the simulator; its messages are ignored. "
                    "If the Unity project registers a custom side channel, register it on the "
                    "trainer too.",
                    channel_id,
                )
        return incoming

__all__ = [
    "ENGINE_CONFIG_CHANNEL_ID", "ENVIRONMENT_PARAMETERS_CHANNEL_ID", "FLOAT_PROPERTIES_CHANNEL_ID",
    "STATS_CHANNEL_ID", "TRAINING_ANALYTICS_CHANNEL_ID", "pack_messages", "unpack_messages",
    "PayloadWriter", "PayloadReader", "EngineConfigType", "encode_engine_config",
    "decode_engine_config", "SAMPLER_TYPES", "encode_env_float", "encode_env_sampler",
    "EnvParameter", "decode_env_parameter", "encode_float_property", "decode_float_property",
    "encode_stat", "decode_stat", "encode_training_environment_initialized",
    "encode_training_behavior_initialized", "hash_for_analytics", "IncomingSideChannelData",
    "SideChannelRouter",
]
