"""Side channels: the ``side_channel`` bytes of ``UnityRLInputProto``/``UnityRLOutputProto``.

Pure encoders and decoders for both directions (trainer side and Unity side), so the trainer and
``unity_stub_env`` speak exactly the same bytes. Everything is little-endian.

Framing and payload primitives (docs/protocol.md, "Framing") live in ``side_channel_wire`` and are
re-exported here, so this module is the one import site for both the trainer and ``unity_stub_env``.

Channels (docs/protocol.md, "Known channels"): engine configuration and environment parameters
(trainer → Unity), float properties (both ways) and stats (Unity → trainer). The trainer sends no training analytics
(the stub only recognises their channel id). Unknown channel ids are warned about once and skipped.
"""
from __future__ import annotations

import enum
import logging
import uuid
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from protos.errors import ProtocolError
from protos.side_channel_wire import (  # re-exported: framing and primitives
    PayloadReader,
    PayloadWriter,
    pack_messages,
    unpack_messages,
)
from protos.types import StatsAggregationMethod

logger = logging.getLogger("mlagents_like")

ENGINE_CONFIG_CHANNEL_ID = uuid.UUID("e951342c-4f7e-11ea-b238-784f4387d1f7")
ENVIRONMENT_PARAMETERS_CHANNEL_ID = uuid.UUID("534c891e-810f-11ea-a9d0-822485860400")
FLOAT_PROPERTIES_CHANNEL_ID = uuid.UUID("60ccf7d0-4f7e-11ea-b238-784f4387d1f7")
STATS_CHANNEL_ID = uuid.UUID("a1d8f7b7-cec8-50f9-b78b-d3e165a78520")
TRAINING_ANALYTICS_CHANNEL_ID = uuid.UUID("b664a4a9-d86f-5a5f-95cb-e8353a7e8356")


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


def encode_env_sequences(key: str, codes, num_labels: int) -> list[bytes]:
    """Label sequences as plain float parameters a Unity game reads with
    ``EnvironmentParameters.GetWithDefault`` (docs/protocol.md, "Label sequences"): ``KEY.count``,
    ``KEY.length``, ``KEY.labels`` (how many labels the model has), then ``KEY.i`` for
    i = k * length + t, the code of label t of sequence k. codes: int [count, length]."""
    codes = np.asarray(codes).reshape(len(codes), -1)
    count, length = codes.shape
    payloads = [encode_env_float(f"{key}.count", count), encode_env_float(f"{key}.length", length),
                encode_env_float(f"{key}.labels", num_labels)]
    payloads += [encode_env_float(f"{key}.{i}", float(code)) for i, code in enumerate(codes.ravel().tolist())]
    return payloads


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

    stats: (key, value, aggregation) in wire order; float_properties: last value per key.
    """

    stats: list[tuple[str, float, StatsAggregationMethod]] = field(default_factory=list)
    float_properties: dict[str, float] = field(default_factory=dict)


class SideChannelRouter:
    """Trainer side: queues outgoing messages and decodes incoming ones.

    Not thread-safe on its own; one router belongs to one simulator connection. Routers given
    the same ``warned_ids`` set (one run's simulators) warn about an unknown channel id once between them.
    """

    def __init__(self, warned_ids: set[uuid.UUID] | None = None) -> None:
        self._outgoing: list[tuple[uuid.UUID, bytes]] = []
        self._warned_ids: set[uuid.UUID] = set() if warned_ids is None else warned_ids

    def queue(self, channel_id: uuid.UUID, payload: bytes) -> None:
        """Queue one message; it leaves with the next ``drain()``."""
        self._outgoing.append((channel_id, bytes(payload)))

    def drain(self) -> bytes:
        """All queued messages framed in queue order; the queue is then empty."""
        data = pack_messages(self._outgoing)
        self._outgoing = []
        return data

    def dispatch(self, data: bytes) -> IncomingSideChannelData:
        """Decode a Unity → trainer ``side_channel`` field. Unknown ids are warned once and skipped."""
        incoming = IncomingSideChannelData()
        for channel_id, payload in unpack_messages(data):
            if channel_id == STATS_CHANNEL_ID:
                incoming.stats.append(decode_stat(payload))
            elif channel_id == FLOAT_PROPERTIES_CHANNEL_ID:
                key, value = decode_float_property(payload)
                incoming.float_properties[key] = value
            elif channel_id not in self._warned_ids:
                self._warned_ids.add(channel_id)
                logger.warning(
                    "Unknown side channel id %s sent by the simulator; its messages are ignored "
                    "(mlagents-like-learn has no custom side channels).",
                    channel_id,
                )
        return incoming


__all__ = [
    "ENGINE_CONFIG_CHANNEL_ID", "ENVIRONMENT_PARAMETERS_CHANNEL_ID", "FLOAT_PROPERTIES_CHANNEL_ID",
    "STATS_CHANNEL_ID", "TRAINING_ANALYTICS_CHANNEL_ID", "pack_messages", "unpack_messages",
    "PayloadWriter", "PayloadReader", "EngineConfigType", "encode_engine_config",
    "decode_engine_config", "SAMPLER_TYPES", "encode_env_float", "encode_env_sampler", "encode_env_sequences",
    "EnvParameter", "decode_env_parameter", "encode_float_property", "decode_float_property",
    "encode_stat", "decode_stat", "IncomingSideChannelData",
    "SideChannelRouter",
]
