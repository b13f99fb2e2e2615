"""Our HTTP/2 gRPC transport: wire encodings against RFC 7541's worked examples, and its
behaviour with real grpcio clients and with clients that are not gRPC at all."""
from __future__ import annotations

import socket
import struct
import threading

import grpc
import pytest

from protos import http2
from protos.communicator_objects import unity_message_pb2
from protos.errors import ProtocolError
from tests.protocol.conftest import free_port, m1, m2
from trainer.protocol import http2_server
from trainer.protocol.server import EXCHANGE_PATH, UnityEndpoint

pytestmark = pytest.mark.timeout(60)


# --------------------------------------------------------------------------- pure encodings
@pytest.mark.parametrize(
    ("value", "prefix", "first", "expected"),
    [
        (10, 5, 0, b"\x0a"),  # RFC 7541 C.1.1
        (1337, 5, 0, b"\x1f\x9a\x0a"),  # C.1.2
        (42, 8, 0, b"\x2a"),  # C.1.3
        (31, 4, 0, b"\x0f\x10"),  # content-type's static index as a 4-bit-prefix name index
        (0, 5, 0x20, b"\x20"),  # dynamic table size update to 0
    ],
)
def test_hpack_integers_match_the_rfc_examples(value, prefix, first, expected):
    assert http2.hpack_int(value, prefix, first) == expected


def test_literal_header_and_frame_layout():
    # RFC 7541 C.2.2 shows "literal without indexing, indexed name"; this is the new-name form:
    # 0x00, name length, name, value length, value
    assert http2.hpack_literal(b"grpc-status", b"0") == b"\x00\x0bgrpc-status\x010"
    # 9-byte header: 24-bit length, type, flags, 31-bit stream id
    assert http2.frame(http2.DATA, http2.END_STREAM, 3, b"abc") == b"\x00\x00\x03\x00\x01\x00\x00\x00\x03abc"
    assert http2_server.RESPONSE_HEADERS == b"\x88\x0f\x10\x10application/grpc"


def test_grpc_message_is_percent_encoded():
    block = http2_server.trailers(12, "unknown method /x.Y/Z; 100%")
    assert block.endswith(b"unknown method /x.Y/Z; 100%25")


def test_our_header_blocks_decode_with_an_independent_hpack_decoder():
    import hpack

    decoded = hpack.Decoder().decode(http2_server.TABLE_SIZE_ZERO + http2_server.RESPONSE_HEADERS + http2_server.trailers(13, "bad"), raw=True)
    assert decoded == [(b":status", b"200"), (b"content-type", b"application/grpc"),
                       (b"grpc-status", b"13"), (b"grpc-message", b"bad")]


# --------------------------------------------------------------------------- with real clients
@pytest.fixture
def transport():
    t = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, max_message_bytes=1 << 20)
    t.start()
    yield t
    t.close(grace=0.5)


def _serve_one(transport, reply: bytes | None = b"pong", box: dict | None = None, wait: float = 10.0):
    """Answer the next call with ``reply`` in a thread (the trainer's role)."""
    def run():
        call = transport.take(wait)
        if box is not None:
            box["call"] = call
        if call is not None and reply is not None:
            call.answer(reply)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_a_grpcio_client_gets_the_answer_bytes(transport):
    box: dict = {}
    thread = _serve_one(transport, b"\x01\x02answer", box)
    with grpc.insecure_channel(f"127.0.0.1:{transport.port}") as channel:
        call = channel.unary_unary(EXCHANGE_PATH.decode())
        assert call(b"question", timeout=10) == b"\x01\x02answer"
    thread.join(10)
    assert box["call"].payload == b"question"


def test_unknown_method_is_unimplemented_not_a_hang(transport):
    box: dict = {}
    reader = _serve_one(transport, None, box, wait=2.0)  # the trainer's thread, reading while it waits
    with grpc.insecure_channel(f"127.0.0.1:{transport.port}") as channel:
        with pytest.raises(grpc.RpcError) as error:
            channel.unary_unary("/communicator_objects.UnityToExternalProto/Other")(b"x", timeout=10)
        assert error.value.code() == grpc.StatusCode.UNIMPLEMENTED
        assert "only serves /communicator_objects.UnityToExternalProto/Exchange" in error.value.details()
    reader.join(15)
    assert box["call"] is None  # nothing reached the trainer


def test_message_over_the_limit_is_resource_exhausted(transport):
    _serve_one(transport, None, wait=2.0)
    with grpc.insecure_channel(f"127.0.0.1:{transport.port}") as channel:
        with pytest.raises(grpc.RpcError) as error:
            channel.unary_unary(EXCHANGE_PATH.decode())(b"x" * (2 << 20), timeout=10)
        assert error.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert str(1 << 20) in error.value.details()


def test_answers_larger_than_the_clients_flow_control_window_arrive_whole(transport):
    """grpcio clients start with a 64 KiB stream window: a 3 MB answer needs WINDOW_UPDATEs."""
    reply = bytes(range(256)) * (3 * 4096)
    thread = _serve_one(transport, reply)
    with grpc.insecure_channel(f"127.0.0.1:{transport.port}",
                               options=[("grpc.max_receive_message_length", -1),
                                        ("grpc.http2.bdp_probe", 0)]) as channel:
        assert channel.unary_unary(EXCHANGE_PATH.decode())(b"q", timeout=20) == reply
    thread.join(10)


def test_a_client_that_is_not_http2_is_disconnected_with_a_reason(transport, caplog):
    with socket.create_connection(("127.0.0.1", transport.port), timeout=5) as sock:
        sock.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        assert transport.take(0.3) is None
        data = sock.recv(65536)
        received = data
        while data:
            data = sock.recv(65536)
            received += data
    # our SETTINGS came first, then a GOAWAY (type 7) with PROTOCOL_ERROR, then the close
    goaway = received.find(b"\x07\x00\x00\x00\x00\x00")
    assert goaway > 0 and struct.unpack(">I", received[goaway + 10 : goaway + 14])[0] == http2.PROTOCOL_ERROR
    assert b"HTTP/2 preface" in received
    assert "did not start with the HTTP/2 preface" in caplog.text


def test_pings_are_acknowledged_and_settings_acked():
    """Raw HTTP/2 bytes: preface, SETTINGS, PING → SETTINGS ACK and PING ACK with the same data."""
    transport = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, 1 << 20)
    transport.start()
    try:
        with socket.create_connection(("127.0.0.1", transport.port), timeout=5) as sock:
            sock.sendall(http2.PREFACE + http2.frame(http2.SETTINGS, 0, 0)
                         + http2.frame(http2.PING, 0, 0, b"12345678"))
            transport.take(0.3)
            received = sock.recv(65536)
        assert http2.frame(http2.SETTINGS, http2.ACK, 0) in received
        assert http2.frame(http2.PING, http2.ACK, 0, b"12345678") in received
        # our own SETTINGS: no push, 16 calls at once, a 2^31-1 stream window, 1 MiB frames,
        # 64 KiB of headers; then the connection window
        assert received.startswith(http2.frame(http2.SETTINGS, 0, 0, struct.pack(
            ">HIHIHIHIHI", 2, 0, 3, 16, 4, 2**31 - 1, 5, 2**20, 6, 2**16)))
    finally:
        transport.close(grace=0.2)


def test_close_on_another_thread_ends_a_take_waiting_there():
    """close() while take() waits on another thread (as a fixture's teardown does beside a
    serving thread): the waiting take returns None at once instead of after its 60 s, and its
    read round is not pulled from under it (before: BufferError from the receive buffer's
    release, EBADF from the closed selector, or a select left waiting on a closed epoll)."""
    transport = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, 1 << 20)
    transport.start()
    outcome: dict = {}
    waiting = threading.Event()

    def serve():
        waiting.set()
        try:
            outcome["call"] = transport.take(60.0)
        except BaseException as error:  # noqa: BLE001 - the test reports any
            outcome["error"] = error

    with socket.create_connection(("127.0.0.1", transport.port), timeout=5) as sock:
        sock.sendall(http2.PREFACE + http2.frame(http2.SETTINGS, 0, 0))
        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        waiting.wait(5)
        for _ in range(20):  # PINGs: the waiting take has reads to do while close() comes
            sock.sendall(http2.frame(http2.PING, 0, 0, b"12345678"))
        transport.close(grace=0.2)
        thread.join(30)
    assert not thread.is_alive(), "take() kept waiting after close()"
    assert outcome == {"call": None}


@pytest.mark.parametrize("server_transport", ["http2", "grpcio"])
def test_garbled_message_is_a_protocol_error_and_the_client_is_told(server_transport):
    port = free_port()
    endpoint = UnityEndpoint(port, timeout_wait=10.0, transport=server_transport)
    endpoint.start()
    outcome: dict = {}

    def client():
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
            try:
                channel.unary_unary(EXCHANGE_PATH.decode())(b"\xff\xff\xff garbage", timeout=10)
            except grpc.RpcError as error:
                outcome["code"] = error.code()

    thread = threading.Thread(target=client, daemon=True)
    thread.start()
    try:
        with pytest.raises(ProtocolError, match=rf"port {port}.*not a valid UnityMessageProto"):
            endpoint.handshake(0, 1)
        thread.join(10)
        assert outcome["code"] == grpc.StatusCode.INTERNAL
    finally:
        endpoint.close()


def test_handshake_over_http2_with_a_grpc_stub_client():
    """M1 → init input; M2 stays pending until close() answers it with status 400."""
    port = free_port()
    endpoint = UnityEndpoint(port, timeout_wait=10.0, transport="http2")
    endpoint.start()
    answers: list = []

    def client():
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
            exchange = channel.unary_unary(EXCHANGE_PATH.decode(),
                                           request_serializer=unity_message_pb2.UnityMessageProto.SerializeToString,
                                           response_deserializer=unity_message_pb2.UnityMessageProto.FromString)
            answers.append(exchange(m1(), timeout=10))
            answers.append(exchange(m2(), timeout=10))

    thread = threading.Thread(target=client, daemon=True)
    thread.start()
    endpoint.handshake(seed=7, num_areas=2)
    endpoint.close()
    thread.join(10)
    assert answers[0].unity_input.rl_initialization_input.seed == 7
    assert answers[0].unity_input.rl_initialization_input.num_areas == 2
    assert answers[1].header.status == 400


def test_caching_decoder_reuses_only_blocks_that_leave_the_table_unchanged():
    import hpack

    encoder, decoder = hpack.Encoder(), http2.CachingDecoder()
    first = encoder.encode([(b"grpc-status", b"0")])  # literal WITH incremental indexing
    again = encoder.encode([(b"grpc-status", b"0")])  # now one indexed byte (dynamic entry 62)
    assert first != again and len(again) == 1
    assert decoder.decode(first) == [(b"grpc-status", b"0")]
    assert first not in decoder._cache  # it changed the table: never reused
    assert decoder.decode(again) == [(b"grpc-status", b"0")]
    assert decoder._cache[again] == [(b"grpc-status", b"0")]  # indexed: cached
    changed = encoder.encode([(b"x-other", b"1")])  # inserts a new entry
    decoder.decode(changed)
    assert decoder._cache == {}  # the table changed: every cached result is void
    # index 62 is now the newest entry: a stale cache would still answer grpc-status
    assert decoder.decode(again) == [(b"x-other", b"1")]


def test_endless_header_blocks_close_the_connection_instead_of_growing():
    transport = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, 1 << 20)
    transport.start()
    try:
        with socket.create_connection(("127.0.0.1", transport.port), timeout=5) as sock:
            chunk = http2.frame(http2.CONTINUATION, 0, 1, b"\x00" * 65536)
            sock.sendall(http2.PREFACE + http2.frame(http2.SETTINGS, 0, 0)
                         + http2.frame(http2.HEADERS, 0, 1, b"\x00" * 16384))
            received = b""
            for _ in range(20):  # 20 x 64 KiB > the 64 KiB limit
                try:
                    sock.sendall(chunk)
                except OSError:
                    break
                transport.take(0.0)
            transport.take(0.2)
            try:
                while True:
                    data = sock.recv(65536)
                    if not data:
                        break
                    received += data
            except OSError:
                pass
        assert b"header block larger than" in received  # in the GOAWAY's debug data
        assert transport._connections == {}
    finally:
        transport.close(grace=0.2)
