"""The simulator's gRPC client: blocking unary calls over HTTP/2, on the caller's thread.

What a simulator needs to call ``Exchange`` like Unity's gRPC client does, without gRPC's
threads (grpcio's client is the other choice, ``communicator._GrpcioChannel``). The framing
(frames, HPACK helpers, limits) is protos/http2.py, which the trainer's server uses too.

    channel = Http2Channel("localhost", 5005, b"/pkg.Service/Method")
    channel.connect(timeout=1.0)       # False while nothing listens
    answer = channel.call(request)     # raises CallError
    channel.close()
"""
from __future__ import annotations

import select
import socket
import struct
from urllib.parse import unquote

from protos.http2 import (
    ACK, CANCEL, CONTINUATION, DATA, DEFAULT_WINDOW, END_HEADERS, END_STREAM, FRAME_SIZE_ERROR, GOAWAY,
    GRPC_OK, HEADERS, MAX_WINDOW, NO_ERROR, OUR_MAX_FRAME, PING, PREFACE, PRIORITY_FLAG, RST_STREAM,
    SETTINGS, SETTINGS_INITIAL_WINDOW_SIZE, SETTINGS_MAX_FRAME_SIZE, WINDOW_UPDATE, CachingDecoder,
    FRAME_NAMES, Http2Error, ReadBuffer, frame, hpack_int, hpack_literal, strip_padding, take_frames,
)
from protos.pacing import PacedWait, wait_paced

_MIN_LENGTH = {RST_STREAM: 4, WINDOW_UPDATE: 4, GOAWAY: 8, PING: 8}  # what the client reads of them


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
        self._reader = ReadBuffer()
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
            if len(payload) < _MIN_LENGTH.get(kind, 0):
                raise Http2Error(f"{FRAME_NAMES[kind]} frame of {len(payload)} bytes", FRAME_SIZE_ERROR)
            if kind == DATA:
                self._recv_unacked += len(payload)  # flow control counts padding too
                payload = strip_padding(flags, payload)
                if self._recv_unacked > MAX_WINDOW // 2:
                    out += frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", self._recv_unacked))
                    self._recv_unacked = 0
                if sid == stream_id and response is not None:
                    response["data"] += payload
                    ended |= bool(flags & END_STREAM)
            elif kind in (HEADERS, CONTINUATION):
                if kind == HEADERS:
                    payload = strip_padding(flags, payload)
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

    def close(self, abort: bool = False) -> None:
        """GOAWAY, then close. ``abort`` (the trainer has ended the session: nothing more to say)
        closes with a reset instead of a FIN, so no TIME_WAIT is left on the trainer's port:
        mlagents_envs binds its port again without SO_REUSEADDR when a script opens its next
        UnityEnvironment, and a TIME_WAIT there fails that bind."""
        if self.sock is not None:
            try:
                self.sock.sendall(frame(GOAWAY, 0, 0, struct.pack(">II", 0, NO_ERROR)))
            except OSError:
                pass
            if abort:
                try:
                    self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                except OSError:
                    pass
            try:
                self.sock.close()
            except OSError:
                pass
            self.sock = None


def _unquote(value: bytes) -> str:
    return unquote(value.decode("utf-8", errors="replace"))
