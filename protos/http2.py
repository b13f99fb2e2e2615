"""HTTP/2 framing that both ends of the wire use: the trainer's server
(trainer/protocol/http2_server.py) and the simulator's client (unity_stub_env/http2_client.py).

Frame types, flags, settings ids, error and gRPC status codes; writing a frame and taking complete
frames off a receive buffer; the HPACK integer and literal encodings of the constant header
blocks; a caching HPACK decoder; padding removal; and the one receive buffer a thread reads all
its sockets into. Nothing here opens a socket or keeps connection state.
"""
from __future__ import annotations

import socket
import struct

import hpack

PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"

# frame types (RFC 9113 §6)
DATA, HEADERS, PRIORITY, RST_STREAM, SETTINGS, PUSH_PROMISE, PING, GOAWAY, WINDOW_UPDATE, CONTINUATION = range(10)
FRAME_NAMES = ("DATA", "HEADERS", "PRIORITY", "RST_STREAM", "SETTINGS", "PUSH_PROMISE", "PING", "GOAWAY",
               "WINDOW_UPDATE", "CONTINUATION")
# flags
END_STREAM, ACK, END_HEADERS, PADDED, PRIORITY_FLAG = 0x1, 0x1, 0x4, 0x8, 0x20
# settings ids
SETTINGS_HEADER_TABLE_SIZE, SETTINGS_ENABLE_PUSH, SETTINGS_MAX_CONCURRENT_STREAMS = 0x1, 0x2, 0x3
SETTINGS_INITIAL_WINDOW_SIZE, SETTINGS_MAX_FRAME_SIZE, SETTINGS_MAX_HEADER_LIST_SIZE = 0x4, 0x5, 0x6
# error codes (RFC 9113 §7)
NO_ERROR, PROTOCOL_ERROR, FLOW_CONTROL_ERROR, STREAM_CLOSED, FRAME_SIZE_ERROR = 0x0, 0x1, 0x3, 0x5, 0x6
REFUSED_STREAM, CANCEL, COMPRESSION_ERROR, ENHANCE_YOUR_CALM = 0x7, 0x8, 0x9, 0xB

# gRPC status codes used here
GRPC_OK, GRPC_INTERNAL, GRPC_UNIMPLEMENTED, GRPC_RESOURCE_EXHAUSTED = 0, 13, 12, 8
GRPC_FAILED_PRECONDITION = 9

MAX_WINDOW = (1 << 31) - 1
DEFAULT_WINDOW = 65535
OUR_MAX_FRAME = 1 << 20  # frames we accept: big observations arrive in few frames, none is buffered past 1 MiB
RECV_BYTES = 1 << 20  # the most one recv reads (ReadBuffer)
MAX_HEADER_LIST = 1 << 16  # decoded; a gRPC request's headers are a few hundred bytes


class ReadBuffer:
    """One preallocated receive buffer: ``recv(1 MiB)`` allocates (and maps) a fresh 1 MiB
    object on every call, which cost 13-32 us for a 14 KB message here; ``recv_into`` this
    buffer then appending the bytes read costs ~6 us. One per transport, shared by its
    connections (one thread reads them all): an idle connection holds no buffer of its own."""

    __slots__ = ("_view",)

    def __init__(self) -> None:
        self._view = memoryview(bytearray(RECV_BYTES))

    def read_into(self, sock: socket.socket, target: bytearray) -> int:
        """Append what one ``recv`` returns to ``target``; the byte count (0: closed)."""
        count = sock.recv_into(self._view)
        target += self._view[:count]
        return count

    def release(self) -> None:
        """Free the buffer now. A closed transport can outlive its ``close()`` as cyclic garbage
        (the traceback of the error that ended its simulator refers to it), which Python's
        collector frees only at its rare full collections: before this, every simulator restart
        kept 1 MiB (the soak's trainer grew ~1 MB per simulator kill, bench/RESULTS.md)."""
        self._view.release()  # the only reference to the bytearray: freed here


class Http2Error(Exception):
    """The peer broke the HTTP/2 protocol; the connection is closed with GOAWAY."""

    def __init__(self, message: str, code: int = PROTOCOL_ERROR) -> None:
        super().__init__(message)
        self.code = code


def frame(kind: int, flags: int, stream_id: int, payload: bytes = b"") -> bytes:
    return struct.pack(">I", len(payload))[1:] + bytes((kind, flags)) + struct.pack(">I", stream_id) + payload


def take_frames(buffer: bytearray) -> list[tuple[int, int, int, bytes]]:
    """Remove the complete frames at the front of ``buffer``: [(type, flags, stream id, payload)].

    Raises Http2Error for a frame longer than we ever allow (both ends advertise OUR_MAX_FRAME).
    """
    frames = []
    position, size = 0, len(buffer)
    while size - position >= 9:
        length = (buffer[position] << 16) | (buffer[position + 1] << 8) | buffer[position + 2]
        if length > OUR_MAX_FRAME:
            raise Http2Error(f"frame of {length} bytes exceeds the maximum", FRAME_SIZE_ERROR)
        end = position + 9 + length
        if end > size:
            break
        stream_id = struct.unpack_from(">I", buffer, position + 5)[0] & 0x7FFFFFFF
        frames.append((buffer[position + 3], buffer[position + 4], stream_id, bytes(buffer[position + 9:end])))
        position = end
    del buffer[:position]
    return frames


def hpack_int(value: int, prefix_bits: int, first: int = 0) -> bytes:
    """HPACK integer (RFC 7541 §5.1) with ``first``'s high bits above the prefix."""
    limit = (1 << prefix_bits) - 1
    if value < limit:
        return bytes((first | value,))
    out = bytearray((first | limit,))
    value -= limit
    while value >= 128:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def hpack_literal(name: bytes, value: bytes) -> bytes:
    """'Literal Header Field without Indexing - New Name', plain (non-Huffman) strings."""
    return b"\x00" + hpack_int(len(name), 7) + name + hpack_int(len(value), 7) + value


class CachingDecoder:
    """hpack's decoder, skipped for header blocks it has decoded before without effect.

    A gRPC peer repeats the same few header blocks on every call (once their entries are in the
    dynamic table, or as literals that are never indexed). Decoding such a block depends only
    on the table, and leaves it unchanged, so while the table stays as it is the earlier result
    is exact. Any block that changes the table empties the cache.
    """

    def __init__(self) -> None:
        self._decoder = hpack.Decoder(max_header_list_size=MAX_HEADER_LIST)
        self._cache: dict[bytes, list] = {}

    def decode(self, block: bytes) -> list:
        headers = self._cache.get(block)
        if headers is not None:
            return headers
        table = self._decoder.header_table
        before = (tuple(table.dynamic_entries), table.maxsize)
        headers = self._decoder.decode(block, raw=True)
        if before == (tuple(table.dynamic_entries), table.maxsize):
            if len(self._cache) < 64:
                self._cache[block] = headers
        else:
            self._cache.clear()
        return headers


def strip_padding(flags: int, payload: bytes) -> bytes:
    """The payload of a DATA or HEADERS frame without its padding (RFC 9113 §6.1), if PADDED."""
    if not flags & PADDED:
        return payload
    if not payload or payload[0] >= len(payload):
        raise Http2Error("bad padding")
    return payload[1 : len(payload) - payload[0]]
