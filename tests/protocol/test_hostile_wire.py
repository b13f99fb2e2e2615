"""Hostile clients against the trainer's HTTP/2 server (trainer/protocol/http2_server.py), beyond single-frame
RFC cases (those are in test_http2_conformance.py): a second client on a port held by a live
session, floods of idle connections, slow-loris, many half-sent requests, and a property test
throwing random and mutated frame sequences at a live transport while a well-behaved client
keeps completing its calls (docs/reliability.md, "Wire and messages")."""
from __future__ import annotations

import logging
import socket
import struct
import threading
import time
import tracemalloc

import grpc
import hpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protos import http2
from protos.communicator_objects import unity_to_external_pb2_grpc
from protos.http2 import (
    CONTINUATION, DATA, END_HEADERS, END_STREAM, GOAWAY, HEADERS, PING, SETTINGS, WINDOW_UPDATE, frame,
)
from tests.protocol.conftest import BIG, ScriptedUnity, agent_info, brain_params, free_port, m1, m2, rl_message
from trainer.protocol import http2_server
from trainer.protocol.server import EXCHANGE_PATH, UnityEndpoint
from unity_stub_env.http2_client import CallError, Http2Channel, request_headers

pytestmark = pytest.mark.timeout(60)

HELLO = b"\x00" + struct.pack(">I", 5) + b"hello"
PREAMBLE = http2.PREFACE + frame(SETTINGS, 0, 0)
HEADER_BLOCK = request_headers(EXCHANGE_PATH, b"127.0.0.1")


def request(stream_id: int, body: bytes = HELLO) -> bytes:
    return frame(HEADERS, END_HEADERS, stream_id, HEADER_BLOCK) + frame(DATA, END_STREAM, stream_id, body)


@pytest.fixture
def transport():
    t = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, max_message_bytes=1000)
    t.start()
    yield t
    t.close(grace=0.1)


def read_until_closed(sock: socket.socket) -> list:
    sock.settimeout(5)
    data = bytearray()
    try:
        while chunk := sock.recv(1 << 16):
            data += chunk
    except (ConnectionResetError, socket.timeout):
        pass
    return http2.take_frames(data)


class GoodClient:
    """The stub's own HTTP/2 client in a thread: each ``call`` is served by the test's thread."""

    def __init__(self, transport) -> None:
        self.transport = transport
        self.client = Http2Channel("127.0.0.1", transport.port, EXCHANGE_PATH)
        assert self.client.connect(5)

    def call(self, payload: bytes, answer: bytes = b"ok", rounds: int = 200) -> bytes:
        result: dict = {}

        def run():
            try:
                result["answer"] = self.client.call(payload, timeout=10)
            except CallError as error:
                result["error"] = error

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        for _ in range(rounds):
            call = self.transport.take(0.05)
            if call is not None:
                assert call.payload == payload
                call.answer(answer)
                break
        thread.join(10)
        assert "error" not in result, result.get("error")
        return result["answer"]

    def close(self) -> None:
        self.client.close()


# ------------------------------------------------------------------ a second client on the port
def test_a_second_client_cannot_inject_calls_into_a_live_session(transport, caplog):
    good = GoodClient(transport)
    assert good.call(b"m1") == b"ok"  # the session: the connection whose call the trainer took
    intruder = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
    intruder.sendall(PREAMBLE + request(1, b"\x00" + struct.pack(">I", 6) + b"inject"))
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        for _ in range(5):
            assert transport.take(0.02) is None  # nothing reaches the trainer
    frames = read_until_closed(intruder)
    fields = {}
    for kind, _, sid, payload in frames:
        if kind == HEADERS and sid == 1:
            fields.update(hpack.Decoder().decode(payload, raw=True))
    assert fields[b"grpc-status"] == b"9"  # FAILED_PRECONDITION, with the reason
    message = fields[b"grpc-message"].decode()
    assert f"port {transport.port} is held by a live training session with 127.0.0.1:" in message
    assert [struct.unpack_from(">II", p) for kind, _, _, p in frames if kind == GOAWAY] == [(1, 0)]
    (line,) = [r.getMessage() for r in caplog.records if r.name == "trainer.protocol.http2_server"]
    assert line.startswith("Closing the connection from 127.0.0.1:") and "held by a live training session" in line
    assert not transport.client_gone
    assert good.call(b"m2", b"still served") == b"still served"
    intruder.close()
    good.close()


def test_a_new_connection_takes_over_once_the_session_has_gone(transport):
    """A simulator that reconnects (its old connection closed) is served again."""
    first = GoodClient(transport)
    assert first.call(b"a") == b"ok"
    first.close()
    second = GoodClient(transport)
    assert second.call(b"b", b"again") == b"again"
    second.close()


@pytest.mark.parametrize("server_transport", ["http2", "grpcio"])
def test_an_intruder_during_the_handshake_is_refused_and_the_simulator_trains_on(server_transport, caplog):
    """Endpoint level, on both transports, with grpcio as both clients: M1 from the simulator,
    then another client's Exchange gets FAILED_PRECONDITION naming the port, and one log line;
    the session's RESET/STEP carry on."""
    port = free_port()
    endpoint = UnityEndpoint(port, timeout_wait=10, transport=server_transport)
    endpoint.start()
    info = agent_info(1, obs=[[0.5]])
    step = rl_message({"B?team=0": [info]}, [brain_params("B?team=0", 1)])
    sim = ScriptedUnity(port, [m1(), m2(), step])
    sim.start()
    try:
        endpoint.handshake(seed=0, num_areas=1)
        with grpc.insecure_channel(f"127.0.0.1:{port}", options=[("grpc.max_receive_message_length", BIG)]) as ch:
            stub = unity_to_external_pb2_grpc.UnityToExternalProtoStub(ch)
            result: dict = {}
            thread = threading.Thread(target=lambda: result.update(
                error=_exchange_error(stub, step)), daemon=True)
            thread.start()
            first = endpoint.reset()
            for _ in range(500):  # the trainer's thread keeps serving the port (here: polling)
                thread.join(0.02)
                if not thread.is_alive():
                    break
                assert not endpoint.client_gone
        assert result["error"].code() == grpc.StatusCode.FAILED_PRECONDITION
        assert f"port {port} is held by a live training session with 127.0.0.1:" in result["error"].details()
        assert list(first.steps) == ["B?team=0"] and not endpoint.client_gone
        refusals = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert len(refusals) == 1 and "held by a live training session" in refusals[0], refusals
    finally:
        endpoint.close()  # answers the simulator's pending step with status 400
        sim.finish()
    assert sim.error is None and [r.header.status for r in sim.responses] == [200, 200, 400]


def test_grpcio_fallback_serves_one_client_and_lets_a_reconnecting_one_take_over(caplog):
    """MLAGENTS_LIKE_TRANSPORT=grpcio: the first client's calls reach the trainer; a second
    client's call is refused (status 9) while the first lives; once the first drops its call
    (a crashed simulator), a new client takes over and a third one is refused."""
    from trainer.protocol.server import SERVICE, _GrpcioTransport

    transport = _GrpcioTransport("127.0.0.1", free_port(), 1000)
    transport.start()
    # one connection each (grpcio would otherwise share one between the channels of a process)
    channels = [grpc.insecure_channel(f"127.0.0.1:{transport.port}", options=[("grpc.use_local_subchannel_pool", 1)])
                for _ in range(3)]
    first, second, third = (ch.unary_unary(f"/{SERVICE}/Exchange") for ch in channels)
    try:
        pending = first.future(b"one", timeout=15)
        call = transport.take(10)
        assert call.payload == b"one"
        with pytest.raises(grpc.RpcError) as refused:
            second(b"inject", timeout=10)
        assert refused.value.code() == grpc.StatusCode.FAILED_PRECONDITION
        assert f"port {transport.port} is held by a live training session with 127.0.0.1:" in refused.value.details()
        assert transport.take(0.1) is None and not transport.client_gone  # nothing reached the trainer
        call.answer(b"ok")
        assert pending.result() == b"ok"
        pending = first.future(b"two", timeout=15)
        assert transport.take(10).payload == b"two"
        pending.cancel()  # the session's simulator goes away with its call unanswered
        assert transport.take(10) is None and transport.client_gone
        later = second.future(b"again", timeout=15)  # a reconnecting simulator takes over
        taken = None
        for _ in range(200):  # (take() no longer waits once client_gone is set)
            taken = transport.take(0.05) or (time.sleep(0.05) or None)
            if taken is not None:
                break
        assert taken.payload == b"again"
        with pytest.raises(grpc.RpcError) as refused:
            third(b"inject", timeout=10)
        assert refused.value.code() == grpc.StatusCode.FAILED_PRECONDITION
        taken.answer(b"served")
        assert later.result() == b"served"
        warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warnings) == 2 and all("held by a live training session" in w for w in warnings), warnings
    finally:
        for ch in channels:
            ch.close()
        transport.close(grace=0.1)


def _exchange_error(stub, message):
    try:
        stub.Exchange(message, wait_for_ready=True, timeout=15)
    except grpc.RpcError as error:
        return error
    return None


def test_closed_transports_hold_no_read_buffer_even_when_something_still_refers_to_them():
    """A restarted simulator's transport is closed, but the traceback of the error that ended
    the simulator can keep it alive until Python's next full collection; each one used to hold
    its 1 MiB read buffer meanwhile (the soak's trainer grew ~1 MB per simulator kill)."""
    kept = []
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for _ in range(10):
            t = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, max_message_bytes=1000)
            t.start()
            good = GoodClient(t)
            assert good.call(b"m1") == b"ok"  # a session, as a simulator's
            good.close()
            t.close(grace=0.1)
            kept.append(t)  # still referenced, as by a traceback
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert held < 2 << 20, held  # was 11.7 MB: 1 MiB each + the test clients; now 1.2 MB
    assert all(t.session is None for t in kept)


# ------------------------------------------------------------------ idle connections, slow-loris
def test_idle_connections_are_capped_and_hold_no_read_buffer_each(transport, caplog):
    good = GoodClient(transport)
    assert good.call(b"m1") == b"ok"
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    idle = []
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        for _ in range(3 * http2_server.MAX_CONNECTIONS):
            idle.append(socket.create_connection(("127.0.0.1", transport.port), timeout=5))
            idle[-1].sendall(PREAMBLE)
            transport.poll()
            transport.poll()
            assert len(transport._connections) <= http2_server.MAX_CONNECTIONS
    held = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert held < 256 * 1024, held  # (each connection used to keep a 1 MiB receive buffer)
    assert transport.session in transport._connections.values()  # the session is never evicted
    assert "connections are open (the most this server keeps)" in caplog.text
    assert good.call(b"m2", b"served") == b"served"
    for sock in idle:
        sock.close()
    good.close()


@pytest.mark.parametrize("what, setting", [("preface", "PREFACE_TIMEOUT_S"), ("idle", "IDLE_TIMEOUT_S")])
def test_slow_loris_and_idle_connections_are_closed_but_never_the_session(transport, monkeypatch, caplog, what,
                                                                            setting):
    monkeypatch.setattr(http2_server, setting, 0.3)
    good = GoodClient(transport)
    assert good.call(b"m1") == b"ok"
    slow = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
    # slow-loris: the preface a byte at a time; idle: a whole preface, then nothing
    slow.sendall(http2.PREFACE[:3] if what == "preface" else PREAMBLE)
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        for _ in range(100):
            transport.poll()
            if len(transport._connections) == 1:
                break
            if what == "preface":
                slow.sendall(b"x"[:0])  # nothing more arrives in time
            time.sleep(0.05)
    assert list(transport._connections.values()) == [transport.session]
    assert any(kind == GOAWAY for kind, *_ in read_until_closed(slow))
    assert ("no HTTP/2 preface within" if what == "preface" else "idle for") in caplog.text
    time.sleep(0.4)  # the session's own idle time never closes it
    assert good.call(b"m2", b"served") == b"served"
    slow.close()
    good.close()


# ------------------------------------------------------------------ oversized requests
def test_many_half_sent_requests_together_cannot_buffer_more_than_one_message(transport, caplog):
    sock = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
    sock.sendall(PREAMBLE)
    data = b"".join(frame(HEADERS, END_HEADERS, sid, HEADER_BLOCK) + frame(DATA, 0, sid, b"\0" * 900)
                    for sid in range(1, 32, 2))  # 16 streams, each under the 1000-byte limit
    sock.sendall(data)
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.http2_server"):
        for _ in range(5):
            transport.poll()
    (connection,) = transport._connections.values()
    assert sum(len(s.body) for s in connection.streams.values()) <= 1000 + 5
    assert "requests buffered at once larger than the server's limit of 1000 bytes" in caplog.text
    sock.close()


def test_a_2_gb_grpc_length_prefix_is_refused_and_the_connection_serves_on(transport):
    sock = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
    sock.sendall(PREAMBLE + request(1, b"\x00" + struct.pack(">I", 2**31) + b"x" * 100) + request(3))
    calls = [c for c in (transport.take(0.05) for _ in range(5)) if c is not None]
    assert [c.payload for c in calls] == [b"hello"]
    sock.settimeout(2)
    got = bytearray()
    while b"grpc-status" not in got:
        got += sock.recv(1 << 16)
    assert b"the gRPC length prefix says 2147483648 bytes but 100 followed" in got
    sock.close()


# ------------------------------------------------------------------ random and mutated frames
_STREAMS = st.sampled_from([0, 1, 1, 3, 5, 2, 2**31 - 1])
_PAYLOADS = st.one_of(
    st.binary(max_size=40),
    st.just(HEADER_BLOCK),
    st.just(HELLO),
    st.just(b"\0" * 8),  # PING-sized
    st.integers(0, 2**32 - 1).map(lambda v: struct.pack(">I", v)),  # WINDOW_UPDATE / RST_STREAM-sized
    st.lists(st.tuples(st.integers(0, 8), st.integers(0, 2**32 - 1)), max_size=3).map(
        lambda items: b"".join(struct.pack(">HI", k, v) for k, v in items)),  # SETTINGS entries
    st.just(b"\x00" + struct.pack(">I", 2**31) + b"x"),  # a 2 GB length prefix
)
_FRAMES = st.tuples(st.integers(0, 12), st.integers(0, 255), _STREAMS, _PAYLOADS).map(lambda f: frame(*f))
# requests the server should serve, to keep a connection alive between hostile frames
_VALID = st.sampled_from([request(1), frame(PING, 0, 0, b"\0" * 8), frame(SETTINGS, 0, 0),
                          frame(WINDOW_UPDATE, 0, 0, struct.pack(">I", 100)),
                          frame(HEADERS, 0, 1, HEADER_BLOCK[:5]) + frame(CONTINUATION, END_HEADERS, 1, HEADER_BLOCK[5:])])


@st.composite
def hostile_bytes(draw):
    preface = draw(st.sampled_from([PREAMBLE, PREAMBLE, PREAMBLE, http2.PREFACE, b"GET / HTTP/1.1\r\n\r\n"]))
    data = bytearray(preface + b"".join(draw(st.lists(st.one_of(_FRAMES, _VALID), max_size=12))))
    for _ in range(draw(st.integers(0, 3))):  # mutations: flip a byte, cut, or insert
        if not data:
            break
        at = draw(st.integers(0, len(data) - 1))
        how = draw(st.sampled_from(["flip", "cut", "insert"]))
        if how == "flip":
            data[at] ^= draw(st.integers(1, 255))
        elif how == "cut":
            del data[at:]
        else:
            data[at:at] = draw(st.binary(min_size=1, max_size=9))
    return bytes(data)


def _bounded(transport) -> None:
    assert len(transport._connections) <= http2_server.MAX_CONNECTIONS
    for connection in transport._connections.values():
        assert len(connection.buffer) <= http2.OUR_MAX_FRAME + 9 + http2.RECV_BYTES
        assert len(connection.out) <= http2_server.MAX_UNSENT
        assert len(connection.streams) <= http2_server.MAX_STREAMS
        assert sum(len(s.body) for s in connection.streams.values()) <= transport.max_message_bytes + 5


@pytest.fixture(scope="module")
def shared():
    """One live transport for every example, its session held by a well-behaved client."""
    t = http2_server.Http2Transport("127.0.0.1", free_port(), EXCHANGE_PATH, max_message_bytes=1000)
    t.start()
    good = GoodClient(t)
    assert good.call(b"first") == b"ok"
    yield t, good
    good.close()
    t.close(grace=0.1)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(attacks=st.lists(hostile_bytes(), min_size=1, max_size=3), keep_open=st.booleans())
def test_random_and_mutated_frames_never_escape_and_the_session_keeps_being_served(shared, attacks, keep_open):
    """Hostile connections beside a live session: nothing escapes ``take`` (the server's own
    Http2Error is handled inside), buffers stay within their bounds, the intruders' calls never
    reach the trainer, and the session's next call is answered."""
    transport, good = shared
    socks = []
    for data in attacks:
        sock = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        try:
            sock.sendall(data)
        except OSError:
            pass
        socks.append(sock)
        for _ in range(3):
            assert transport.take(0.0) is None  # nothing but the session's calls is handed out
            _bounded(transport)
    if not keep_open:
        for sock in socks:
            sock.close()
    assert not transport.client_gone
    assert good.call(b"next", b"served") == b"served"
    _bounded(transport)
    for sock in socks:
        sock.close()


@settings(max_examples=150, deadline=None)
@given(data=hostile_bytes())
def test_random_and_mutated_frames_as_the_first_client_end_in_a_call_or_a_closed_connection(data):
    """The hostile client may become the session (nobody else is connected): it gets its calls
    or its connection closed, nothing escapes; once it leaves, a simulator connecting next is
    served unless the hostile one had left a call unanswered (then the trainer is told:
    ``client_gone``, and a real run restarts that simulator)."""
    transport = http2_server.Http2Transport("127.0.0.1", 0, EXCHANGE_PATH, max_message_bytes=1000)
    transport.start()
    try:
        sock = socket.create_connection(("127.0.0.1", transport.port), timeout=5)
        try:
            sock.sendall(data)
        except OSError:
            pass
        for _ in range(4):
            call = transport.take(0.0)
            if call is not None:
                call.answer(b"answered")
            _bounded(transport)
        sock.close()
        for _ in range(3):
            transport.poll()
        if not transport.client_gone:
            good = GoodClient(transport)
            assert good.call(b"after", b"served") == b"served"
            good.close()
    finally:
        transport.close(grace=0.05)


@pytest.mark.timeout(20)  # refusing it used to wait up to 30 s in sendall for the intruder to read
def test_refusing_an_intruder_that_does_not_read_never_blocks_the_trainer(transport, monkeypatch):
    monkeypatch.setattr(http2_server, "MAX_UNSENT", 64 << 20)  # keep it connected while its buffers fill
    good = GoodClient(transport)
    assert good.call(b"m1") == b"ok"
    intruder = socket.socket()
    intruder.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    intruder.connect(("127.0.0.1", transport.port))
    intruder.sendall(PREAMBLE)
    intruder.settimeout(5)
    pings = frame(PING, 0, 0, b"\0" * 8) * 4000
    for _ in range(2000):  # until the server holds acknowledgements the socket would not take
        intruder.sendall(pings)
        transport.poll()
        held = [c for c in transport._connections.values() if c is not transport.session]
        if held and held[0].out:
            break
    assert held and held[0].out
    intruder.sendall(request(1))
    for _ in range(5):
        assert transport.take(0.02) is None
    assert list(transport._connections.values()) == [transport.session]
    assert good.call(b"m2", b"served") == b"served"
    intruder.close()
    good.close()
