"""Side channel wire format: message framing and little-endian payload primitives (docs/protocol.md, "Framing").

Framing: the ``side_channel`` field is a concatenation of messages, each
``16 bytes channel UUID (uuid.bytes_le, .NET Guid order) | int32 payload length n | n bytes payload``.
Primitives: bool (1 byte), int32, float32, string (int32 byte length + ASCII bytes),
float list (int32 count + that many float32). Import these through ``protos.side_channels``.
"""
from __future__ import annotations

import struct
import uuid
from typing import Iterable

import numpy as np

from protos.errors import ProtocolError

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
