"""The trainer's gRPC server on python-hyper's ``h2`` state machine: measured, not used.

``bench/transport.py`` compares it with the hand-written server of ``trainer/protocol/http2_server.py``
(and with grpcio). Same interface and threading as ``http2_server.Http2Transport``, which it extends
(listener, ``take`` with pacing, ``poll``, ``close``); only each connection's frame handling is
``h2``'s: it parses and validates every frame (RFC 9113), keeps both flow-control windows and
the HPACK tables, and reports requests as events. The hand-written server was kept because this
one costs about 6x more per exchange on the trainer's side (e.g. 150 vs 21 us for basic, 126 us
with h2's header validation off) and about half of the exchanges/s of bench/protocol.py for
basic: see bench/RESULTS.md.
"""
from __future__ import annotations

import logging
import socket
import struct
import time

import h2.config
import h2.connection
import h2.events
import h2.exceptions
import h2.settings

from protos import http2
from protos.http2 import (
    GRPC_INTERNAL,
    GRPC_RESOURCE_EXHAUSTED,
    GRPC_UNIMPLEMENTED,
    MAX_WINDOW,
    OUR_MAX_FRAME,
    ReadBuffer,
)
from trainer.protocol import http2_server
from trainer.protocol.http2_server import IncomingCall, _peer_name

logger = logging.getLogger(__name__)

_RESPONSE_HEADERS = [(b":status", b"200"), (b"content-type", b"application/grpc")]
_TRAILERS_OK = [(b"grpc-status", b"0")]
_SEND_TIMEOUT_S = 30.0
_CONFIG = h2.config.H2Configuration(
    client_side=False, header_encoding=None,
    validate_outbound_headers=False, normalize_outbound_headers=False,
    validate_inbound_headers=True, normalize_inbound_headers=False,
)


class _Stream:
    __slots__ = ("body", "refused")

    def __init__(self) -> None:
        self.body = bytearray()
        self.refused = False


class H2Connection:
    """One connection driven by ``h2.connection.H2Connection``: what ``Http2Transport`` needs
    from a connection (``read_available``, ``drop``, ``shutdown``) and what ``IncomingCall``
    needs (``send_response``, ``send_error``)."""

    def __init__(self, sock: socket.socket, transport: "H2Transport") -> None:
        self.sock = sock
        self.transport = transport
        self.peer = _peer_name(sock)
        self._reader = ReadBuffer()
        self._buffer = bytearray()
        self.streams: dict[int, _Stream] = {}
        self.pending: dict[int, IncomingCall] = {}
        self.closed = False
        # what Http2Transport's connection bookkeeping reads (docs/protocol.md: limits); h2 checks
        # the preface itself, so the slow-loris sweep treats it as seen
        self.opened_at = self.active_at = time.monotonic()
        self.settings_seen = True
        self.conn = h2.connection.H2Connection(config=_CONFIG)
        self.conn.local_settings = h2.settings.Settings(client=False, initial_values={
            h2.settings.SettingCodes.INITIAL_WINDOW_SIZE: MAX_WINDOW,
            h2.settings.SettingCodes.MAX_FRAME_SIZE: OUR_MAX_FRAME,
            h2.settings.SettingCodes.MAX_CONCURRENT_STREAMS: 100,
            h2.settings.SettingCodes.MAX_HEADER_LIST_SIZE: 1 << 16,
        })
        # h2 takes the size from these settings only when the client acknowledges them, and only
        # between reads: a client that sends its ACK and a large frame in one write would be refused
        self.conn.max_inbound_frame_size = OUR_MAX_FRAME
        sock.setblocking(True)
        sock.settimeout(_SEND_TIMEOUT_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.conn.initiate_connection()
        self.conn.increment_flow_control_window(MAX_WINDOW - 65535)
        self.flush()

    def read_available(self) -> list[IncomingCall]:
        try:
            received = self._reader.read_into(self.sock, self._buffer)
        except (ConnectionError, OSError):
            received = 0
        if not received:
            self.drop("the connection was closed")
            return []
        data, self._buffer = bytes(self._buffer), bytearray()
        calls: list[IncomingCall] = []
        try:
            events = self.conn.receive_data(data)
            for event in events:
                self._event(event, calls)
        except h2.exceptions.ProtocolError as error:
            logger.warning("Closing the connection from %s: %s", self.peer, error)
            # h2's own GOAWAY (when it queued one) carries no reason: ours says why
            self.conn.data_to_send()
            code = int(getattr(error, "error_code", None) or http2.PROTOCOL_ERROR)
            goaway = struct.pack(">II", self.conn.highest_inbound_stream_id, code) + str(error).encode()[:200]
            self._send_raw(http2.frame(http2.GOAWAY, 0, 0, goaway))
            self.drop(str(error))
            return []
        self.flush()
        return calls

    def _event(self, event, calls: list) -> None:
        kind = type(event)
        if kind is h2.events.DataReceived:
            if event.flow_controlled_length:
                self.conn.acknowledge_received_data(event.flow_controlled_length, event.stream_id)
            stream = self.streams.get(event.stream_id)
            if stream is not None and not stream.refused:
                stream.body += event.data
                if len(stream.body) > self.transport.max_message_bytes + 5:
                    self._refuse(event.stream_id, stream, GRPC_RESOURCE_EXHAUSTED,
                                 f"message larger than the server's limit of {self.transport.max_message_bytes} bytes")
            if event.stream_ended is not None:
                self._end_stream(event.stream_id, calls)
        elif kind is h2.events.RequestReceived:
            stream = _Stream()
            self.streams[event.stream_id] = stream
            fields = dict(event.headers)
            path = fields.get(b":path", b"")
            if fields.get(b":method") != b"POST" or not fields.get(b"content-type", b"").startswith(b"application/grpc"):
                self._refuse(event.stream_id, stream, GRPC_INTERNAL, "expected a gRPC POST request")
            elif path != self.transport.path:
                self._refuse(event.stream_id, stream, GRPC_UNIMPLEMENTED,
                             f"unknown method {path.decode(errors='replace')}; this server only serves "
                             f"{self.transport.path.decode()}")
            if event.stream_ended is not None:
                self._end_stream(event.stream_id, calls)
        elif kind is h2.events.StreamReset:
            self.streams.pop(event.stream_id, None)
            call = self.pending.pop(event.stream_id, None)
            if call is not None:
                call.cancelled = True
                self.transport.call_dropped(call, "the simulator cancelled its call")
        elif kind is h2.events.ConnectionTerminated:
            pass  # GOAWAY: calls in flight may still be answered

    def _end_stream(self, stream_id: int, calls: list) -> None:
        stream = self.streams.get(stream_id)
        if stream is None or stream.refused:
            self.streams.pop(stream_id, None)
            return
        body = stream.body
        if len(body) < 5:
            self._refuse(stream_id, stream, GRPC_INTERNAL, "the request carried no gRPC message")
        elif body[0]:
            self._refuse(stream_id, stream, GRPC_UNIMPLEMENTED, "compressed messages are not supported")
        elif struct.unpack_from(">I", body, 1)[0] != len(body) - 5:
            self._refuse(stream_id, stream, GRPC_INTERNAL, "a unary request must carry exactly one complete gRPC message")
        else:
            call = IncomingCall(self, stream_id, bytes(body[5:]))
            stream.body = bytearray()
            self.pending[stream_id] = call
            calls.append(call)

    def _refuse(self, stream_id: int, stream: _Stream, status: int, message: str) -> None:
        logger.warning("Refused a call from %s: %s", self.peer, message)
        stream.refused = True
        stream.body = bytearray()
        self.send_error(stream_id, status, message, flush=False)

    def send_response(self, stream_id: int, message: bytes) -> None:
        self.pending.pop(stream_id, None)
        if self.closed or stream_id not in self.streams:
            return
        conn = self.conn
        try:
            conn.send_headers(stream_id, _RESPONSE_HEADERS)
            body = memoryview(b"\x00" + struct.pack(">I", len(message)) + message)
            offset = 0
            while offset < len(body):
                allowed = min(conn.local_flow_control_window(stream_id), conn.max_outbound_frame_size,
                              len(body) - offset)
                if allowed <= 0:
                    self.flush()
                    if not self._wait_for_window(stream_id):
                        return
                    continue
                conn.send_data(stream_id, body[offset:offset + allowed].tobytes())
                offset += allowed
            conn.send_headers(stream_id, _TRAILERS_OK, end_stream=True)
        except (h2.exceptions.StreamClosedError, h2.exceptions.ProtocolError) as error:
            logger.debug("Answer on stream %d not sent: %s", stream_id, error)
        self.streams.pop(stream_id, None)
        self.flush()
        self.transport.pace.sent()

    def send_error(self, stream_id: int, status: int, message: str, flush: bool = True) -> None:
        self.pending.pop(stream_id, None)
        headers = _RESPONSE_HEADERS + [(b"grpc-status", str(status).encode())]
        if message:
            headers.append((b"grpc-message", _percent(message)))
        try:
            self.conn.send_headers(stream_id, headers, end_stream=True)
        except (h2.exceptions.StreamClosedError, h2.exceptions.ProtocolError):
            pass
        stream = self.streams.get(stream_id)
        if stream is not None and not stream.refused:
            self.streams.pop(stream_id, None)
        if flush:
            self.flush()

    def _wait_for_window(self, stream_id: int) -> bool:
        deadline = time.monotonic() + _SEND_TIMEOUT_S
        import selectors

        while self.conn.local_flow_control_window(stream_id) <= 0:
            if self.closed or stream_id not in self.streams or time.monotonic() > deadline:
                self.drop("the client stopped reading its answer")
                return False
            with selectors.DefaultSelector() as readable:
                readable.register(self.sock, selectors.EVENT_READ)
                ready = readable.select(1.0)
            if ready:
                self.transport.queue_calls(self.read_available())
        return True

    def flush(self) -> None:
        self._send_raw(self.conn.data_to_send())

    def _send_raw(self, data: bytes) -> None:
        if not data or self.closed:
            return
        try:
            self.sock.sendall(data)
        except (OSError, socket.timeout) as error:
            self.drop(f"sending failed ({error})")

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

    def idle(self) -> bool:
        return not self.pending and not self.streams

    def close_with(self, code: int, why: str) -> None:
        """Close with GOAWAY carrying ``code`` (h2 error code), as ``http2`` connections do."""
        if not self.closed:
            try:
                self.conn.close_connection(error_code=code, additional_data=why.encode()[:200])
                self.flush()
            except Exception:  # noqa: BLE001 - best effort on a connection being dropped
                pass
        self.drop(why)

    def shutdown(self, grace: float) -> None:
        if self.closed:
            return
        try:
            self.conn.close_connection()
        except h2.exceptions.ProtocolError:
            pass
        self.flush()
        if self.closed:
            return
        try:
            self.sock.shutdown(socket.SHUT_WR)
            deadline = time.monotonic() + grace
            self.sock.settimeout(0.05)
            while time.monotonic() < deadline:
                try:
                    if not self.sock.recv(1 << 20):
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


def _percent(message: str) -> bytes:
    from urllib.parse import quote

    return quote(message, safe=" !\"#$&'()*+,-./:;<=>?@[\\]^_`{|}~").encode()


class H2Transport(http2_server.Http2Transport):
    """``Http2Transport`` whose connections are ``h2`` state machines."""

    def _accept(self) -> None:
        try:
            sock, _ = self._listener.accept()
        except (BlockingIOError, OSError):
            return
        connection = H2Connection(sock, self)
        if not connection.closed:
            self._connections[sock] = connection
            import selectors

            self._selector.register(sock, selectors.EVENT_READ)
