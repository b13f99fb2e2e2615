"""The trainer's gRPC server for unary calls, speaking HTTP/2 directly on sockets, on one thread.

Why not grpcio's server: on a small machine its Python layer costs about half a millisecond per
call (a completion-queue thread, a worker thread, then a hand-off to the trainer's thread, each
waiting for the GIL), which is most of an exchange with a fast simulator. Here the trainer's own
thread reads the request off the socket and writes the answer back; nothing else runs.

Why not python-hyper's ``h2`` state machine on this same thread: measured with
``bench/transport.py`` (bench/peers/h2_transport.py, numbers in bench/RESULTS.md), it costs
several times this server's cost of the trainer's time per exchange, which halves
bench/protocol.py's exchanges/s for basic; a well-kept library is preferred only while it costs
at most 5 % end to end (docs/performance.md, "The transport").
So this file does what ``h2`` would enforce for a server of unary calls, each case tested in
tests/protocol/test_http2_conformance.py: a peer that breaks RFC 9113 gets GOAWAY (connection
errors) or RST_STREAM (stream errors) with the RFC's error code and the trainer logs one line.

Scope: what a gRPC client (Unity's Grpc.Core, grpcio, grpc-dotnet) needs for unary calls of one
method over cleartext HTTP/2 ("prior knowledge"): the connection preface, SETTINGS (+ACK),
PING (+ACK), WINDOW_UPDATE flow control in both directions, HEADERS/CONTINUATION with
HPACK-decoded request headers (``hpack``), DATA split to the peer's frame size, RST_STREAM,
GOAWAY, and gRPC's length-prefixed messages with trailers. Responses never use HPACK's dynamic
table, so they are a few constant bytes. Up to ``MAX_CONNECTIONS`` connections are open at
once, but calls are taken from one of them only, the session's (the first whose call the
trainer took); while it lives another client's request is refused, and once it has closed the
next connection takes over (a simulator that reconnects). The framing it shares with the
simulator's client (unity_stub_env/http2_client.py) is protos/http2.py.

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
import threading
import time
from urllib.parse import quote

import hpack

from protos.http2 import (
    ACK, COMPRESSION_ERROR, CONTINUATION, DATA, DEFAULT_WINDOW, END_HEADERS, END_STREAM,
    ENHANCE_YOUR_CALM, FLOW_CONTROL_ERROR, FRAME_NAMES, FRAME_SIZE_ERROR, GOAWAY,
    GRPC_FAILED_PRECONDITION, GRPC_INTERNAL, GRPC_RESOURCE_EXHAUSTED, GRPC_UNIMPLEMENTED, HEADERS,
    MAX_HEADER_LIST, MAX_WINDOW, NO_ERROR, OUR_MAX_FRAME, PADDED, PING, PREFACE, PRIORITY,
    PRIORITY_FLAG, PROTOCOL_ERROR, PUSH_PROMISE, RECV_BYTES, REFUSED_STREAM, RST_STREAM, SETTINGS,
    SETTINGS_ENABLE_PUSH, SETTINGS_HEADER_TABLE_SIZE, SETTINGS_INITIAL_WINDOW_SIZE,
    SETTINGS_MAX_CONCURRENT_STREAMS, SETTINGS_MAX_FRAME_SIZE, SETTINGS_MAX_HEADER_LIST_SIZE,
    STREAM_CLOSED, WINDOW_UPDATE, CachingDecoder, Http2Error, ReadBuffer, frame, hpack_int,
    hpack_literal, strip_padding, take_frames,
)
from protos.pacing import PacedWait, wait_paced
from trainer.protocol.listen import listen

logger = logging.getLogger(__name__)

_CONNECTION_FRAMES = frozenset((SETTINGS, PING, GOAWAY))  # stream 0 only
MAX_HEADER_BLOCK = 1 << 16  # encoded, over HEADERS + CONTINUATION frames
MAX_CONTINUATIONS = 64  # CONTINUATION frames per block (empty ones would never reach the size limit)
MAX_STREAMS = 16  # calls open at once; a simulator makes one at a time
MAX_UNSENT = 1 << 20  # replies a client leaves unread (PING flood) before it is disconnected
MAX_CONNECTIONS = 8  # open at once; past this the longest-idle one other than the session's is closed
PREFACE_TIMEOUT_S = 10.0  # to send the preface and SETTINGS (a slow-loris client is closed after it)
IDLE_TIMEOUT_S = 60.0  # a connection other than the session's, without a call in flight, is closed after it
_SEND_TIMEOUT_S = 30.0
OUR_SETTINGS = struct.pack(">HIHIHIHIHI", SETTINGS_ENABLE_PUSH, 0, SETTINGS_MAX_CONCURRENT_STREAMS, MAX_STREAMS,
                           SETTINGS_INITIAL_WINDOW_SIZE, MAX_WINDOW, SETTINGS_MAX_FRAME_SIZE, OUR_MAX_FRAME,
                           SETTINGS_MAX_HEADER_LIST_SIZE, MAX_HEADER_LIST)

# ":status: 200" is static entry 8; content-type (static name 31) as a literal without indexing
RESPONSE_HEADERS = b"\x88" + hpack_int(31, 4) + hpack_int(16, 7) + b"application/grpc"
TABLE_SIZE_ZERO = hpack_int(0, 5, 0x20)  # we never use the dynamic table for what we send
TRAILERS_OK = hpack_literal(b"grpc-status", b"0")


def trailers(status: int, message: str = "") -> bytes:
    block = hpack_literal(b"grpc-status", str(status).encode())
    if message:  # gRPC's percent-encoding of grpc-message
        block += hpack_literal(b"grpc-message", quote(message, safe=" !\"#$&'()*+,-./:;<=>?@[\\]^_`{|}~").encode())
    return block


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
    __slots__ = ("body", "send_window", "ended", "refused")

    def __init__(self, send_window: int) -> None:
        self.body = bytearray()
        self.send_window = send_window
        self.ended = False  # the client's END_STREAM arrived: half-closed (remote)
        self.refused = False  # answered with an error already; the rest of its data is dropped


class _Connection:
    """One HTTP/2 connection: frame checks (RFC 9113; docs/protocol.md), flow control and
    response writing. A connection error answers GOAWAY with its code and closes; a stream
    error answers RST_STREAM and cancels that stream's call."""

    def __init__(self, sock: socket.socket, transport: "Http2Transport") -> None:
        self.sock = sock
        self.transport = transport
        self.peer = _peer_name(sock)
        self.buffer = bytearray()
        self._reader = transport.reader
        self.opened_at = self.active_at = time.monotonic()  # active: its last complete request
        self.preface_seen = False
        self.settings_seen = False  # the preface must be followed by SETTINGS
        self.decoder = CachingDecoder()
        self.streams: dict[int, _Stream] = {}  # open or half-closed (remote), until answered
        self.pending: dict[int, IncomingCall] = {}  # handed out, not answered yet
        self.reset_ids: collections.deque[int] = collections.deque(maxlen=32)  # frames for them are ignored
        self.peer_initial_window = DEFAULT_WINDOW
        self.peer_max_frame = 16384
        self.send_window = DEFAULT_WINDOW
        self.recv_window = MAX_WINDOW  # what the client may still send on the connection
        self.header_stream = 0  # a HEADERS block continued by CONTINUATION frames
        self.header_flags = 0
        self.header_block = bytearray()
        self.continuations = 0
        self.table_size_sent = False
        self.last_stream = 0
        self.goaway = False
        self.closed = False
        self.out = bytearray()
        sock.setblocking(True)
        sock.settimeout(_SEND_TIMEOUT_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.out += frame(SETTINGS, 0, 0, OUR_SETTINGS)
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
            self.close_with(error.code, str(error))
            return []
        self.flush(wait=False)
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
            if not self.settings_seen:
                if kind != SETTINGS or flags & ACK:
                    raise Http2Error("the connection preface must be followed by a SETTINGS frame")
                self.settings_seen = True
            if self.closed:
                return
            self._frame(kind, flags, stream_id, payload, calls)

    def _not_http2(self) -> str:
        return ("the client did not start with the HTTP/2 preface; only gRPC clients (a Unity "
                "player or the Editor with ML-Agents) can talk to this port")

    def _frame(self, kind: int, flags: int, stream_id: int, payload: bytes, calls: list) -> None:
        if self.header_stream and kind != CONTINUATION:
            raise Http2Error("expected a CONTINUATION frame")
        if kind in _CONNECTION_FRAMES:
            if stream_id:
                raise Http2Error(f"{FRAME_NAMES[kind]} frame on stream {stream_id} (only stream 0 may carry it)")
        elif kind <= CONTINUATION and kind != WINDOW_UPDATE and not stream_id:
            raise Http2Error(f"{FRAME_NAMES[kind]} frame on stream 0")
        if kind == DATA:
            self._data(flags, stream_id, payload, calls)
        elif kind == HEADERS:
            payload = strip_padding(flags, payload)
            if flags & PRIORITY_FLAG:
                if len(payload) < 5:
                    raise Http2Error("HEADERS frame too short for its priority fields", FRAME_SIZE_ERROR)
                payload = payload[5:]
            self.header_stream, self.header_flags, self.continuations = stream_id, flags, 0
            self.header_block = bytearray(payload)
            self._header_fragment_added(calls)
        elif kind == CONTINUATION:
            if stream_id != self.header_stream:
                raise Http2Error("CONTINUATION frame without a HEADERS frame before it on its stream")
            self.header_block += payload
            self.continuations += 1
            if self.continuations > MAX_CONTINUATIONS:
                raise Http2Error(f"more than {MAX_CONTINUATIONS} CONTINUATION frames in one header block",
                                 ENHANCE_YOUR_CALM)
            self.header_flags = (self.header_flags & ~END_HEADERS) | (flags & END_HEADERS)
            self._header_fragment_added(calls)
        elif kind == SETTINGS:
            if flags & ACK:
                if payload:
                    raise Http2Error("SETTINGS acknowledgement with a payload", FRAME_SIZE_ERROR)
            else:
                self._settings(payload)
                self.out += frame(SETTINGS, ACK, 0)
        elif kind == PING:
            if len(payload) != 8:
                raise Http2Error(f"PING frame of {len(payload)} bytes (must be 8)", FRAME_SIZE_ERROR)
            if not flags & ACK:
                self.out += frame(PING, ACK, 0, payload)
        elif kind == WINDOW_UPDATE:
            self._window_update(stream_id, payload)
        elif kind == RST_STREAM:
            if len(payload) != 4:
                raise Http2Error(f"RST_STREAM frame of {len(payload)} bytes (must be 4)", FRAME_SIZE_ERROR)
            self._check_not_idle(kind, stream_id)
            self.streams.pop(stream_id, None)
            self._cancel(stream_id, "the simulator cancelled its call")
        elif kind == PRIORITY:
            if len(payload) != 5:
                self._reset(stream_id, FRAME_SIZE_ERROR, f"PRIORITY frame of {len(payload)} bytes (must be 5)")
            elif struct.unpack_from(">I", payload)[0] & 0x7FFFFFFF == stream_id:
                self._reset(stream_id, PROTOCOL_ERROR, "a stream cannot depend on itself")
        elif kind == GOAWAY:
            if len(payload) < 8:
                raise Http2Error(f"GOAWAY frame of {len(payload)} bytes (must be at least 8)", FRAME_SIZE_ERROR)
            self.goaway = True
        elif kind == PUSH_PROMISE:
            raise Http2Error("a client may not send PUSH_PROMISE")
        # unknown frame types are ignored (RFC 9113 §5.5)

    def _check_not_idle(self, kind: int, stream_id: int) -> None:
        if stream_id > self.last_stream:
            raise Http2Error(f"{FRAME_NAMES[kind]} frame on stream {stream_id}, which was never opened")

    def _window_update(self, stream_id: int, payload: bytes) -> None:
        if len(payload) != 4:
            raise Http2Error(f"WINDOW_UPDATE frame of {len(payload)} bytes (must be 4)", FRAME_SIZE_ERROR)
        increment = struct.unpack(">I", payload)[0] & 0x7FFFFFFF
        if stream_id == 0:
            if not increment:
                raise Http2Error("WINDOW_UPDATE with an increment of 0 on the connection")
            self.send_window += increment
            if self.send_window > MAX_WINDOW:
                raise Http2Error("WINDOW_UPDATE beyond 2^31-1 on the connection", FLOW_CONTROL_ERROR)
            return
        self._check_not_idle(WINDOW_UPDATE, stream_id)
        stream = self.streams.get(stream_id)
        if stream is None:
            return  # closed: a late update is harmless
        if not increment:
            self._reset(stream_id, PROTOCOL_ERROR, "WINDOW_UPDATE with an increment of 0")
            return
        stream.send_window += increment
        if stream.send_window > MAX_WINDOW:
            self._reset(stream_id, FLOW_CONTROL_ERROR, "WINDOW_UPDATE beyond 2^31-1")

    def _header_fragment_added(self, calls: list) -> None:
        if len(self.header_block) > MAX_HEADER_BLOCK:
            raise Http2Error(f"header block larger than {MAX_HEADER_BLOCK} bytes", ENHANCE_YOUR_CALM)
        if self.header_flags & END_HEADERS:
            self._headers_done(calls)

    def _settings(self, payload: bytes) -> None:
        if len(payload) % 6:
            raise Http2Error(f"SETTINGS frame of {len(payload)} bytes (must be a multiple of 6)", FRAME_SIZE_ERROR)
        for offset in range(0, len(payload), 6):
            key, value = struct.unpack_from(">HI", payload, offset)
            if key == SETTINGS_ENABLE_PUSH and value > 1:
                raise Http2Error(f"SETTINGS_ENABLE_PUSH of {value} (must be 0 or 1)")
            if key == SETTINGS_INITIAL_WINDOW_SIZE:
                if value > MAX_WINDOW:
                    raise Http2Error(f"SETTINGS_INITIAL_WINDOW_SIZE of {value} (above 2^31-1)", FLOW_CONTROL_ERROR)
                delta = value - self.peer_initial_window
                self.peer_initial_window = value
                for stream in self.streams.values():
                    stream.send_window += delta
                    if stream.send_window > MAX_WINDOW:
                        raise Http2Error("SETTINGS_INITIAL_WINDOW_SIZE overflows a stream's window", FLOW_CONTROL_ERROR)
            elif key == SETTINGS_MAX_FRAME_SIZE:
                if not 16384 <= value <= (1 << 24) - 1:
                    raise Http2Error(f"SETTINGS_MAX_FRAME_SIZE of {value} (must be 16384 to 2^24-1)")
                self.peer_max_frame = value
            elif key == SETTINGS_HEADER_TABLE_SIZE:
                self.table_size_sent = False  # restate that our table stays empty

    def _headers_done(self, calls: list) -> None:
        stream_id, flags, block = self.header_stream, self.header_flags, bytes(self.header_block)
        self.header_stream, self.header_block = 0, bytearray()
        headers = self._decode(block)  # always: the HPACK table must stay in step with the client's
        stream = self.streams.get(stream_id)
        if stream is not None:  # trailers: they end the request
            if stream.ended:
                self._reset(stream_id, STREAM_CLOSED, "HEADERS after the request ended")
            elif not flags & END_STREAM:
                self._reset(stream_id, PROTOCOL_ERROR, "a second HEADERS block that does not end the request")
            else:
                self._end_stream(stream_id, calls)
            return
        if stream_id in self.reset_ids:
            return
        if stream_id % 2 == 0:
            raise Http2Error(f"stream id {stream_id} is even (client streams are odd)")
        if stream_id <= self.last_stream:
            raise Http2Error(f"stream id {stream_id} is not above the last one ({self.last_stream})")
        self.last_stream = stream_id
        refusal = self.transport.refusal(self)
        if refusal is not None:
            self.send_error(stream_id, GRPC_FAILED_PRECONDITION, refusal, flush=False)
            raise Http2Error(refusal, NO_ERROR)
        if len(self.streams) >= MAX_STREAMS:
            self._reset(stream_id, REFUSED_STREAM, f"more than {MAX_STREAMS} calls at once")
            return
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
        if flags & END_STREAM:
            self._end_stream(stream_id, calls)

    def _decode(self, block: bytes) -> list:
        try:
            return self.decoder.decode(block)
        except hpack.OversizedHeaderListError:
            raise Http2Error(f"headers larger than {MAX_HEADER_LIST} bytes once decoded", ENHANCE_YOUR_CALM) from None
        except Exception as error:  # hpack raises several error types for bad input
            raise Http2Error(f"undecodable header block ({error})", COMPRESSION_ERROR) from None

    def _data(self, flags: int, stream_id: int, payload: bytes, calls: list) -> None:
        self.recv_window -= len(payload)  # flow control counts the whole frame, padding included
        if self.recv_window < 0:
            raise Http2Error("DATA beyond the connection's flow-control window", FLOW_CONTROL_ERROR)
        if self.recv_window < MAX_WINDOW // 2:
            self.out += frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", MAX_WINDOW - self.recv_window))
            self.recv_window = MAX_WINDOW
        payload = strip_padding(flags, payload) if flags & PADDED else payload
        stream = self.streams.get(stream_id)
        if stream is None or stream.ended:
            if stream_id not in self.reset_ids:
                self._check_not_idle(DATA, stream_id)
                self._reset(stream_id, STREAM_CLOSED, "DATA after the request ended")
            return
        if not stream.refused:
            stream.body += payload
            limit = self.transport.max_message_bytes + 5
            if len(stream.body) > limit:
                self._refuse(stream_id, stream, GRPC_RESOURCE_EXHAUSTED,
                             f"message larger than the server's limit of {self.transport.max_message_bytes} bytes")
            elif len(self.streams) > 1 and sum(len(s.body) for s in self.streams.values()) > limit:
                # several streams may not together buffer more than one message may hold
                self._refuse(stream_id, stream, GRPC_RESOURCE_EXHAUSTED,
                             f"requests buffered at once larger than the server's limit of "
                             f"{self.transport.max_message_bytes} bytes")
        if flags & END_STREAM:
            self._end_stream(stream_id, calls)

    def _end_stream(self, stream_id: int, calls: list) -> None:
        stream = self.streams[stream_id]
        stream.ended = True
        if stream.refused:
            self.streams.pop(stream_id, None)
            return
        body = stream.body
        if len(body) < 5:
            self._refuse(stream_id, stream, GRPC_INTERNAL, "the request carried no gRPC message")
        elif body[0]:
            self._refuse(stream_id, stream, GRPC_UNIMPLEMENTED, "compressed messages are not supported")
        elif struct.unpack_from(">I", body, 1)[0] != len(body) - 5:
            self._refuse(stream_id, stream, GRPC_INTERNAL,
                         f"the gRPC length prefix says {struct.unpack_from('>I', body, 1)[0]} bytes but "
                         f"{len(body) - 5} followed; a unary request carries exactly one message")
        else:
            call = IncomingCall(self, stream_id, bytes(body[5:]))
            stream.body = bytearray()
            self.active_at = time.monotonic()
            self.pending[stream_id] = call
            calls.append(call)

    def _refuse(self, stream_id: int, stream: _Stream, status: int, message: str) -> None:
        logger.warning("Refused a call from %s: %s", self.peer, message)
        stream.refused = True
        stream.body = bytearray()
        self.send_error(stream_id, status, message, flush=False)

    def _reset(self, stream_id: int, code: int, why: str) -> None:
        """A stream error: RST_STREAM with ``code``; the stream's call (if any) is cancelled."""
        logger.warning("Reset stream %d from %s: %s", stream_id, self.peer, why)
        self.out += frame(RST_STREAM, 0, stream_id, struct.pack(">I", code))
        self.streams.pop(stream_id, None)
        self.reset_ids.append(stream_id)
        self._cancel(stream_id, why)

    def _cancel(self, stream_id: int, why: str) -> None:
        call = self.pending.pop(stream_id, None)
        if call is not None:
            call.cancelled = True
            self.transport.call_dropped(call, why)

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
        if stream is not None and (stream.ended or not stream.refused):
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
            if select.select([self.sock], [], [], 1.0)[0]:
                self.transport.queue_calls(self.read_available())
        return True

    def flush(self, wait: bool = True) -> None:
        """Send ``out``; ``wait=False`` (replies to PING/SETTINGS, WINDOW_UPDATE) sends what the
        socket takes now and keeps the rest, so a client that floods without reading cannot stall
        the trainer: past ``MAX_UNSENT`` bytes kept, its connection is closed."""
        if not self.out or self.closed:
            self.out.clear()
            return
        try:
            if wait:
                data, self.out = bytes(self.out), bytearray()
                self.sock.sendall(data)
                return
            self.sock.setblocking(False)
            try:
                sent = self.sock.send(bytes(self.out))  # a copy: `out` stays resizable
            except BlockingIOError:
                sent = 0
            finally:
                self.sock.settimeout(_SEND_TIMEOUT_S)
            del self.out[:sent]
            if len(self.out) > MAX_UNSENT:
                logger.warning("Closing the connection from %s: it does not read what the trainer sends "
                               "(%d bytes of replies waiting), e.g. it floods PINGs", self.peer, len(self.out))
                self.drop("the client does not read its replies")
        except (OSError, socket.timeout) as error:
            self.drop(f"sending failed ({error})")

    # ------------------------------------------------------------------ teardown
    def drop(self, why: str) -> None:
        if self.closed:
            return
        self.closed = True
        self.out.clear()
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
                    if not self.sock.recv(RECV_BYTES):
                        break
                except socket.timeout:
                    continue
        except OSError:
            pass
        self.pending.clear()  # answered with 400 by the endpoint already; nothing to cancel
        self.drop("the server closed")

    def close_with(self, code: int, why: str) -> None:
        """A connection error or one the server ends on its own account: one log line, GOAWAY
        (sent as far as the socket takes it now: a client that does not read cannot make the
        trainer wait), closed."""
        logger.warning("Closing the connection from %s: %s", self.peer, why)
        if not self.closed:
            self.out += frame(GOAWAY, 0, 0, struct.pack(">II", self.last_stream, code) + why.encode()[:200])
            self.flush(wait=False)
        self.drop(why)

    def at_eof(self) -> bool:
        """The client has closed its end (a peek, nothing is consumed)."""
        if self.closed:
            return True
        try:
            if not select.select([self.sock], [], [], 0.0)[0]:
                return False  # (recv on a socket with a timeout would wait for data first)
            return self.sock.recv(1, socket.MSG_PEEK) == b""
        except (ConnectionError, ValueError):
            return True
        except OSError:
            return False

    def idle(self) -> bool:
        return not self.pending and not self.streams


def _peer_name(sock: socket.socket) -> str:
    try:
        host, port = sock.getpeername()[:2]
        return f"{host}:{port}"
    except OSError:
        return "a client"


class Http2Transport:
    """Listens on ``bind:port`` and hands out complete unary calls of ``path``."""

    def __init__(self, bind: str, port: int, path: bytes, max_message_bytes: int, spin_s: float = 0.0,
                 listener: socket.socket | None = None) -> None:
        """``listener``: a socket already listening on ``bind:port`` (trainer.protocol.listen) to
        serve on instead of binding one in ``start``; the transport closes it."""
        self.bind = bind
        self.port = port
        self.path = path
        self.max_message_bytes = max_message_bytes
        self.pace = PacedWait(spin_s)  # when the simulator's next call is due (pacing.py)
        self.client_gone = False
        self.closed = False
        self._listener: socket.socket | None = None
        self._given_listener = listener
        self._selector = selectors.DefaultSelector()
        self._connections: dict[socket.socket, _Connection] = {}
        self._ready: collections.deque[IncomingCall] = collections.deque()
        self.reader = ReadBuffer()
        # the connection whose calls the trainer takes; others are refused while it lives, so a
        # second client on the port cannot inject steps into the session (docs/protocol.md, "Malformed HTTP/2")
        self.session: _Connection | None = None
        self._next_sweep = 0.0
        # take() may wait on one thread while close() runs on another (a thread serving the
        # simulator, stopped from outside): close() must not free the receive buffer, the selector
        # or a socket under a read in progress (a BufferError, or EBADF from a closed epoll). Each
        # read round holds this lock; close() wakes the round's select through _wake and then
        # takes the lock, so it waits for that round only, never for the rest of take()'s timeout.
        self._lock = threading.Lock()
        self._wake: tuple[socket.socket, socket.socket] | None = None

    def start(self) -> None:
        listener, self._given_listener = self._given_listener or listen(self.bind, self.port), None
        self.port = listener.getsockname()[1]
        self._listener = listener
        self._selector.register(listener, selectors.EVENT_READ)
        self._wake = socket.socketpair()
        self._wake[0].setblocking(False)
        self._selector.register(self._wake[0], selectors.EVENT_READ)

    # callbacks from connections
    def call_dropped(self, call: IncomingCall, why: str) -> None:
        """The session's client went away with a call unanswered: the trainer is told
        (``client_gone``). Another connection's calls never reached the trainer."""
        logger.debug("Call on stream %d dropped: %s", call.stream_id, why)
        if call.connection is self.session:
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

    def refusal(self, connection: _Connection) -> str | None:
        """Why ``connection`` may not make calls (another live client holds the session), or None."""
        session = self.session
        if session is None or session is connection:
            return None
        if session.at_eof():
            session.drop("the connection was closed")
        if session.closed:
            self.session = None
            return None
        return (f"port {self.port} is held by a live training session with {session.peer}; a second "
                "simulator cannot join it. Give each simulator its own port (--num-envs, --base-port).")

    def _adopt(self, call: IncomingCall) -> bool:
        """True if ``call`` belongs to the session (its connection becomes the session if there is
        none); else the call is refused and its connection closed."""
        connection = call.connection
        refusal = self.refusal(connection)
        if refusal is None:
            self.session = connection
            if call.cancelled:  # dropped before the trainer took it: as if dropped after
                self.client_gone = True
            return True
        call.answered = True
        if not call.cancelled:
            connection.send_error(call.stream_id, GRPC_FAILED_PRECONDITION, refusal, flush=False)
        connection.close_with(NO_ERROR, refusal)  # never waits on a client that does not read
        return False

    def _sweep(self) -> None:
        """Close connections that never finished the preface (slow-loris) or sit idle."""
        now = time.monotonic()
        if now < self._next_sweep:
            return
        self._next_sweep = now + 1.0
        for connection in list(self._connections.values()):
            if connection is self.session:
                continue
            if not connection.settings_seen and now - connection.opened_at > PREFACE_TIMEOUT_S:
                connection.close_with(PROTOCOL_ERROR, f"no HTTP/2 preface within {PREFACE_TIMEOUT_S:.0f} s")
            elif connection.idle() and now - connection.active_at > IDLE_TIMEOUT_S:
                connection.close_with(NO_ERROR, f"idle for {IDLE_TIMEOUT_S:.0f} s")

    def _pump(self, timeout: float) -> bool:
        """One select round: accept, read, collect calls. False if nothing was ready."""
        with self._lock:
            if self.closed:
                return False
            return self._pump_locked(timeout)

    def _pump_locked(self, timeout: float) -> bool:
        if self._connections:
            self._sweep()
        events = self._selector.select(timeout)
        for key, _ in events:
            if self._wake is not None and key.fileobj is self._wake[0]:
                continue  # close() on another thread: the caller sees `closed` next
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
        while self._ready:
            call = self._ready.popleft()
            if self._adopt(call):
                return call
        return None

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
        if len(self._connections) >= MAX_CONNECTIONS:
            idle = [c for c in self._connections.values() if c is not self.session and c.idle()]
            if not idle:
                logger.warning("Refused a connection from %s: %d connections are open already",
                               _peer_name(sock), MAX_CONNECTIONS)
                sock.close()
                return
            min(idle, key=lambda c: c.active_at).close_with(
                NO_ERROR, f"idle, and {MAX_CONNECTIONS} connections are open (the most this server keeps)")
        connection = _Connection(sock, self)
        if not connection.closed:
            self._connections[sock] = connection
            self._selector.register(sock, selectors.EVENT_READ)

    def close(self, grace: float = 2.0) -> None:
        if self.closed:
            return
        self.closed = True
        if self._wake is not None:
            self._wake[1].send(b"\0")  # ends a select that another thread's take() is in
        with self._lock:
            self._close_locked(grace)

    def _close_locked(self, grace: float) -> None:
        if self._given_listener is not None:  # never started
            self._given_listener.close()
            self._given_listener = None
        if self._listener is not None:
            self._selector.unregister(self._listener)
            self._listener.close()
            self._listener = None
        for connection in list(self._connections.values()):
            connection.shutdown(grace)
        self._connections.clear()
        self._ready.clear()
        self._selector.close()
        if self._wake is not None:
            for end in self._wake:
                end.close()
            self._wake = None
        self.session = None  # (connection <-> transport: no cycle left through it)
        self.reader.release()
