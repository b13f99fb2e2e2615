"""RFC 9113 conformance of the trainer's HTTP/2 server: every frame-level error a server of unary
gRPC calls can meet, sent as real bytes over a loopback socket to the real ``Http2Transport``.

Each case asserts the exact reaction: a connection error answers GOAWAY with its error code and
closes the connection, a stream error answers RST_STREAM with its code and leaves the connection
serving, a bad gRPC message gets a trailers-only answer with its grpc-status. In every case the
trainer's side logs one line saying why, ``take`` returns (no exception escapes, no hang).
"""
from __future__ import annotations

import logging
import socket
import struct

import h2.config
import h2.connection
import h2.events
import hpack
import pytest

from tests.protocol.conftest import free_port
from trainer.protocol import http2_server
from trainer.errors import UnityTimeOutError
from protos import http2
from protos.http2 import (
    ACK, CONTINUATION, DATA, END_HEADERS, END_STREAM, GOAWAY, HEADERS, PADDED, PING, PRIORITY,
    PRIORITY_FLAG, PUSH_PROMISE, RST_STREAM, SETTINGS, WINDOW_UPDATE, frame,
)
from trainer.protocol.server import EXCHANGE_PATH, UnityEndpoint
from unity_stub_env.http2_client import request_headers

pytestmark = pytest.mark.timeout(30)

PROTOCOL, FLOW, STREAM_CLOSED, FRAME_SIZE = 0x1, 0x3, 0x5, 0x6
REFUSED, COMPRESSION, CALM = 0x7, 0x9, 0xB
HELLO = b"\x00" + struct.pack(">I", 5) + b"hello"  # one gRPC message
PREAMBLE = http2.PREFACE + frame(SETTINGS, 0, 0)
HEADER_BLOCK = request_headers(EXCHANGE_PATH, b"127.0.0.1")


def headers(stream_id: int, end_stream: bool = False, block: bytes = HEADER_BLOCK) -> bytes:
    return frame(HEADERS, END_HEADERS | (END_STREAM if end_stream else 0), stream_id, block)


def request(stream_id: int, body: bytes = HELLO) -> bytes:
    return headers(stream_id) + frame(DATA, END_STREAM, stream_id, body)


def window_update(stream_id: int, increment: int) -> bytes:
    return frame(WINDOW_UPDATE, 0, stream_id, struct.pack(">I", increment))


def setting(key: int, value: int) -> bytes:
    return frame(SETTINGS, 0, 0, struct.pack(">HI", key, value))


@pytest.fixture
def transport():
    t = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, max_message_bytes=1000)
    t.start()
    yield t
    t.close(grace=0.1)


class Client:
    """A raw client socket; the test's thread also runs the server (``pump``)."""

    def __init__(self, transport, preamble: bytes = PREAMBLE) -> None:
        self.transport = transport
        self.sock = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
        self.buffer = bytearray()
        self.calls: list = []
        if preamble:
            self.sock.sendall(preamble)

    def send(self, data: bytes) -> "Client":
        self.sock.sendall(data)
        return self

    def pump(self, rounds: int = 2) -> list:
        for _ in range(rounds):
            call = self.transport.take(0.05)
            if call is not None:
                self.calls.append(call)
        return self.calls

    def frames(self, until_closed: bool) -> list[tuple[int, int, int, bytes]]:
        """Frames the server sent: until it closes the connection, or for 0.2 s."""
        self.sock.settimeout(5 if until_closed else 0.2)
        try:
            while True:
                data = self.sock.recv(1 << 16)
                if not data:
                    break
                self.buffer += data
        except (socket.timeout, ConnectionResetError):
            if until_closed:
                raise AssertionError("the server did not close the connection")
        out = http2.take_frames(self.buffer)
        assert not self.buffer  # only whole frames
        return out

    def close(self) -> None:
        self.sock.close()


def goaway(transport, data: bytes, preamble: bytes = PREAMBLE) -> tuple[int, int, str]:
    """Send ``data``; the server must answer GOAWAY and close: (last stream, code, reason)."""
    client = Client(transport, preamble)
    client.send(data).pump()
    frames = client.frames(until_closed=True)
    client.close()
    (payload,) = [p for kind, _, sid, p in frames if kind == GOAWAY and sid == 0]
    assert all(kind != RST_STREAM for kind, *_ in frames)
    last, code = struct.unpack_from(">II", payload)
    assert transport._connections == {}
    return last, code, payload[8:].decode()


# (name, bytes after the preface and an empty SETTINGS, GOAWAY code, reason in GOAWAY and log)
CONNECTION_ERRORS = [
    ("SETTINGS not a multiple of 6", frame(SETTINGS, 0, 0, b"\0" * 7), FRAME_SIZE, "SETTINGS frame of 7 bytes"),
    ("SETTINGS ack with payload", frame(SETTINGS, ACK, 0, b"\0" * 6), FRAME_SIZE, "acknowledgement with a payload"),
    ("PING of 7 bytes", frame(PING, 0, 0, b"\0" * 7), FRAME_SIZE, "PING frame of 7 bytes (must be 8)"),
    ("PING of 9 bytes", frame(PING, 0, 0, b"\0" * 9), FRAME_SIZE, "PING frame of 9 bytes (must be 8)"),
    ("WINDOW_UPDATE empty", frame(WINDOW_UPDATE, 0, 0), FRAME_SIZE, "WINDOW_UPDATE frame of 0 bytes"),
    ("WINDOW_UPDATE 1 byte", frame(WINDOW_UPDATE, 0, 0, b"\x01"), FRAME_SIZE, "WINDOW_UPDATE frame of 1 bytes"),
    ("WINDOW_UPDATE 5 bytes", frame(WINDOW_UPDATE, 0, 0, b"\0\0\0\x01\0"), FRAME_SIZE, "WINDOW_UPDATE frame of 5"),
    ("stream WINDOW_UPDATE 1 byte", headers(1) + frame(WINDOW_UPDATE, 0, 1, b"\x01"), FRAME_SIZE,
     "WINDOW_UPDATE frame of 1 bytes"),
    ("RST_STREAM of 3 bytes", headers(1) + frame(RST_STREAM, 0, 1, b"\0\0\x08"), FRAME_SIZE,
     "RST_STREAM frame of 3 bytes (must be 4)"),
    ("RST_STREAM of 5 bytes", headers(1) + frame(RST_STREAM, 0, 1, b"\0" * 5), FRAME_SIZE, "RST_STREAM frame of 5"),
    ("GOAWAY of 7 bytes", frame(GOAWAY, 0, 0, b"\0" * 7), FRAME_SIZE, "GOAWAY frame of 7 bytes"),
    ("connection window past 2^31-1", window_update(0, 2**31 - 1), FLOW, "beyond 2^31-1 on the connection"),
    ("zero WINDOW_UPDATE on the connection", window_update(0, 0), PROTOCOL, "increment of 0 on the connection"),
    ("INITIAL_WINDOW_SIZE above 2^31-1", setting(0x4, 2**31), FLOW, "SETTINGS_INITIAL_WINDOW_SIZE of 2147483648"),
    ("INITIAL_WINDOW_SIZE overflows an open stream",
     headers(1) + window_update(1, 2**31 - 1 - 65535) + setting(0x4, 65536), FLOW, "overflows a stream's window"),
    ("ENABLE_PUSH of 2", setting(0x2, 2), PROTOCOL, "SETTINGS_ENABLE_PUSH of 2 (must be 0 or 1)"),
    ("MAX_FRAME_SIZE below 16384", setting(0x5, 16383), PROTOCOL, "SETTINGS_MAX_FRAME_SIZE of 16383"),
    ("MAX_FRAME_SIZE above 2^24-1", setting(0x5, 2**24), PROTOCOL, "SETTINGS_MAX_FRAME_SIZE of 16777216"),
    ("DATA on stream 0", frame(DATA, 0, 0, b"x"), PROTOCOL, "DATA frame on stream 0"),
    ("HEADERS on stream 0", headers(0), PROTOCOL, "HEADERS frame on stream 0"),
    ("RST_STREAM on stream 0", frame(RST_STREAM, 0, 0, b"\0\0\0\x08"), PROTOCOL, "RST_STREAM frame on stream 0"),
    ("PRIORITY on stream 0", frame(PRIORITY, 0, 0, b"\0" * 5), PROTOCOL, "PRIORITY frame on stream 0"),
    ("SETTINGS on a stream", headers(1) + frame(SETTINGS, 0, 1), PROTOCOL, "SETTINGS frame on stream 1"),
    ("PING on a stream", frame(PING, 0, 1, b"\0" * 8), PROTOCOL, "PING frame on stream 1"),
    ("GOAWAY on a stream", frame(GOAWAY, 0, 1, b"\0" * 8), PROTOCOL, "GOAWAY frame on stream 1"),
    ("DATA on an idle stream", frame(DATA, END_STREAM, 1, HELLO), PROTOCOL, "DATA frame on stream 1, which was never"),
    ("WINDOW_UPDATE on an idle stream", window_update(3, 1), PROTOCOL, "WINDOW_UPDATE frame on stream 3, which"),
    ("RST_STREAM on an idle stream", frame(RST_STREAM, 0, 5, b"\0\0\0\x08"), PROTOCOL, "RST_STREAM frame on stream 5"),
    ("even stream id", headers(2), PROTOCOL, "stream id 2 is even"),
    ("decreasing stream id", headers(5) + headers(3), PROTOCOL, "stream id 3 is not above the last one (5)"),
    ("CONTINUATION without HEADERS", frame(CONTINUATION, END_HEADERS, 1, b"\x83"), PROTOCOL,
     "CONTINUATION frame without a HEADERS frame"),
    ("CONTINUATION for another stream", frame(HEADERS, 0, 1, b"\x83") + frame(CONTINUATION, END_HEADERS, 3, b"\x86"),
     PROTOCOL, "CONTINUATION frame without a HEADERS frame before it on its stream"),
    ("a frame between header fragments", frame(HEADERS, 0, 1, b"\x83") + frame(PING, 0, 0, b"\0" * 8), PROTOCOL,
     "expected a CONTINUATION frame"),
    ("CONTINUATION flood", frame(HEADERS, 0, 1, b"\x83") + frame(CONTINUATION, 0, 1) * 65, CALM,
     "more than 64 CONTINUATION frames"),
    ("DATA padding as long as the frame", headers(1) + frame(DATA, PADDED, 1, b"\x04abc"), PROTOCOL, "bad padding"),
    ("DATA padded but empty", headers(1) + frame(DATA, PADDED, 1), PROTOCOL, "bad padding"),
    ("HEADERS padding too long", frame(HEADERS, PADDED | END_HEADERS, 1, b"\x09" + HEADER_BLOCK[:3]), PROTOCOL,
     "bad padding"),
    ("HEADERS too short for its priority", frame(HEADERS, PRIORITY_FLAG | END_HEADERS, 1, b"\0\0\0"), FRAME_SIZE,
     "too short for its priority fields"),
    ("frame above SETTINGS_MAX_FRAME_SIZE", struct.pack(">I", 2**20 + 1)[1:] + b"\x00\x00\x00\x00\x00\x01", FRAME_SIZE,
     "frame of 1048577 bytes exceeds the maximum"),
    ("PUSH_PROMISE from a client", frame(PUSH_PROMISE, END_HEADERS, 1, b"\0\0\0\x02\x83"), PROTOCOL,
     "a client may not send PUSH_PROMISE"),
    ("undecodable HPACK", headers(1, block=b"\xff\xff\xff\xff\x0f"), COMPRESSION, "undecodable header block"),
    ("HPACK bomb: small block, huge header list",
     # one 4000-byte value added to the dynamic table (index 62), then referenced 20 times
     headers(1, block=b"\x40" + http2.hpack_int(1, 7) + b"x" + http2.hpack_int(4000, 7) + b"v" * 4000 + b"\xbe" * 20),
     CALM, "headers larger than 65536 bytes once decoded"),
    ("header block above 64 KiB", frame(HEADERS, 0, 1, b"\0" * 16384) + frame(CONTINUATION, 0, 1, b"\0" * 16384) * 4,
     CALM, "header block larger than 65536 bytes"),
]


@pytest.mark.parametrize(("data", "code", "reason"), [case[1:] for case in CONNECTION_ERRORS],
                         ids=[case[0] for case in CONNECTION_ERRORS])
def test_connection_errors_answer_goaway_with_the_rfc_code(transport, caplog, data, code, reason):
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        _, got_code, got_reason = goaway(transport, data)
    assert (got_code, reason in got_reason) == (code, True), got_reason
    (record,) = [r for r in caplog.records if r.name == "trainer.protocol.http2_server"]
    assert record.getMessage().startswith("Closing the connection from 127.0.0.1:") and reason in record.getMessage()
    assert record.exc_info is None
    assert transport.take(0.0) is None and not transport.closed  # still listening for the next client


def test_a_bad_preface_and_a_missing_settings_frame_are_protocol_errors(transport):
    assert goaway(transport, b"", preamble=b"PRI * HTTP/1.1\r\n\r\n")[1:] == (PROTOCOL, _reason_preface())
    _, code, reason = goaway(transport, frame(PING, 0, 0, b"\0" * 8), preamble=http2.PREFACE)
    assert (code, reason) == (PROTOCOL, "the connection preface must be followed by a SETTINGS frame")


def _reason_preface() -> str:
    return ("the client did not start with the HTTP/2 preface; only gRPC clients (a Unity player or the "
            "Editor with ML-Agents) can talk to this port")


def test_goaway_names_the_last_stream_it_took(transport):
    last, code, _ = goaway(transport, request(1) + request(3) + frame(PING, 0, 0, b"\0"))
    assert (last, code) == (3, FRAME_SIZE)


def test_data_beyond_the_connection_window_we_granted_is_a_flow_control_error(transport, caplog):
    """We grant 2^31-1 bytes and top it up once half is used; to reach the limit without sending
    2 GB, the server's record of what is left is lowered to 10 bytes before 11 arrive."""
    client = Client(transport)
    client.send(headers(1)).pump()
    (connection,) = transport._connections.values()
    connection.recv_window = 10
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        client.send(frame(DATA, 0, 1, b"x" * 11)).pump()
    frames = client.frames(until_closed=True)
    (payload,) = [p for kind, _, _, p in frames if kind == GOAWAY]
    assert struct.unpack_from(">II", payload) == (1, FLOW) and b"beyond the connection's flow-control window" in payload
    assert "beyond the connection's flow-control window" in caplog.text


def test_a_dropped_connection_cancels_the_call_it_had_made(transport):
    client = Client(transport)
    (call,) = client.send(request(1)).pump()
    client.send(frame(WINDOW_UPDATE, 0, 0, b"\x01")).pump()
    assert call.cancelled and transport.client_gone
    call.answer(b"late")  # nothing to send it on: no error


# (name, bytes, stream, RST_STREAM code, what to send before a next call; None: the reset
# cancelled a call the trainer had taken, so the client is gone for the trainer)
CANCEL_1 = frame(RST_STREAM, 0, 1, b"\0\0\0\x08")
STREAM_ERRORS = [
    ("PRIORITY of 4 bytes", frame(PRIORITY, 0, 1, b"\0" * 4), 1, FRAME_SIZE, b""),
    ("PRIORITY of 6 bytes", frame(PRIORITY, 0, 3, b"\0" * 6), 3, FRAME_SIZE, b""),
    ("PRIORITY on itself", frame(PRIORITY, 0, 1, b"\0\0\0\x01\x10"), 1, PROTOCOL, b""),
    ("zero WINDOW_UPDATE on a stream", headers(1) + window_update(1, 0), 1, PROTOCOL, b""),
    ("stream window past 2^31-1", headers(1) + window_update(1, 2**31 - 1), 1, FLOW, b""),
    ("DATA after the request ended", request(1) + frame(DATA, 0, 1, b"x"), 1, STREAM_CLOSED, None),
    ("HEADERS after the request ended", request(1) + headers(1, end_stream=True), 1, STREAM_CLOSED, None),
    ("DATA on a closed stream", headers(1, end_stream=True) + frame(DATA, 0, 1, b"x"), 1, STREAM_CLOSED, b""),
    ("second HEADERS block not ending the request", headers(1) + headers(1), 1, PROTOCOL, b""),
    ("a 17th call at once", b"".join(headers(s) for s in range(1, 34, 2)), 33, REFUSED, CANCEL_1),
]


@pytest.mark.parametrize(("data", "stream_id", "code", "then"), [case[1:] for case in STREAM_ERRORS],
                         ids=[case[0] for case in STREAM_ERRORS])
def test_stream_errors_answer_rst_stream_and_the_connection_keeps_serving(transport, caplog, data, stream_id, code,
                                                                          then):
    client = Client(transport)
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        client.send(data).pump()
    resets = [(sid, struct.unpack(">I", p)[0]) for kind, _, sid, p in client.frames(until_closed=False)
              if kind == RST_STREAM]
    assert resets == [(stream_id, code)]
    (record,) = [r for r in caplog.records if r.name == "trainer.protocol.http2_server" and "Reset" in r.getMessage()]
    assert record.getMessage().startswith(f"Reset stream {stream_id} from 127.0.0.1:")
    assert transport._connections  # still open
    if then is None:
        assert transport.client_gone and client.calls[0].cancelled
        return
    # the connection still serves a new call, and frames on the reset stream are ignored
    client.send(then + frame(DATA, END_STREAM, stream_id, b"late") + request(101)).pump()
    (call,) = [c for c in client.calls if c.stream_id == 101]
    assert call.payload == b"hello"
    call.answer(b"ok")
    kinds = [(kind, sid) for kind, _, sid, _ in client.frames(until_closed=False)]
    assert (HEADERS, 101) in kinds and (DATA, 101) in kinds and GOAWAY not in [k for k, _ in kinds]
    client.close()


def test_data_after_the_request_ended_cancels_the_trainers_call(transport):
    client = Client(transport)
    (call,) = client.send(request(1)).pump()
    client.send(frame(DATA, 0, 1, b"more")).pump()
    assert call.cancelled and transport.client_gone


def _answer(client: Client) -> dict:
    """The decoded headers of the server's (trailers-only) answer on stream 1."""
    fields: dict = {}
    decoder = hpack.Decoder()
    for kind, flags, sid, payload in client.frames(until_closed=False):
        if kind == HEADERS and sid == 1:
            fields.update(decoder.decode(payload, raw=True))
            fields["end_stream"] = bool(flags & END_STREAM)
    return fields


GRPC_ERRORS = [
    ("length prefix above the data", b"\x00" + struct.pack(">I", 10) + b"hello", b"13",
     "the gRPC length prefix says 10 bytes but 5 followed"),
    ("length prefix below the data", b"\x00" + struct.pack(">I", 2) + b"hello", b"13",
     "the gRPC length prefix says 2 bytes but 5 followed"),
    ("no message", b"\x00\x00", b"13", "the request carried no gRPC message"),
    ("compressed message", b"\x01" + struct.pack(">I", 5) + b"hello", b"12", "compressed messages are not supported"),
    ("message above the limit", b"\x00" + struct.pack(">I", 2000) + b"x" * 2000, b"8",
     "message larger than the server's limit of 1000 bytes"),
]


@pytest.mark.parametrize(("body", "status", "reason"), [case[1:] for case in GRPC_ERRORS],
                         ids=[case[0] for case in GRPC_ERRORS])
def test_bad_grpc_messages_get_a_grpc_status_and_never_reach_the_trainer(transport, caplog, body, status, reason):
    client = Client(transport)
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        calls = client.send(request(1, body)).pump()
    assert calls == []
    fields = _answer(client)
    assert (fields[b"grpc-status"], fields["end_stream"]) == (status, True)
    assert reason in fields[b"grpc-message"].decode().replace("%25", "%")
    assert reason in caplog.text
    client.close()


def test_late_window_update_rst_stream_and_priority_on_a_closed_stream_are_ignored(transport, caplog):
    """RFC 9113 §5.1: they may cross our END_STREAM on the wire; no reaction, the connection serves on."""
    client = Client(transport)
    (call,) = client.send(request(1)).pump()
    call.answer(b"first")
    client.frames(until_closed=False)
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        client.send(window_update(1, 100) + frame(PRIORITY, 0, 1, b"\0" * 5) + CANCEL_1 + request(3)).pump()
    assert [c.stream_id for c in client.calls] == [1, 3] and not transport.client_gone
    assert caplog.records == []
    client.calls[1].answer(b"second")
    sent = [(kind, sid) for kind, _, sid, _ in client.frames(until_closed=False)]
    assert sent == [(HEADERS, 3), (DATA, 3), (HEADERS, 3)]
    client.close()


def test_unknown_frame_types_are_ignored(transport):
    client = Client(transport)
    (call,) = client.send(frame(0x20, 0xFF, 0, b"whatever") + frame(0x21, 0, 7) + request(1)).pump()
    assert call.payload == b"hello"
    client.close()


def test_a_window_update_of_one_byte_ends_in_the_endpoints_timeout_not_a_traceback():
    """It used to make struct.error escape ``take`` (the trainer died with a traceback)."""
    port = free_port()
    endpoint = UnityEndpoint(port, timeout_wait=1.0, transport="http2")
    endpoint.start()
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
            sock.sendall(PREAMBLE + frame(WINDOW_UPDATE, 0, 0, b"\x01"))
            with pytest.raises(UnityTimeOutError, match=f"No simulator connected on 127.0.0.1:{port}"):
                endpoint.handshake(seed=0, num_areas=1)
    finally:
        endpoint.close()


@pytest.mark.timeout(20)  # the old server blocked 30 s in sendall
def test_a_client_flooding_pings_without_reading_is_disconnected(transport, caplog):
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", transport.port))
    sock.settimeout(5)
    sock.sendall(PREAMBLE)
    pings = frame(PING, 0, 0, b"\0" * 8) * 2000
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        for _ in range(3000):  # up to 100 MB of replies
            if not transport._connections and _ > 0:
                break
            try:
                sock.sendall(pings)
            except OSError:
                break
            transport.take(0.0)
    assert transport._connections == {}
    assert "does not read what the trainer sends" in caplog.text
    sock.close()


def test_an_independent_http2_client_gets_its_answer(transport):
    """python-hyper's h2 as the client: preface, SETTINGS, a call with the real header set."""
    conn = h2.connection.H2Connection(h2.config.H2Configuration(client_side=True, header_encoding=None))
    conn.initiate_connection()
    conn.send_headers(1, [(b":method", b"POST"), (b":scheme", b"http"), (b":path", EXCHANGE_PATH),
                          (b":authority", b"127.0.0.1"), (b"content-type", b"application/grpc"), (b"te", b"trailers")])
    conn.send_data(1, HELLO, end_stream=True)
    client = Client(transport, preamble=conn.data_to_send())
    (call,) = client.pump()
    assert call.payload == b"hello"
    call.answer(b"answer")
    events = conn.receive_data(bytes(client.sock.recv(1 << 16)))
    conn.receive_data(b"")
    data = b"".join(e.data for e in events if isinstance(e, h2.events.DataReceived))
    trailers = [dict(e.headers) for e in events if isinstance(e, h2.events.TrailersReceived)]
    assert data == b"\x00" + struct.pack(">I", 6) + b"answer" and trailers == [{b"grpc-status": b"0"}]
    assert any(isinstance(e, h2.events.StreamEnded) for e in events)
    client.close()
