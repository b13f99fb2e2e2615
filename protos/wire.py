"""Protobuf wire bytes for many equal-shaped records at once, built with numpy.

A repeated message field whose elements all have the same layout (the same fields, the same
lengths) serializes to rows of equal width: ``tag, length, content``. Building those rows as one
uint8 matrix replaces a Python loop that fills one message object per agent. Records of a few
different lengths are built as one matrix of the longest layout, and a byte mask drops what
each record leaves out.

Field layouts used here (proto3, docs/protocol.md, "Message schema"): packed repeated scalars are
``tag(LEN), byte length, values``; a float is ``tag(I32)`` + 4 little-endian bytes; a varint field is ``tag(VARINT)`` +
the shortest varint (``varint_columns`` for a column of integers).
"""
from __future__ import annotations

import functools
from typing import Sequence, Union

import numpy as np

Part = Union[bytes, np.ndarray]  # constant bytes, or a uint8 [n, width] column block

VARINT, I64, LEN, I32 = 0, 1, 2, 5
MIN_MATRIX_ROWS = 8  # below this many records numpy's per-call cost loses to a plain loop


_ONE_BYTE = tuple(bytes([value]) for value in range(0x80))  # the varints of 0..127


def varint(value: int) -> bytes:
    """The shortest varint of an integer; a negative int32/int64 is written as protobuf does,
    as the 10-byte varint of its 64-bit two's complement."""
    if 0 <= value < 0x80:  # tags, lengths and ids of small messages: no loop, no new bytes
        return _ONE_BYTE[value]
    if value < 0:
        value += 1 << 64
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


@functools.lru_cache(maxsize=256)
def tag(field_number: int, wire_type: int) -> bytes:
    return varint((field_number << 3) | wire_type)


@functools.lru_cache(maxsize=4096)
def len_prefix(field_number: int, length: int) -> bytes:
    """Tag and byte length of a length-delimited field holding ``length`` bytes (cached: a
    simulator's messages repeat the same few lengths every step)."""
    return tag(field_number, LEN) + varint(length)


def field(field_number: int, content: bytes) -> bytes:
    """A length-delimited field: tag, byte length, then ``content`` (a sub-message, bytes, a
    packed array)."""
    return len_prefix(field_number, len(content)) + content


def map_entry(field_number: int, key: str, value: bytes) -> bytes:
    """One entry of a ``map<string, Message>`` field: key (1), then the serialized value (2)."""
    name = key.encode()
    return field(field_number, len_prefix(1, len(name)) + name + len_prefix(2, len(value)) + value)


def float_columns(values: np.ndarray, n: int) -> np.ndarray:
    """float [n, k] → uint8 [n, 4k] little-endian float32 bytes."""
    values = np.ascontiguousarray(np.asarray(values, dtype="<f4").reshape(n, -1))
    return values.view(np.uint8).reshape(n, -1)


_VARINT_SHIFTS = np.arange(0, 35, 7, dtype=np.int64)
_VARINT_LIMITS = 1 << _VARINT_SHIFTS[1:]  # a varint of 0 <= v < 2**35 is 1 + (v >= each) bytes


def varint_columns(values: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Integers [n] (0 <= v < 2**31) → (uint8 [n, w], bool [n, w] or None): each one's shortest
    varint, left-aligned in as many columns as the longest needs, and which columns each uses
    (None when all use all w)."""
    values = np.asarray(values, dtype=np.int64)
    low, high = (int(values.min()), int(values.max())) if values.size else (0, 0)
    if low < 0 or high >= 1 << 31:
        raise ValueError("varint columns hold 0 <= value < 2**31 (non-negative int32)")
    width = len(varint(high))
    if width == 1:
        return values.astype(np.uint8)[:, None], None
    columns = ((values[:, None] >> _VARINT_SHIFTS[:width]) & 0x7F).astype(np.uint8)
    if width == len(varint(low)):  # all of one length: no per-value work
        columns[:, :width - 1] |= 0x80
        return columns, None
    lengths = 1 + (values[:, None] >= _VARINT_LIMITS[:width - 1]).sum(axis=1)
    position = np.arange(width)
    columns[position < lengths[:, None] - 1] |= 0x80
    return columns, position < lengths[:, None]


def width(part: Part) -> int:
    return len(part) if isinstance(part, (bytes, bytearray)) else part.shape[1]


# the constant bytes of a row layout, laid out once: (template row, [(column, width)] of the blocks)
_TEMPLATES: dict[tuple, tuple[np.ndarray, list[tuple[int, int]]]] = {}


def rows(parts: Sequence[Part], n: int) -> np.ndarray:
    """uint8 [n, sum of widths]: constant parts repeated on every row, column blocks as given.

    The constant parts of a layout are laid into a template row once (cached by layout); each
    call copies the template into every row and writes only the column blocks.
    """
    parts = [bytes(p) if isinstance(p, bytearray) else p for p in parts]
    key = tuple(p if isinstance(p, bytes) else p.shape[1] for p in parts)
    cached = _TEMPLATES.get(key)
    if cached is None:
        template = np.zeros(sum(len(k) if isinstance(k, bytes) else k for k in key), dtype=np.uint8)
        blocks, column = [], 0
        for k in key:
            if isinstance(k, bytes):
                template[column:column + len(k)] = np.frombuffer(k, dtype=np.uint8)
                column += len(k)
            else:
                blocks.append((column, k))
                column += k
        if len(_TEMPLATES) > 256:
            _TEMPLATES.clear()
        cached = _TEMPLATES[key] = (template, blocks)
    template, blocks = cached
    out = np.empty((n, len(template)), dtype=np.uint8)
    out[:] = template
    for (column, w), part in zip(blocks, [p for p in parts if not isinstance(p, bytes)]):
        out[:, column:column + w] = part
    return out


# UnityMessageProto.header (1) = HeaderProto{status (1) = 200}: every answer and every step
# message starts with these bytes; both ends write them directly
_HEADER_OK = tag(1, VARINT) + varint(200)
HEADER_OK_FIELD = len_prefix(1, len(_HEADER_OK)) + _HEADER_OK


def repeated_rows(field_number: int, parts: Sequence[Part], n: int) -> bytes:
    """A serialized repeated message field of n elements whose bytes are ``rows(parts, n)``:
    each element's header (tag, length) is one more constant part of its row."""
    if n == 0:
        return b""
    return rows([len_prefix(field_number, sum(width(p) for p in parts)), *parts], n).tobytes()

