"""Protobuf wire format written out by hand, field by field (no generated classes involved).

Used to write down golden bytes for ``transcript_basic.json``. Only what proto3 needs here:

  tag(n, wt)     = varint((n << 3) | wt); wire types 0 varint, 2 length-delimited, 5 fixed32
  varint(v)      = 7 bits per byte, least significant group first, high bit = "more follows";
                   negative int32 values are sign-extended to 64 bits (10 bytes)
  ld(n, payload) = tag(n, 2) + varint(len(payload)) + payload     (strings, bytes, messages,
                   packed repeated scalars, map entries)
  proto3 leaves out fields that hold their default value (0, false, "", empty) — callers
  simply do not emit them; messages are written in ascending field-number order, which is
  what both Google.Protobuf (C#) and the Python runtime do.
"""
from __future__ import annotations

import struct


def varint(value: int) -> bytes:
    """Base-128 varint; negative numbers as their 64-bit two's complement (like int32 fields)."""
    if value < 0:
        value += 1 << 64
    out = bytearray()
    while True:
        low = value & 0x7F
        value >>= 7
        if value:
            out.append(low | 0x80)
        else:
            out.append(low)
            return bytes(out)


def tag(field_number: int, wire_type: int) -> bytes:
    return varint((field_number << 3) | wire_type)


def int_field(field_number: int, value: int) -> bytes:
    """int32 / enum / bool field (wire type 0)."""
    return tag(field_number, 0) + varint(int(value))


def float_field(field_number: int, value: float) -> bytes:
    """float field (wire type 5, IEEE-754 single, little-endian)."""
    return tag(field_number, 5) + struct.pack("<f", value)


def ld(field_number: int, payload: bytes) -> bytes:
    """Length-delimited field (wire type 2)."""
    return tag(field_number, 2) + varint(len(payload)) + payload


def string_field(field_number: int, text: str) -> bytes:
    return ld(field_number, text.encode("utf-8"))


def packed_varints(field_number: int, values) -> bytes:
    """Packed repeated int32 / bool / enum."""
    return ld(field_number, b"".join(varint(int(v)) for v in values))


def packed_floats(field_number: int, values) -> bytes:
    """Packed repeated float."""
    return ld(field_number, b"".join(struct.pack("<f", v) for v in values))


def map_entry(field_number: int, key: str, value_message: bytes) -> bytes:
    """One entry of a map<string, Message>: a nested message {1: key, 2: value}."""
    return ld(field_number, string_field(1, key) + ld(2, value_message))
