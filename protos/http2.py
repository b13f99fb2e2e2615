"""A single-threaded gRPC server for unary calls, speaking HTTP/2 directly on sockets.

Why not grpcio's server: on a small machine its Python layer costs about half a millisecond per
call (a completion-queue thread, a worker thread, then a hand-off to the trainer's thread, each
waiting for the GIL), which is most of an exchange with a fast simulator. Here the trainer's own
thread reads the request off the socket and writes the answer back; nothing else runs.

Scope: what a gRPC client (Unity's Grpc.Core, grpcio, grpc-dotnet) needs for unary calls of one
method over cleartext HTTP/2 (RFC 9113, "prior knowledge"): the connection preface, SETTINGS
(+ACK), PING (+ACK), WINDOW_UPDATE flow control in both directions, HEADERS/CONTINUATION with
HPACK-decoded request headers (``hpack``), DATA split to the peer's frame size, RST_STREAM,
GOAWAY, and gRPC's length-prefixed messages with trailers. Responses never use HPACK's dynamic
table, so they are a few constant bytes. Several connections are served (a simulator that
reconnects); calls are handed out in arrival order.

    transport = Http2Transport("127.0.0.1", 5005, path=b"/pkg.Service/Method", max_message_bytes=...)
    transport.start()                  # OSError if the port is taken
    call = transport.take(timeout=1)   # an IncomingCall, or None
    call.answer(response_bytes)        # DATA + trailers, written before this returns
    transport.close()
"""
from __future__ import annotations

import collections
import logging
import select
import selectors
import socket
import struct
import time
from urllib.parse import quote

import hpack

from protos.pacing import PacedWait, wait_paced

logger = logging.getLogger(__name__)

PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"

# frame types (RFC 9113 §6)
DATA, HEADERS, PRIORITY, RST_STREAM, SETTINGS, PUSH_PROMISE, PING, GOAWAY, WINDOW_UPDATE, CONTINUATION = range(10)
# flags
END_STREAM, ACK, END_HEADERS, PADDED, PRIORITY_FLAG = 0x1, 0x1, 0x4, 0x8, 0x20
# settings ids
SETTINGS_HEADER_TABLE_SIZE, SETTINGS_INITIAL_WINDOW_SIZE, SETTINGS_MAX_FRAME_SIZE = 0x1, 0x4, 0x5
# error codes
NO_ERROR, PROTOCOL_ERROR, FLOW_CONTROL_ERROR, FRAME_SIZE_ERROR, CANCEL = 0x0, 0x1, 0x3, 0x6, 0x8

# gRPC status codes used here
GRPC_OK, GRPC_INTERNAL, GRPC_UNIMPLEMENTED, GRPC_RESOURCE_EXHAUSTED = 0, 13, 12, 8

MAX_WINDOW = (1 << 31) - 1
DEFAULT_WINDOW = 65535
OUR_MAX_FRAME = (1 << 24) - 1  # the largest allowed: big observations arrive in few frames
_RECV_BYTES = 1 << 20
MAX_HEADER_BLOCK = 1 << 20  # a gRPC request's headers are a few hundred bytes
_SEND_TIMEOUT_S = 30.0


class _ReadBuffer:
    """One preallocated receive buffer: ``recv(1 MiB)`` allocates (and maps) a fresh 1 MiB
    object on every call, which cost 13-32 us for a 14 KB message here; ``recv_into`` this
    buffer then appending the bytes read costs ~6 us."""

    __slots__ = ("_view",)

    def __init__(self) -> None:
        self._view = memoryview(bytearray(_RECV_BYTES))

    def read_into(self, sock: socket.socket, target: bytearray) -> int:
        """Append what one ``recv`` returns to ``target``; the byte count (0: closed)."""
        count = sock.recv_into(self._view)
        target += self._view[:count]
        return count


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


# ":status: 200" is static entry 8; content-type (static name 31) as a literal without indexing
RESPONSE_HEADERS = b"\x88" + hpack_int(31, 4) + hpack_int(16, 7) + b"application/grpc"
TABLE_SIZE_ZERO = hpack_int(0, 5, 0x20)  # we never use the dynamic table for what we send
TRAILERS_OK = hpack_literal(b"grpc-status", b"0")


def trailers(status: int, message: str = "") -> bytes:
    block = hpack_literal(b"grpc-status", str(status).encode())
    if message:  # gRPC's percent-encoding of grpc-message
        block += hpack_literal(b"grpc-message", quote(message, safe=" !\"#$&'()*+,-./:;<=>?@[\\]^_`{|}~").encode())
    return block


class CachingDecoder:
    """hpack's decoder, skipped for header blocks it has decoded before without effect.

    A gRPC peer repeats the same few header blocks on every call (once their entries are in the
    dynamic table, or as literals that are never indexed). Decoding such a block depends only
    on the table, and leaves it unchanged, so while the table stays as it is the earlier result
    is exact. Any block that changes the table empties the cache.
    """

    def __init__(self) -> None:
        self._decoder = hpack.Decoder()
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


class IncomingCall:
    """One complete unary request; ``answer`` sends the response (or an error status)."""

    __slots__ = ("connection", "stream_id", "payload", "answered", "cancelled")

    def __init__(self, connection: "_Connection", stream_id: int, payload: bytes) -> None:
        self.connection = connection
        self.stream_id = stream_id
        self.payload = payload
        self.answered = False
        self.cancelled = False  # the client reset the stream or the connection dropped

    def answer(self, message: bytes) -> None:
        if self.answered:
            return
        self.answered = True
        if not self.cancelled:
            self.connection.send_response(self.stream_id, message)

    def fail(self, status: int, message: str) -> None:
        if self.answered:
            return
        self.answered = True
        if not self.cancelled:
            self.connection.send_error(self.stream_id, status, message)


class _Stream:
    __slots__ = ("body", "send_window", "path_ok", "refused")

    def __init__(self, send_window: int) -> None:
        self.body = bytearray()
        self.send_window = send_window
        self.path_ok = False
        self.refused = False  # answered with an error already; the rest of its data is dropped


class _Connection:
    """One HTTP/2 connection: frame parsing, flow control and response writing."""

    def __init__(self, sock: socket.socket, transport: "Http2Transport") -> None:
        self.sock = sock
        self.transport = transport
        self.peer = _peer_name(sock)
        self.buffer = bytearray()
        self._reader = _ReadBuffer()
        self.preface_seen = False
        self.decoder = CachingDecoder()
        self.streams: dict[int, _Stream] = {}
        self.pending: dict[int, IncomingCall] = {}  # handed out, not answered yet
        self.peer_initial_window = DEFAULT_WINDOW
        self.peer_max_frame = 16384
        self.send_window = DEFAULT_WINDOW
        self.recv_unacked = 0
        self.header_stream = 0  # a HEADERS block continued by CONTINUATION frames
        self.header_flags = 0
        self.header_block = bytearray()
        self.table_size_sent = False
        self.last_stream = 0
        self.goaway = False
        self.closed = False
        self.out = bytearray()
        sock.setblocking(True)
        sock.settimeout(_SEND_TIMEOUT_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        settings = struct.pack(">HIHI", SETTINGS_INITIAL_WINDOW_SIZE, MAX_WINDOW,
                               SETTINGS_MAX_FRAME_SIZE, OUR_MAX_FRAME)
        self.out += frame(SETTINGS, 0, 0, settings)
        self.out += frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", MAX_WINDOW - DEFAULT_WINDOW))
        self.flush()

    # ------------------------------------------------------------------ reading
    def read_available(self) -> list[IncomingCall]:
        """Read what the socket has (it is readable) and return the calls it completed."""
        try:
            received = self._reader.read_into(self.sock, self.buffer)
        except (ConnectionError, OSError):
            received = 0
        if not received:
            self.drop("the connection was closed")
            return []
        calls: list[IncomingCall] = []
        try:
            self._parse(calls)
        except Http2Error as error:
            logger.warning("Closing the connection from %s: %s", self.peer, error)
            self.out += frame(GOAWAY, 0, 0, struct.pack(">II", self.last_stream, error.code) + str(error).encode()[:200])
            self.flush()
            self.drop(str(error))
            return []
        self.flush()
        return calls

    def _parse(self, calls: list[IncomingCall]) -> None:
        buffer = self.buffer
        if not self.preface_seen:
            if len(buffer) < len(PREFACE):
                if not PREFACE.startswith(bytes(buffer)):
                    raise Http2Error(self._not_http2())
                return
            if bytes(buffer[: len(PREFACE)]) != PREFACE:
                raise Http2Error(self._not_http2())
            del buffer[: len(PREFACE)]
            self.preface_seen = True
        for kind, flags, stream_id, payload in take_frames(buffer):
            self._frame(kind, flags, stream_id, payload, calls)

    def _not_http2(self) -> str:
        return ("the client did not start with the HTTP/2 preface; only gRPC clients (a Unity "
                "player or the Editor with ML-Agents) can talk to this port")

    def _frame(self, kind: int, flags: int, stream_id: int, payload: bytes, calls: list) -> None:
        if self.header_stream and kind != CONTINUATION:
            raise Http2Error("expected a CONTINUATION frame")
        if kind == DATA:
            self._data(flags, stream_id, payload, calls)
        elif kind == HEADERS:
            payload = _strip_padding(flags, payload)
            if flags & PRIORITY_FLAG:
                payload = payload[5:]
            self.header_stream, self.header_flags = stream_id, flags
            self.header_block = bytearray(payload)
            self._check_header_size()
            if flags & END_HEADERS:
                self._headers_done(calls)
        elif kind == CONTINUATION:
            if stream_id != self.header_stream:
                raise Http2Error("CONTINUATION for another stream")
            self.header_block += payload
            self._check_header_size()
            if flags & END_HEADERS:
                self._headers_done(calls)
        elif kind == SETTINGS:
            if not flags & ACK:
                self._settings(payload)
                self.out += frame(SETTINGS, ACK, 0)
        elif kind == PING:
            if not flags & ACK:
                self.out += frame(PING, ACK, 0, payload)
        elif kind == WINDOW_UPDATE:
            increment = struct.unpack(">I", payload[:4])[0] & 0x7FFFFFFF
            if stream_id == 0:
                self.send_window += increment
            elif stream_id in self.streams:
                self.streams[stream_id].send_window += increment
        elif kind == RST_STREAM:
            self.streams.pop(stream_id, None)
            call = self.pending.pop(stream_id, None)
            if call is not None:
                call.cancelled = True
                self.transport.call_dropped(call, "the simulator cancelled its call")
        elif kind == GOAWAY:
            self.goaway = True
        elif kind == PUSH_PROMISE:
            raise Http2Error("a client may not send PUSH_PROMISE")
        # PRIORITY and unknown frame types are ignored (RFC 9113 §5.5)

    def _check_header_size(self) -> None:
        if len(self.header_block) > MAX_HEADER_BLOCK:
            raise Http2Error(f"header block larger than {MAX_HEADER_BLOCK} bytes")

    def _settings(self, payload: bytes) -> None:
        if len(payload) % 6:
            raise Http2Error("malformed SETTINGS frame", FRAME_SIZE_ERROR)
        for offset in range(0, len(payload), 6):
            key, value = struct.unpack_from(">HI", payload, offset)
            if key == SETTINGS_INITIAL_WINDOW_SIZE:
                if value > MAX_WINDOW:
                    raise Http2Error("initial window too large", FLOW_CONTROL_ERROR)
                delta = value - self.peer_initial_window
                self.peer_initial_window = value
                for stream in self.streams.values():
                    stream.send_window += delta
            elif key == SETTINGS_MAX_FRAME_SIZE:
                if not 16384 <= value <= OUR_MAX_FRAME:
                    raise Http2Error("invalid SETTINGS_MAX_FRAME_SIZE")
                self.peer_max_frame = value
            elif key == SETTINGS_HEADER_TABLE_SIZE:
                self.table_size_sent = False  # restate that our table stays empty

    def _headers_done(self, calls: list) -> None:
        stream_id, flags, block = self.header_stream, self.header_flags, bytes(self.header_block)
        self.header_stream, self.header_block = 0, bytearray()
        headers = self._decode(block)
        if stream_id in self.streams or stream_id in self.pending:
            # trailers from the client, or a HEADERS block on a stream that is already open
            if flags & END_STREAM:
                self._end_stream(stream_id, calls)
            return
        if stream_id % 2 == 0 or stream_id <= self.last_stream:
            raise Http2Error(f"invalid new stream id {stream_id}")
        self.last_stream = stream_id
        stream = _Stream(self.peer_initial_window)
        self.streams[stream_id] = stream
        fields = dict(headers)
        path = fields.get(b":path", b"")
        if fields.get(b":method") != b"POST" or not fields.get(b"content-type", b"").startswith(b"application/grpc"):
            self._refuse(stream_id, stream, GRPC_INTERNAL, "expected a gRPC POST request")
        elif path != self.transport.path:
            self._refuse(stream_id, stream, GRPC_UNIMPLEMENTED,
                         f"unknown method {path.decode(errors='replace')}; this server only serves "
                         f"{self.transport.path.decode()}")
        else:
            stream.path_ok = True
        if flags & END_STREAM:
            self._end_stream(stream_id, calls)

    def _decode(self, block: bytes) -> list:
        try:
            return self.decoder.decode(block)
        except Exception as error:  # hpack raises several error types for bad input
            raise Http2Error(f"undecodable header block ({error})", 0x9) from None

    def _data(self, flags: int, stream_id: int, payload: bytes, calls: list) -> None:
        self.recv_unacked += len(payload)  # flow control counts the whole frame, padding included
        payload = _strip_padding(flags, payload) if flags & PADDED else payload
        if self.recv_unacked > MAX_WINDOW // 2:
            self.out += frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", self.recv_unacked))
            self.recv_unacked = 0
        stream = self.streams.get(stream_id)
        if stream is None:
            return  # a stream we reset or finished; its data only counts against the window
        if not stream.refused:
            stream.body += payload
            limit = self.transport.max_message_bytes + 5
            if len(stream.body) > limit:
                self._refuse(stream_id, stream, GRPC_RESOURCE_EXHAUSTED,
                             f"message larger than the server's limit of {self.transport.max_message_bytes} bytes")
        if flags & END_STREAM:
            self._end_stream(stream_id, calls)

    def _end_stream(self, stream_id: int, calls: list) -> None:
        stream = self.streams.get(stream_id)
        if stream is None or stream.refused:
            self.streams.pop(stream_id, None)
            return
        body = stream.body
        if len(body) < 5:
            self._refuse(stream_id, stream, GRPC_INTERNAL, "the request carried no gRPC message")
            return
        compressed = body[0]
        length = struct.unpack_from(">I", body, 1)[0]
        if compressed:
            self._refuse(stream_id, stream, GRPC_UNIMPLEMENTED, "compressed messages are not supported")
            return
        if length != len(body) - 5:
            self._refuse(stream_id, stream, GRPC_INTERNAL,
                         "a unary request must carry exactly one complete gRPC message")
            return
        call = IncomingCall(self, stream_id, bytes(body[5:]))
        stream.body = bytearray()
        self.pending[stream_id] = call
        calls.append(call)

    def _refuse(self, stream_id: int, stream: _Stream, status: int, message: str) -> None:
        logger.warning("Refused a call from %s: %s", self.peer, message)
        stream.refused = True
        stream.body = bytearray()
        self.send_error(stream_id, status, message, flush=False)

    # ------------------------------------------------------------------ writing
    def _header_block(self, block: bytes) -> bytes:
        if not self.table_size_sent:
            self.table_size_sent = True
            return TABLE_SIZE_ZERO + block
        return block

    def send_response(self, stream_id: int, message: bytes) -> None:
        self.pending.pop(stream_id, None)
        stream = self.streams.get(stream_id)
        if stream is None or self.closed:
            return
        self.out += frame(HEADERS, END_HEADERS, stream_id, self._header_block(RESPONSE_HEADERS))
        body = b"\x00" + struct.pack(">I", len(message)) + message
        offset = 0
        while offset < len(body):
            allowed = min(self.send_window, stream.send_window, self.peer_max_frame, len(body) - offset)
            if allowed <= 0:
                self.flush()
                if not self._wait_for_window(stream_id, stream):
                    return
                continue
            self.out += frame(DATA, 0, stream_id, body[offset : offset + allowed])
            offset += allowed
            self.send_window -= allowed
            stream.send_window -= allowed
        self.out += frame(HEADERS, END_HEADERS | END_STREAM, stream_id, TRAILERS_OK)
        self.streams.pop(stream_id, None)
        self.flush()
        self.transport.pace.sent()

    def send_error(self, stream_id: int, status: int, message: str, flush: bool = True) -> None:
        """A trailers-only response: HTTP 200 with the gRPC status, ending the stream."""
        self.pending.pop(stream_id, None)
        self.out += frame(HEADERS, END_HEADERS | END_STREAM, stream_id,
                          self._header_block(RESPONSE_HEADERS + trailers(status, message)))
        stream = self.streams.get(stream_id)
        if stream is not None and not stream.refused:
            self.streams.pop(stream_id, None)
        if flush:
            self.flush()

    def _wait_for_window(self, stream_id: int, stream: _Stream) -> bool:
        """Block until the client opens its flow-control window (it reads what we sent)."""
        deadline = time.monotonic() + _SEND_TIMEOUT_S
        while min(self.send_window, stream.send_window) <= 0:
            if self.closed or stream_id not in self.streams or time.monotonic() > deadline:
                self.drop("the client stopped reading its answer")
                return False
            readable = selectors.DefaultSelector()
            readable.register(self.sock, selectors.EVENT_READ)
            ready = readable.select(1.0)
            readable.close()
            if ready:
                self.transport.queue_calls(self.read_available())
        return True

    def flush(self) -> None:
        if not self.out or self.closed:
            self.out.clear()
            return
        data, self.out = bytes(self.out), bytearray()
        try:
            self.sock.sendall(data)
        except (OSError, socket.timeout) as error:
            self.drop(f"sending failed ({error})")

    # ------------------------------------------------------------------ teardown
    def drop(self, why: str) -> None:
        if self.closed:
            return
        self.closed = True
        for call in list(self.pending.values()):
            call.cancelled = True
            self.transport.call_dropped(call, why)
        self.pending.clear()
        self.streams.clear()
        self.transport.connection_closed(self)
        try:
            self.sock.close()
        except OSError:
            pass

    def shutdown(self, grace: float) -> None:
        """GOAWAY, then let the client read everything before the socket closes."""
        if self.closed:
            return
        self.out += frame(GOAWAY, 0, 0, struct.pack(">II", self.last_stream, NO_ERROR))
        self.flush()
        if self.closed:
            return
        try:
            self.sock.shutdown(socket.SHUT_WR)
            deadline = time.monotonic() + grace
            self.sock.settimeout(0.05)
            while time.monotonic() < deadline:
                try:
                    if not self.sock.recv(_RECV_BYTES):
                        break
                except socket.timeout:
                    continue
        except OSError:
            pass
        self.pending.clear()
        self.closed = True
        self.transport.connection_closed(self)
        try:
            self.sock.close()
        except OSError:
            pass


def _strip_padding(flags: int, payload: bytes) -> bytes:
    if not flags & PADDED:
        return payload
    if not payload or payload[0] >= len(payload):
        raise Http2Error("bad padding")
    return payload[1 : len(payload) - payload[0]]


def _peer_name(sock: socket.socket) -> str:
    try:
        host, port = sock.getpeername()[:2]
        return f"{host}:{port}"
    except OSError:
        return "a client"


class Http2Transport:
    """Listens on ``bind:port`` and hands out complete unary calls of ``path``."""

    def __init__(self, bind: str, port: int, path: bytes, max_message_bytes: int, spin_s: float = 0.0) -> None:
        self.bind = bind
        self.port = port
        self.path = path
        self.max_message_bytes = max_message_bytes
        self.pace = PacedWait(spin_s)  # when the simulator's next call is due (pacing.py)
        self.client_gone = False
        self.closed = False
        self._listener: socket.socket | None = None
        self._selector = selectors.DefaultSelector()
        self._connections: dict[socket.socket, _Connection] = {}
        self._ready: collections.deque[IncomingCall] = collections.deque()

    def start(self) -> None:
        family = socket.AF_INET6 if ":" in self.bind else socket.AF_INET
        listener = socket.socket(family, socket.SOCK_STREAM)
        try:
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # TIME_WAIT only
            listener.bind((self.bind, self.port))
            listener.listen(8)
        except OSError:
            listener.close()
            raise
        listener.setblocking(False)
        self.port = listener.getsockname()[1]
        self._listener = listener
        self._selector.register(listener, selectors.EVENT_READ)

    # callbacks from connections
    def call_dropped(self, call: IncomingCall, why: str) -> None:
        logger.debug("Call on stream %d dropped: %s", call.stream_id, why)
        self.client_gone = True

    def connection_closed(self, connection: _Connection) -> None:
        if connection.sock in self._connections:
            del self._connections[connection.sock]
            try:
                self._selector.unregister(connection.sock)
            except (KeyError, ValueError):
                pass
        self._ready = collections.deque(c for c in self._ready if c.connection is not connection)

    def queue_calls(self, calls: list[IncomingCall]) -> None:
        self._ready.extend(calls)

    def poll(self) -> None:
        """Process whatever the sockets hold without waiting (e.g. to notice a cancelled call)."""
        if not self.closed:
            self._pump(0.0)

    def _pump(self, timeout: float) -> bool:
        """One select round: accept, read, collect calls. False if nothing was ready."""
        events = self._selector.select(timeout)
        for key, _ in events:
            if key.fileobj is self._listener:
                self._accept()
            else:
                connection = self._connections.get(key.fileobj)
                if connection is not None:
                    self._ready.extend(connection.read_available())
        return bool(events)

    def take(self, timeout: float) -> IncomingCall | None:
        """The next complete call, waiting up to ``timeout`` s; None on timeout, once a pending
        call was dropped by the client, or after ``close``."""
        if self.closed:
            return None
        if not self._ready and timeout <= 0:
            if not self.client_gone:
                self._pump(0.0)
                if self._ready:  # it was there before we looked: nothing to learn about its timing
                    self.pace.forget()
        elif not self._ready:
            # the caller looked with timeout 0 a moment ago: wait_paced's first look is the next one
            deadline = time.monotonic() + timeout
            polled = wait_paced(self.pace, list(self._connections), self._call_ready, timeout)
            while not self._ready:
                if self.closed or self.client_gone:
                    return None
                remaining = deadline - time.monotonic()
                if not self._pump(max(remaining, 0.0)) and remaining <= 0:
                    return None
            self.pace.arrived(polled)
        return self._ready.popleft() if self._ready else None

    def _call_ready(self) -> bool:
        """Read what the sockets hold; True once a call is complete (or waiting is pointless)."""
        if self.closed or self.client_gone:
            return True
        self._pump(0.0)
        return bool(self._ready)

    def _accept(self) -> None:
        try:
            sock, _ = self._listener.accept()
        except (BlockingIOError, OSError):
            return
        connection = _Connection(sock, self)
        if not connection.closed:
            self._connections[sock] = connection
            self._selector.register(sock, selectors.EVENT_READ)

    def close(self, grace: float = 2.0) -> None:
        if self.closed:
            return
        self.closed = True
        if self._listener is not None:
            self._selector.unregister(self._listener)
            self._listener.close()
            self._listener = None
        for connection in list(self._connections.values()):
            connection.shutdown(grace)
        self._connections.clear()
        self._ready.clear()
        self._selector.close()


# =========================================================================== client side
class CallError(Exception):
    """A unary call failed: ``code`` is the gRPC status name (UNAVAILABLE when the connection
    could not be made or was lost)."""

    def __init__(self, code: str, details: str = "") -> None:
        super().__init__(f"{code}: {details}" if details else code)
        self.code = code
        self.details = details


_STATUS_NAMES = {0: "OK", 1: "CANCELLED", 2: "UNKNOWN", 3: "INVALID_ARGUMENT", 4: "DEADLINE_EXCEEDED",
                 5: "NOT_FOUND", 8: "RESOURCE_EXHAUSTED", 12: "UNIMPLEMENTED", 13: "INTERNAL",
                 14: "UNAVAILABLE"}


def request_headers(path: bytes, authority: bytes) -> bytes:
    """The constant header block of a gRPC request (static-table entries and plain literals)."""
    return (b"\x83"  # :method POST (static 3)
            + b"\x86"  # :scheme http (static 6)
            + hpack_int(4, 4) + hpack_int(len(path), 7) + path  # :path, name from static 4
            + hpack_int(1, 4) + hpack_int(len(authority), 7) + authority  # :authority (static 1)
            + hpack_int(31, 4) + hpack_int(16, 7) + b"application/grpc"
            + hpack_literal(b"te", b"trailers")
            + hpack_literal(b"user-agent", b"mlagents-like-http2/1"))


class Http2Channel:
    """Blocking unary gRPC calls over one cleartext HTTP/2 connection, on the caller's thread.

    What a simulator needs to call ``Exchange`` like Unity's gRPC client does, without gRPC's
    threads: ``connect`` (retrying until the server listens), ``call`` (one request, one
    answer, flow control and PING/SETTINGS handled while waiting), ``close``.
    """

    def __init__(self, host: str, port: int, path: bytes, spin_s: float = 0.0) -> None:
        self.host, self.port, self.path = host, port, path
        self.pace = PacedWait(spin_s)  # when the trainer's answer is due (pacing.py)
        self._headers = request_headers(path, f"{host}:{port}".encode())
        self.sock: socket.socket | None = None
        self._decoder = CachingDecoder()
        self._buffer = bytearray()
        self._reader = _ReadBuffer()
        self._next_stream = 1
        self._send_window = DEFAULT_WINDOW
        self._peer_initial_window = DEFAULT_WINDOW
        self._stream_window = DEFAULT_WINDOW
        self._peer_max_frame = 16384
        self._recv_unacked = 0
        self._goaway_last: int | None = None

    def connect(self, timeout: float) -> bool:
        """Open the TCP connection and send the preface; False if the server refused."""
        try:
            sock = socket.create_connection((self.host, self.port), timeout=timeout)
        except OSError:
            return False
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(None)
        self.sock = sock
        settings = struct.pack(">HIHIHI", 0x2, 0, SETTINGS_INITIAL_WINDOW_SIZE, MAX_WINDOW,
                               SETTINGS_MAX_FRAME_SIZE, OUR_MAX_FRAME)  # ENABLE_PUSH=0
        self._send(PREFACE + frame(SETTINGS, 0, 0, settings)
                   + frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", MAX_WINDOW - DEFAULT_WINDOW)))
        return True

    def call(self, request: bytes, timeout: float | None = None) -> bytes:
        """Send one request; return the response message. Raises CallError."""
        if self.sock is None:
            raise CallError("UNAVAILABLE", "not connected")
        if self._goaway_last is not None:
            raise CallError("UNAVAILABLE", "the server is shutting the connection down")
        stream_id = self._next_stream
        self._next_stream += 2
        self._stream_window = self._peer_initial_window
        self.sock.settimeout(timeout)
        try:
            out = bytearray(frame(HEADERS, END_HEADERS, stream_id, self._headers))
            body = b"\x00" + struct.pack(">I", len(request)) + request
            offset = 0
            while offset < len(body):
                allowed = min(self._send_window, self._stream_window, self._peer_max_frame, len(body) - offset)
                if allowed <= 0:
                    self._send(bytes(out))
                    out.clear()
                    self._read_frames(stream_id, None)  # until a WINDOW_UPDATE opens the window
                    continue
                end = offset + allowed
                out += frame(DATA, END_STREAM if end == len(body) else 0, stream_id, body[offset:end])
                self._send_window -= allowed
                self._stream_window -= allowed
                offset = end
            self._send(bytes(out))
            self.pace.sent()
            response: dict = {"data": bytearray(), "status": None, "message": "", "http": None}
            sock = [self.sock]
            polled = wait_paced(self.pace, sock, lambda: bool(select.select(sock, [], [], 0.0)[0]))
            self._read_frames(stream_id, response, polled)
        except socket.timeout:
            self.close()
            raise CallError("DEADLINE_EXCEEDED", "no answer in time") from None
        except OSError as error:
            self.close()
            raise CallError("UNAVAILABLE", str(error)) from None
        except Http2Error as error:
            self.close()
            raise CallError("INTERNAL", f"the server broke HTTP/2: {error}") from None
        finally:
            if self.sock is not None:
                self.sock.settimeout(None)
        status = response["status"]
        if status is None:
            status = 13 if response["http"] == b"200" else 14
        if status != GRPC_OK:
            raise CallError(_STATUS_NAMES.get(status, str(status)), response["message"])
        data = response["data"]
        if len(data) < 5 or data[0] or struct.unpack_from(">I", data, 1)[0] != len(data) - 5:
            raise CallError("INTERNAL", "the answer is not one uncompressed gRPC message")
        return bytes(data[5:])

    def _read_frames(self, stream_id: int, response: dict | None, polled: bool = False) -> None:
        """Read and handle frames until ``response``'s stream ends (or, with None, until one
        read's worth of frames is handled: used to wait for WINDOW_UPDATE). ``polled``: the
        answer's first bytes were found by polling (``pacing.wait_paced``)."""
        while True:
            if not self._reader.read_into(self.sock, self._buffer):
                raise OSError("the server closed the connection")
            if response is not None:
                self.pace.arrived(polled)
            ended = self._parse(stream_id, response)
            if ended or response is None:
                return

    def _parse(self, stream_id: int, response: dict | None) -> bool:
        ended, out = False, bytearray()
        for kind, flags, sid, payload in take_frames(self._buffer):
            if kind == DATA:
                self._recv_unacked += len(payload)  # flow control counts padding too
                payload = _strip_padding(flags, payload)
                if self._recv_unacked > MAX_WINDOW // 2:
                    out += frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", self._recv_unacked))
                    self._recv_unacked = 0
                if sid == stream_id and response is not None:
                    response["data"] += payload
                    ended |= bool(flags & END_STREAM)
            elif kind in (HEADERS, CONTINUATION):
                if kind == HEADERS:
                    payload = _strip_padding(flags, payload)
                    if flags & PRIORITY_FLAG:
                        payload = payload[5:]
                    self._header_parts = [payload]
                    self._header_end_stream = bool(flags & END_STREAM)
                else:
                    self._header_parts.append(payload)
                if flags & END_HEADERS:
                    headers = self._decoder.decode(b"".join(self._header_parts))
                    if sid == stream_id and response is not None:
                        for name, value in headers:
                            if name == b":status":
                                response["http"] = value
                            elif name == b"grpc-status":
                                response["status"] = int(value)
                            elif name == b"grpc-message":
                                response["message"] = _unquote(value)
                        ended |= self._header_end_stream
            elif kind == SETTINGS and not flags & ACK:
                for offset in range(0, len(payload) - len(payload) % 6, 6):
                    key, value = struct.unpack_from(">HI", payload, offset)
                    if key == SETTINGS_INITIAL_WINDOW_SIZE:
                        self._stream_window += value - self._peer_initial_window
                        self._peer_initial_window = value
                    elif key == SETTINGS_MAX_FRAME_SIZE:
                        self._peer_max_frame = value
                out += frame(SETTINGS, ACK, 0)
            elif kind == PING and not flags & ACK:
                out += frame(PING, ACK, 0, payload)
            elif kind == WINDOW_UPDATE:
                increment = struct.unpack(">I", payload[:4])[0] & 0x7FFFFFFF
                if sid == 0:
                    self._send_window += increment
                elif sid == stream_id:
                    self._stream_window += increment
            elif kind == RST_STREAM and sid == stream_id:
                code = struct.unpack(">I", payload[:4])[0]
                raise CallError("CANCELLED" if code == CANCEL else "INTERNAL",
                                f"the server reset the call (HTTP/2 error {code})")
            elif kind == GOAWAY:
                self._goaway_last = struct.unpack(">I", payload[:4])[0] & 0x7FFFFFFF
                if stream_id > self._goaway_last and response is not None:
                    raise CallError("UNAVAILABLE", "the server went away before taking the call")
        if out:
            self._send(bytes(out))
        return ended

    def _send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def close(self) -> None:
        if self.sock is not None:
            try:
                self.sock.sendall(frame(GOAWAY, 0, 0, struct.pack(">II", 0, NO_ERROR)))
            except OSError:
                pass
            try:
                self.sock.close()
            except OSError:
                pass
            self.sock = None


def _unquote(value: bytes) -> str:
    from urllib.parse import unquote

    return unquote(value.decode("utf-8", errors="replace"))
