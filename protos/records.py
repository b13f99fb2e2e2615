"""Decoding many AgentInfoProtos at once, from their serialized bytes.

Parsed message by message, every agent costs the trainer several microseconds of Python attribute
access (measured ~5 µs per ball3d agent, the largest per-agent cost of an exchange). But the agents
of one behavior almost always serialize to the same *layout*: the same fields with the same
lengths, only the values differ. So:

1. the serialized ``ListAgentInfoProto`` is cut into its records: runs of consecutive records of
   one length are recognised at once from their headers at a fixed stride;
2. records of equal length form one uint8 matrix [rows, length]: a view of each run, joined by
   one copy when there are several (a gather by index for records of 128 bytes or more);
3. the first record is walked byte by byte, once, to learn its layout: which bytes are tags,
   length prefixes and other fixed content, which are values (the reward's 4 bytes, the id's
   varint bytes, each observation's packed floats, the action mask's bools);
4. every row is checked against that layout at once: all fixed bytes equal, and the continuation
   bit of every varint value byte equal (so every varint has the same length). Rows that pass
   parse exactly as the walked record does, so the values are plain matrix columns.

Anything else — PNG or other compressed observations, a field repeated where it should not be,
rows of one length whose layouts differ, an observation shape other than the behavior spec's —
makes ``decode`` return None, and the caller parses agent by agent (which also produces the
precise error messages for malformed input). Layouts are cached per (behavior, record length); rows of one length with different layouts are
split by layout (up to eight per length).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protos import wire

# AgentInfoProto (docs/protocol.md, "Message schema"): 7 reward f32, 8 done, 9 max_step_reached, 10 id int32,
# 11 action_mask repeated bool (packed), 13 observations, 14 group_id int32, 15 group_reward f32
_F32_FIELDS = (7, 15)
_VARINT_FIELDS = (8, 9, 10, 14)
_MASK, _OBSERVATIONS = 11, 13
# ObservationProto: 1 shape (packed int32), 2 compression_type, 3 compressed_data, 4 float_data
_SHAPE, _COMPRESSION, _COMPRESSED_DATA, _FLOAT_DATA = 1, 2, 3, 4
MIN_ROWS = 64  # below this many agents the per-agent parse is about as fast (measured; mixed layouts cost more)


class _Unsupported(Exception):
    """The record uses something the matrix path does not handle; parse agent by agent."""


def _varint(data: bytes, pos: int, end: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= end or shift > 63:
            raise _Unsupported("truncated varint")
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, pos
        shift += 7


def _key(record: bytes, pos: int, end: int, fixed: list[int]) -> tuple[int, int, int]:
    """(field number, wire type, position after the key); the key's bytes are fixed."""
    start = pos
    key, pos = _varint(record, pos, end)
    fixed.extend(range(start, pos))
    return key >> 3, key & 7, pos


def _length(record: bytes, pos: int, end: int, fixed: list[int]) -> tuple[int, int]:
    """A length prefix (fixed bytes) → (content start, content end)."""
    start = pos
    size, pos = _varint(record, pos, end)
    fixed.extend(range(start, pos))
    if pos + size > end:
        raise _Unsupported("truncated field")
    return pos, pos + size


_WIDTHS = {1: 8, 5: 4}  # wire type -> bytes of a fixed64 / fixed32 value


def _scalar(record: bytes, pos: int, end: int, wire_type: int) -> tuple[int, int]:
    """(start, end) of a value that is not length-delimited: varint, fixed64 or fixed32."""
    if wire_type == 0:
        return pos, _varint(record, pos, end)[1]
    width = _WIDTHS.get(wire_type)
    if width is None or pos + width > end:
        raise _Unsupported("group wire type or truncated value")
    return pos, pos + width


class _Checked:
    """A walked record's fixed bytes and varint value bytes, checked against many rows at once."""

    def _finish(self, record: bytes, fixed: list[int], cont: list[int]) -> None:
        # one check for both: fixed bytes compare whole, varint value bytes by continuation bit
        self.checked = np.array(fixed + cont, dtype=np.intp)
        self.check_mask = np.array([0xFF] * len(fixed) + [0x80] * len(cont), dtype=np.uint8)
        template = np.frombuffer(record, dtype=np.uint8)
        self.expected = template[self.checked] & self.check_mask

    def matches(self, rows: np.ndarray) -> np.ndarray:
        """bool [rows]: which rows parse exactly like the walked record."""
        return ((rows[:, self.checked] & self.check_mask) == self.expected).all(axis=1)


class _Layout(_Checked):
    """Where the fixed bytes and the values sit in an AgentInfoProto record of one length."""

    def __init__(self, record: bytes) -> None:
        self.length = len(record)
        fixed: list[int] = []
        cont: list[int] = []
        self.f32: dict[int, int] = {}  # field -> column of its 4 bytes
        self.varints: dict[int, list[int]] = {}  # field -> columns of its varint bytes
        self.mask: tuple[int, int] | None = None  # (first column, count) of packed bools
        self.obs: list[tuple[tuple[int, ...], int, int]] = []  # (shape, first column, floats)
        pos, end = 0, len(record)
        while pos < end:
            field, wire_type, pos = _key(record, pos, end, fixed)
            if wire_type == 2:
                pos, content_end = _length(record, pos, end, fixed)
                if field == _MASK:
                    if self.mask is not None or any(b >= 0x80 for b in record[pos:content_end]):
                        raise _Unsupported("split or multi-byte mask")
                    self.mask = (pos, content_end - pos)
                    cont.extend(range(pos, content_end))
                elif field == _OBSERVATIONS:
                    self.obs.append(_observation_layout(record, pos, content_end, fixed))
                else:
                    fixed.extend(range(pos, content_end))
                pos = content_end
                continue
            if field == _MASK:
                raise _Unsupported("unpacked action mask")
            start, pos = _scalar(record, pos, end, wire_type)
            if wire_type == 0 and field in _VARINT_FIELDS:
                if field in self.varints:
                    raise _Unsupported("repeated scalar")
                self.varints[field] = list(range(start, pos))
                cont.extend(range(start, pos))
            elif wire_type == 5 and field in _F32_FIELDS:
                if field in self.f32:
                    raise _Unsupported("repeated scalar")
                self.f32[field] = start
            else:
                fixed.extend(range(start, pos))
        self._finish(record, fixed, cont)


class _ActionLayout(_Checked):
    """The same for an AgentActionProto: 1 vector_actions_deprecated (packed float), 4 value
    (float), 6 continuous_actions (packed float), 7 discrete_actions (packed int32)."""

    def __init__(self, record: bytes) -> None:
        fixed: list[int] = []
        cont: list[int] = []
        self.continuous: tuple[int, int] = (0, 0)  # (first column, count)
        self.discrete: list[list[int]] = []  # the columns of each discrete action's varint
        seen: set[int] = set()
        pos, end = 0, len(record)
        while pos < end:
            field, wire_type, pos = _key(record, pos, end, fixed)
            if field in seen and field in (1, 4, 6, 7):
                raise _Unsupported("field split or repeated")
            seen.add(field)
            if wire_type == 2:
                pos, content_end = _length(record, pos, end, fixed)
                size = content_end - pos
                if field in (1, 6) and size % 4:
                    raise _Unsupported("bad packed field")
                if field == 6:
                    self.continuous = (pos, size // 4)
                elif field == 7:
                    p = pos
                    while p < content_end:
                        first = p
                        _, p = _varint(record, p, content_end)
                        self.discrete.append(list(range(first, p)))
                        cont.extend(range(first, p))
                elif field != 1:  # deprecated vector actions: values nobody reads here
                    fixed.extend(range(pos, content_end))
                pos = content_end
            elif field in (1, 6, 7):
                raise _Unsupported("unpacked actions")
            else:
                start, pos = _scalar(record, pos, end, wire_type)
                if (field, wire_type) != (4, 5):  # 4: the deprecated float value nobody reads
                    fixed.extend(range(start, pos))
        self._finish(record, fixed, cont)


def _observation_layout(record: bytes, pos: int, end: int, fixed: list[int]):
    """(shape, first payload column, float count) of one ObservationProto at [pos, end)."""
    shape: tuple[int, ...] = ()
    payload: tuple[int, int] | None = None
    while pos < end:
        field, wire_type, pos = _key(record, pos, end, fixed)
        if field == _COMPRESSED_DATA or (field == _SHAPE and wire_type != 2):
            raise _Unsupported("compressed or unpacked observation")
        if wire_type == 2:
            pos, content_end = _length(record, pos, end, fixed)
            if field == _SHAPE:
                dims, p = [], pos
                while p < content_end:
                    dim, p = _varint(record, p, content_end)
                    dims.append(dim)
                shape = tuple(dims)
                fixed.extend(range(pos, content_end))
            elif field == _FLOAT_DATA:
                if payload is not None:
                    raise _Unsupported("float_data twice")
                payload = _float_data_layout(record, pos, content_end, fixed)
            else:
                fixed.extend(range(pos, content_end))
            pos = content_end
        else:
            start, pos = _scalar(record, pos, end, wire_type)
            if field == _COMPRESSION and record[start:pos] != b"\x00":
                raise _Unsupported("compressed observation")
            fixed.extend(range(start, pos))
    first, count = payload if payload is not None else (0, 0)
    return shape, first, count


def _float_data_layout(record: bytes, pos: int, end: int, fixed: list[int]) -> tuple[int, int]:
    payload = None
    while pos < end:
        field, wire_type, pos = _key(record, pos, end, fixed)
        if (field, wire_type) != (1, 2) or payload is not None:
            raise _Unsupported("unexpected FloatData content")
        pos, content_end = _length(record, pos, end, fixed)
        if (content_end - pos) % 4:
            raise _Unsupported("bad float payload")
        payload = (pos, (content_end - pos) // 4)
        pos = content_end
    return payload if payload is not None else (0, 0)


def split_records(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """Start offsets and lengths of the records of a serialized ``repeated ... = 1`` message."""
    cut = _cut(data)
    return None if cut is None else cut[:2]


def _cut(data: bytes) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int, int]] | None] | None:
    """(starts, lengths, runs): ``runs`` lists (first record, header position, record count,
    length) of consecutive records of one length when every record is shorter than 128 bytes
    (2-byte headers), else None. None for anything but whole field-1 records."""
    end = len(data)
    # records shorter than 128 bytes have 2-byte headers. Runs of records of one length are
    # skipped at once: from a known record start, the headers of the next ``count`` records of
    # the same length would sit at a fixed stride, and the run goes on for as long as they read
    # (0x0A, length) (bytes.lstrip counts that in C). Each run ends where the length changes;
    # records all of one length (the common case) are one run.
    runs: list[tuple[int, int, int, int]] = []
    pos = row = 0
    while pos + 1 < end and data[pos] == 0x0A and data[pos + 1] < 0x80:
        size = data[pos + 1]
        stride = size + 2
        stop = pos + (end - pos) // stride * stride
        count = (stop - pos) // stride
        if count == 0:  # a truncated last record: the general walk below rejects it
            break
        run = min(count - len(data[pos:stop:stride].lstrip(b"\n")),
                  count - len(data[pos + 1:stop:stride].lstrip(bytes((size,)))))
        runs.append((row, pos, run, size))
        row += run
        pos += run * stride
    if pos == end:
        lengths = np.repeat(np.array([r[3] for r in runs], dtype=np.intp), [r[2] for r in runs])
        return np.cumsum(lengths + 2) - lengths, lengths, runs
    # a long record somewhere: the general walk
    starts, lengths = [], []
    pos = 0
    try:
        while pos < end:
            if data[pos] != 0x0A:
                return None
            size, pos = _varint(data, pos + 1, end)
            starts.append(pos)
            lengths.append(size)
            pos += size
    except _Unsupported:
        return None
    if pos != end:
        return None
    return np.array(starts, dtype=np.intp), np.array(lengths, dtype=np.intp), None


@dataclass
class Decoded:
    """Every agent's fields, in message order (the same values the per-agent parse gives)."""

    reward: np.ndarray  # float32 [n]
    group_reward: np.ndarray  # float32 [n]
    agent_id: np.ndarray  # int64 [n]
    group_id: np.ndarray  # int32 [n]
    done: np.ndarray  # bool [n]
    max_step: np.ndarray  # bool [n]
    obs: list[np.ndarray]  # float32 [n, *shape] per observation
    mask: np.ndarray  # bool [n, mask_width]; rows without a mask are all False


_LAYOUTS: dict[tuple, list[_Checked]] = {}
_MAX_LAYOUTS = 8  # per record length; more distinct layouts than this: parse agent by agent


def _groups(key, data: bytes, make_layout, cut=None) -> tuple[int, list]:
    """Cut ``data`` into records and sort them by layout: (record count, [(rows, uint8 matrix
    [rows, length], layout)]) covering every record once. Raises _Unsupported. ``cut``: the
    result of ``_cut(data)`` if the caller has it already."""
    if cut is None:
        cut = _cut(data)
    if cut is None:
        raise _Unsupported("not a repeated message field 1")
    starts, lengths, runs = cut
    n = len(starts)
    buf = np.frombuffer(data, dtype=np.uint8)
    groups = []
    distinct = sorted({run[3] for run in runs}) if runs is not None else sorted(set(lengths.tolist()))
    for length in distinct:
        if runs is not None:
            # each run of records of this length is a [count, length] view at a fixed stride
            # (no copy when there is one run); several are joined by one copy
            mine = [run for run in runs if run[3] == length]
            views = [buf[pos:pos + count * (length + 2)].reshape(count, length + 2)[:, 2:]
                     for _, pos, count, _ in mine]
            if len(mine) == 1:
                rows, matrix = np.arange(mine[0][0], mine[0][0] + mine[0][2]), views[0]
            else:
                rows = np.concatenate([np.arange(first, first + count) for first, _, count, _ in mine])
                matrix = np.concatenate(views)
        else:
            rows = np.arange(n) if len(distinct) == 1 else np.nonzero(lengths == length)[0]
            matrix = buf[starts[rows][:, None] + np.arange(length)]
        layouts = _LAYOUTS.setdefault((key, length), [])
        # rows of one length almost always share one layout; a few may not (e.g. a mask of
        # another width traded against an omitted field): each distinct layout is walked once
        for _ in range(_MAX_LAYOUTS):
            ok = None
            for layout in layouts:
                ok = layout.matches(matrix)
                if ok.any():
                    break
            if ok is None or not ok.any():
                first = int(starts[rows[0]])
                layout = make_layout(data[first:first + length])
                layouts.insert(0, layout)
                del layouts[_MAX_LAYOUTS:]
                ok = layout.matches(matrix)
            if ok.all():
                groups.append((rows, matrix, layout))
                break
            groups.append((rows[ok], matrix[ok], layout))
            rows, matrix = rows[~ok], matrix[~ok]
        else:
            raise _Unsupported("too many layouts")
    if len(_LAYOUTS) > 256:
        _LAYOUTS.clear()
    return n, groups


def decode(key: str, data: bytes, shapes: list[tuple[int, ...]], mask_width: int, cut=None) -> Decoded | None:
    """All AgentInfoProtos of serialized ListAgentInfoProto ``data``, or None (see module doc).

    ``shapes``: the behavior's observation shapes (all must be uncompressed floats);
    ``mask_width``: the sum of its discrete branch sizes.
    """
    try:
        n, groups = _groups(key, data, _Layout, cut)
    except _Unsupported:
        return None
    sizes = [math.prod(shape) for shape in shapes]
    for _, _, layout in groups:
        if len(layout.obs) != len(shapes) or any(
                shape != want or count != size
                for (shape, _, count), want, size in zip(layout.obs, shapes, sizes)):
            return None  # the per-agent parse reports the mismatch
        if layout.mask is not None and layout.mask[1] not in (0, mask_width):
            return None  # a mask of the wrong length: the per-agent parse reports it too
    out = Decoded(
        reward=np.zeros(n, np.float32), group_reward=np.zeros(n, np.float32),
        agent_id=np.zeros(n, np.int64), group_id=np.zeros(n, np.int32),
        done=np.zeros(n, bool), max_step=np.zeros(n, bool),
        obs=[np.zeros((n, *shape), np.float32) for shape in shapes],
        mask=np.zeros((n, mask_width), bool),
    )
    for rows, matrix, layout in groups:
        _fill(out, rows, matrix, layout, mask_width)
    return out


def decode_actions(key: str, data: bytes, continuous: int, branches: int
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """Serialized ListAgentActionProto → (continuous float32 [n, continuous], discrete int32
    [n, branches]), or None when the matrix path does not apply or any agent's widths differ
    (the per-agent path then reports it)."""
    try:
        n, groups = _groups(("actions", key), data, _ActionLayout)
    except _Unsupported:
        return None
    cont = np.zeros((n, continuous), np.float32)
    disc = np.zeros((n, branches), np.int32)
    for rows, matrix, layout in groups:
        column, count = layout.continuous
        if count != continuous or len(layout.discrete) != branches:
            return None
        if count:
            cont[rows] = _f32(matrix, column, count)
        for branch, columns in enumerate(layout.discrete):
            disc[rows, branch] = _int32(_varints(matrix, columns))
    return cont, disc


def _f32(matrix: np.ndarray, column: int, count: int = 1) -> np.ndarray:
    return np.ascontiguousarray(matrix[:, column:column + 4 * count]).view("<f4").astype(np.float32)


def _varints(matrix: np.ndarray, columns: list[int]) -> np.ndarray:
    if len(columns) == 1:
        return matrix[:, columns[0]].astype(np.uint64)
    groups = (matrix[:, columns] & 0x7F).astype(np.uint64) << _SHIFTS[:len(columns)]
    return groups.sum(axis=1, dtype=np.uint64)  # the 7-bit groups do not overlap: sum == or


_SHIFTS = np.arange(0, 70, 7, dtype=np.uint64)


def _int32(value: np.ndarray) -> np.ndarray:
    """Varint → int32 as protobuf reads it (negative numbers are sign-extended 10-byte varints)."""
    return value.view(np.int64).astype(np.int32)


def _fill(out: Decoded, rows, matrix: np.ndarray, layout: _Layout, mask_width: int) -> None:
    if 7 in layout.f32:
        out.reward[rows] = _f32(matrix, layout.f32[7])[:, 0]
    if 15 in layout.f32:
        out.group_reward[rows] = _f32(matrix, layout.f32[15])[:, 0]
    varints = layout.varints
    if 8 in varints:
        out.done[rows] = _varints(matrix, varints[8]) != 0
    if 9 in varints:
        out.max_step[rows] = _varints(matrix, varints[9]) != 0
    if 10 in varints:
        out.agent_id[rows] = _int32(_varints(matrix, varints[10]))
    if 14 in varints:
        out.group_id[rows] = _int32(_varints(matrix, varints[14]))
    for target, (shape, column, count) in zip(out.obs, layout.obs):
        if count:
            target[rows] = _f32(matrix, column, count).reshape(-1, *shape)
    if layout.mask is not None and layout.mask[1] == mask_width and mask_width:
        column, count = layout.mask
        out.mask[rows] = matrix[:, column:column + count] != 0


# --------------------------------------------------------------------------- whole messages
def _fields(data: bytes, start: int, end: int) -> list[tuple[int, int, int, int, int]]:
    """The fields of the message at data[start:end]: (number, wire type, key start, value
    start, value end) each. Raises _Unsupported on anything malformed."""
    out = []
    pos = start
    while pos < end:
        key_start = pos
        key, pos = _varint(data, pos, end)
        number, wire_type = key >> 3, key & 7
        if wire_type == 2:
            size, pos = _varint(data, pos, end)
            value_start, value_end = pos, pos + size
        else:
            value_start, value_end = _scalar(data, pos, end, wire_type)
        if value_end > end or number == 0:
            raise _Unsupported("malformed message")
        out.append((number, wire_type, key_start, value_start, value_end))
        pos = value_end
    return out


def _replace(data: bytes, fields: list, index: int, number: int, body: bytes) -> bytes:
    """The message of ``fields`` with field ``index`` replaced by a length-delimited ``body``."""
    parts = [data[f[2]:f[4]] for f in fields]
    parts[index] = wire.len_prefix(number, len(body)) + body
    return b"".join(parts)


def _only(fields: list, number: int) -> int:
    """Index of the single length-delimited field ``number``; raises if absent or repeated."""
    found = [i for i, f in enumerate(fields) if f[0] == number]
    if len(found) != 1 or fields[found[0]][1] != 2:
        raise _Unsupported("field absent, repeated or not a message")
    return found[0]


def split_agent_lists(payload: bytes, min_rows: int) -> tuple[bytes, dict[str, tuple[bytes, tuple]]] | None:
    """Take the large agent info lists out of a serialized UnityMessageProto before it is parsed.

    Returns (the message without those ``agentInfos`` map entries, {behavior: (serialized
    ListAgentInfoProto, its ``_cut``)}) for every list of at least ``min_rows`` records, so that
    they are decoded once, from their bytes (``decode``), instead of being parsed into protobuf
    objects and serialized again. None when there is no such list or anything is unusual (a
    field repeated, a map key twice, a malformed length): the caller then parses the message
    as it is.
    """
    try:
        top = _fields(payload, 0, len(payload))
        output_index = _only(top, 2)  # UnityMessageProto.unity_output
        output = top[output_index]
        middle = _fields(payload, output[3], output[4])
        rl_index = _only(middle, 1)  # UnityOutputProto.rl_output
        rl = middle[rl_index]
        taken: dict[str, tuple[bytes, tuple]] = {}
        seen: set[str] = set()
        kept: list[bytes] = []
        for field in _fields(payload, rl[3], rl[4]):
            if field[0] == 2 and field[1] == 2:  # UnityRLOutputProto.agentInfos map entry
                entry = _fields(payload, field[3], field[4])
                if [(f[0], f[1]) for f in entry] != [(1, 2), (2, 2)]:
                    return None  # an entry with a default or repeated key/value: parse it all
                name = payload[entry[0][3]:entry[0][4]].decode("utf-8")
                if name in seen:
                    return None
                seen.add(name)
                value = payload[entry[1][3]:entry[1][4]]
                cut = _cut(value)
                if cut is not None and len(cut[0]) >= min_rows:
                    taken[name] = (value, cut)
                    continue
            kept.append(payload[field[2]:field[4]])
        if not taken:
            return None
        middle_body = _replace(payload, middle, rl_index, 1, b"".join(kept))
        return _replace(payload, top, output_index, 2, middle_body), taken
    except (_Unsupported, UnicodeDecodeError):
        return None
