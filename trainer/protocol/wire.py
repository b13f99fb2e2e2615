"""Protobuf wire bytes for many equal-shaped records at once, built with numpy.

A repeated message field whose elements all have the same layout (the same fields, the same
lengths) serializes to rows of equal width: ``tag, length, content``. Building those rows as one
uint8 matrix replaces a Python loop that fills one message object per agent; the bytes are then
merged into the real message with ``MergeFromString`` (protobuf's C parser), so what finally goes
on the wire is still protobuf's own canonical serialization.

Field layouts used here (proto3, spec §2): packed repeated scalars are ``tag(LEN), byte length,
values``; a float is ``tag(I32)`` + 4 little-endian bytes; a varint field is ``tag(VARINT)`` +
varint. Integers whose varint length could differ between records are written as 5-byte varints
(continuation bits on the first four bytes), which every protobuf parser accepts and which the
merge turns back into the shortest form.
"""
from __future__ import annotations

from typing import Sequence, Union

import numpy as np

Part = Union[bytes, np.ndarray]  # constant bytes, or a uint8 [n, width] column block

VARINT, I64, LEN, I32 = 0, 1, 2, 5
MIN_MATRIX_ROWS = 8  # below this many records numpy's per-call cost loses to a plain loop


def varint(value: int) -> bytes:
    """The shortest varint of a non-negative integer."""
    if value < 0:
        raise ValueError("negative values need 10-byte varints; not used here")
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def tag(field_number: int, wire_type: int) -> bytes:
    return varint((field_number << 3) | wire_type)


def len_prefix(field_number: int, length: int) -> bytes:
    """Tag and byte length of a length-delimited field holding ``length`` bytes."""
    return tag(field_number, LEN) + varint(length)


def float_columns(values: np.ndarray, n: int) -> np.ndarray:
    """float [n, k] → uint8 [n, 4k] little-endian float32 bytes."""
    values = np.ascontiguousarray(np.asarray(values, dtype="<f4").reshape(n, -1))
    return values.view(np.uint8).reshape(n, -1)


def varint5_columns(values: np.ndarray) -> np.ndarray:
    """Non-negative integers [n] (< 2**32) → uint8 [n, 5] fixed-width (overlong) varints."""
    values = np.asarray(values, dtype=np.int64)
    if values.size and (values.min() < 0 or values.max() >= 1 << 32):
        raise ValueError("fixed-width varints hold 0 <= value < 2**32")
    out = np.empty((len(values), 5), dtype=np.uint8)
    for index in range(5):
        out[:, index] = (values >> (7 * index)) & 0x7F
    out[:, :4] |= 0x80
    return out


def width(part: Part) -> int:
    return len(part) if isinstance(part, (bytes, bytearray)) else part.shape[1]


def rows(parts: Sequence[Part], n: int) -> np.ndarray:
    """uint8 [n, sum of widths]: constant parts repeated on every row, column blocks as given."""
    total = sum(width(p) for p in parts)
    out = np.empty((n, total), dtype=np.uint8)
    column = 0
    for part in parts:
        w = width(part)
        if isinstance(part, (bytes, bytearray)):
            out[:, column : column + w] = np.frombuffer(bytes(part), dtype=np.uint8)
        else:
            out[:, column : column + w] = part
        column += w
    return out


def repeated_messages(field_number: int, content: np.ndarray) -> bytes:
    """Serialized repeated message field: each row of ``content`` is one element's bytes."""
    n, size = content.shape
    if n == 0:
        return b""
    return rows([len_prefix(field_number, size), content], n).tobytes()
