"""The gRPC server end of ONE simulator connection (docs/protocol.md, "Transport").

The simulator (Unity or unity-stub-env) is the gRPC client: every message it sends is the request
of an ``Exchange`` call, and the trainer's next message is that call's response. Two transports
carry the calls, both handing the trainer raw request bytes that ``codec.decode_message`` decodes
once, on its thread:

* ``http2`` (default): ``protos.http2``, a single-threaded HTTP/2 server; the
  trainer's thread reads requests off the socket and writes answers itself.
* ``grpcio`` (``MLAGENTS_LIKE_TRANSPORT=grpcio``): grpcio's server; a servicer thread parks each
  call in a slot until the trainer answers it. Kept as a fallback and as the reference the
  tests run against too.

    endpoint = UnityEndpoint(port=5005, is_alive=process_is_running)
    endpoint.start()
    init = endpoint.handshake(seed=0, num_areas=1)   # M1 answered, M2 left pending
    result = endpoint.reset(side_channel)            # answers M2 with RESET
    result = endpoint.step(actions, side_channel)    # answers with STEP, waits for the next
    endpoint.close()                                 # answers whatever is pending with 400
"""
from __future__ import annotations

import collections
import logging
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Callable, Mapping

from protos.communicator_objects import unity_message_pb2
from protos.errors import ProtocolError
from protos.http2 import GRPC_INTERNAL
from protos.types import ActionTuple, BehaviorSpec, StepResult
from protos.versions import COMMUNICATION_VERSION, PACKAGE_VERSION, all_true_capabilities
from trainer.config.env_vars import TRANSPORTS
from trainer.errors import (
    PortInUseError,
    SimulatorExitedError,
    UnityCommunicatorStoppedError,
    UnityTimeOutError,
)
from trainer.protocol import codec
from trainer.protocol.http2_server import Http2Transport
from trainer.protocol.listen import port_in_use_error
from trainer.stop import STOP

if TYPE_CHECKING:  # grpcio is imported by its transport only (MLAGENTS_LIKE_TRANSPORT=grpcio)
    import grpc

logger = logging.getLogger(__name__)

MAX_MESSAGE_BYTES = 256 * 1024 * 1024  # camera observations easily pass gRPC's 4 MiB default
STATUS_OK = 200
STATUS_CLOSING = 400


def _status_message(status: int) -> unity_message_pb2.UnityMessageProto:
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = status
    return message


# longest wait between looks at a stop signal while a simulator is silent (loading, paused)
_STOP_POLL_S = 0.25
_DELIVERY_WAIT_S = 0.05  # upper bound; normally the RPC completes in well under a millisecond
SERVICE = "communicator_objects.UnityToExternalProto"
EXCHANGE_PATH = f"/{SERVICE}/Exchange".encode()


class _PendingCall:
    """One Exchange call the simulator is blocked in (grpcio transport), and its answer."""

    __slots__ = ("payload", "response", "error", "_answered", "finished")

    def __init__(self, payload: bytes) -> None:
        self.payload = payload
        self.response: bytes | None = None
        self.error: tuple[grpc.StatusCode, str] | None = None
        self._answered = threading.Event()
        self.finished = threading.Event()  # the RPC is over: the answer has left this process

    def answer(self, response: bytes) -> None:
        if self.response is None and self.error is None:
            self.response = response
        self._answered.set()
        # Let gRPC's threads put the answer on the wire before the trainer goes back to work:
        # otherwise they wait for the GIL while we process trajectories, and the simulator
        # idles for that long. The wait ends as soon as the RPC completes (about 1 ms).
        self.finished.wait(_DELIVERY_WAIT_S)

    def fail(self, status: int, message: str) -> None:
        if self.response is None and self.error is None:
            import grpc

            code = next((c for c in grpc.StatusCode if c.value[0] == status), grpc.StatusCode.INTERNAL)
            self.error = (code, message)
        self._answered.set()

    def abandon(self) -> None:
        self._answered.set()

    def wait(self, timeout: float) -> bool:
        return self._answered.wait(timeout)


def _peer_address(peer: str) -> str:
    """grpcio's peer string ("ipv4:127.0.0.1:5000", "ipv6:[::1]:5000") as host:port."""
    return peer.split(":", 1)[1] if peer.startswith(("ipv4:", "ipv6:")) else peer


class _GrpcioTransport:
    """grpcio's server with a rendezvous: each incoming call is parked in a slot until the
    trainer's thread answers it (or the transport closes, or the client goes away).

    Not the default: its threads make an exchange cost about 0.5 ms where ``http2`` takes
    0.06 ms (bench/transport.py, round trip with a 150-byte request). Kept for two reasons: it
    is the independent server implementation the endpoint tests also run against (the same
    test must pass on both), and a fallback (MLAGENTS_LIKE_TRANSPORT=grpcio) should a Unity
    build's gRPC client meet something our server does not handle."""

    def __init__(self, bind: str, port: int, max_message_bytes: int) -> None:
        self.bind = bind
        self.port = port
        self.max_message_bytes = max_message_bytes
        self._cond = threading.Condition()
        self._incoming: collections.deque[_PendingCall] = collections.deque()
        self._server: grpc.Server | None = None
        self.closed = False
        self.client_gone = False
        # the peer (grpcio's "ipv4:host:port", one per client connection) whose calls the trainer
        # takes; another peer's calls are refused while it has not gone, as protos.http2 does, so
        # a second client on the port cannot inject steps into the session (docs/protocol.md, "Malformed HTTP/2")
        self.session: str | None = None
        self._session_gone = False  # its client dropped a call unanswered: the next peer takes over

    def start(self) -> None:
        import grpc

        server = grpc.server(
            ThreadPoolExecutor(max_workers=4, thread_name_prefix=f"unity-endpoint-{self.port}"),
            options=[
                ("grpc.max_receive_message_length", self.max_message_bytes),
                ("grpc.max_send_message_length", self.max_message_bytes),
                ("grpc.so_reuseport", 0),  # a second server on this port must fail
            ],
        )
        handler = grpc.unary_unary_rpc_method_handler(self._exchange)  # raw bytes both ways
        server.add_generic_rpc_handlers([grpc.method_handlers_generic_handler(SERVICE, {"Exchange": handler})])
        host = f"[{self.bind}]" if ":" in self.bind else self.bind
        try:
            bound_port = server.add_insecure_port(f"{host}:{self.port}")
        except RuntimeError:
            bound_port = 0
        if bound_port == 0:
            server.stop(None)
            raise OSError(f"cannot bind {host}:{self.port}")
        self.port = bound_port
        server.start()
        self._server = server

    # ---- gRPC side
    def _exchange(self, request: bytes, context):
        call = _PendingCall(request)
        with self._cond:
            if self.closed:
                return _status_message(STATUS_CLOSING).SerializeToString()
            refusal = self._refusal(context.peer())
            if refusal is None:
                self._incoming.append(call)
                self._cond.notify_all()
        if refusal is not None:  # never reaches the trainer
            import grpc

            logger.warning("Refused a call from %s: %s", _peer_address(context.peer()), refusal)
            context.abort(grpc.StatusCode.FAILED_PRECONDITION, refusal)  # raises: the call ends here
        if not context.add_callback(lambda: self._on_rpc_done(call)):
            self._on_rpc_done(call)  # the RPC had already ended
        while not call.wait(1.0):
            if not context.is_active():
                self._on_rpc_done(call)
        if call.error is not None:
            context.abort(*call.error)
        if call.response is not None:
            return call.response
        return _status_message(STATUS_CLOSING).SerializeToString()

    def _refusal(self, peer: str) -> str | None:
        """Why ``peer`` may not make calls (the session is another live client's), or None; the
        first peer to call becomes the session. Called with ``_cond`` held."""
        if self.session is None or self._session_gone:
            self.session, self._session_gone = peer, False
            return None
        if peer == self.session:
            return None
        return (f"port {self.port} is held by a live training session with {_peer_address(self.session)}; a "
                "second simulator cannot join it. Give each simulator its own port (--num-envs, --base-port).")

    def _on_rpc_done(self, call: _PendingCall) -> None:
        """The RPC ended; if it was never answered the client went away (crash, cancel)."""
        call.finished.set()
        if call.response is None and call.error is None:
            call.abandon()
            with self._cond:
                self.client_gone = self._session_gone = True  # only the session's calls are queued
                self._cond.notify_all()

    # ---- trainer side
    def poll(self) -> None:
        """Nothing to do: grpcio's threads notice a cancelled call on their own."""

    def take(self, timeout: float) -> _PendingCall | None:
        """The next incoming call, or None after ``timeout`` s or once the client is gone."""
        with self._cond:
            self._cond.wait_for(
                lambda: self._incoming or self.client_gone or self.closed, timeout=timeout
            )
            return self._incoming.popleft() if self._incoming else None

    def close(self, grace: float = 2.0) -> None:
        """Refuse new calls, answer queued ones with 400, stop serving."""
        with self._cond:
            self.closed = True
            queued = list(self._incoming)
            self._incoming.clear()
            self._cond.notify_all()
        closing = _status_message(STATUS_CLOSING).SerializeToString()
        for call in queued:
            call.response = closing
            call._answered.set()
        if self._server is not None:
            # the grace period lets the 400 answers reach the simulator before sockets close
            self._server.stop(grace=grace).wait(grace + 3.0)
            self._server = None


class UnityEndpoint:
    """The trainer side of one simulator connection on ``bind:port``."""

    def __init__(
        self,
        port: int,
        bind: str = "127.0.0.1",
        timeout_wait: float = 60.0,
        is_alive: Callable[[], bool] | None = None,
        describe: str | Callable[[], str] = "",
        transport: str = "http2",
        spin_wait: float = 0.0,
        editor: bool = False,
        listener: socket.socket | None = None,
    ) -> None:
        """``describe``: names the simulator in errors (a callable is asked when the error
        happens, so it can say how the process ended). ``spin_wait`` (s): poll for the simulator's
        next call up to this long past when it is due instead of sleeping through it
        (protos/pacing.py; HTTP/2 transport only). ``transport``: one of TRANSPORTS (the run's
        MLAGENTS_LIKE_TRANSPORT, trainer.config.env_vars). ``editor``: the Unity Editor connects
        (no --env), which changes the advice when the port is taken. ``listener``: a socket
        already listening on ``bind:port`` (trainer.protocol.listen; the pool binds it before it
        launches the simulator), which ``start`` serves on and this endpoint then owns (HTTP/2
        transport only)."""
        self.port = port
        self.editor = editor
        self.bind = bind
        self.timeout_wait = float(timeout_wait)
        self.is_alive = is_alive
        self.describe = describe
        self.spin_wait = float(spin_wait)
        self.behavior_specs: dict[str, BehaviorSpec] = {}
        self.init_output = None  # UnityRLInitializationOutputProto from M1
        self.transport_name = transport
        if self.transport_name not in TRANSPORTS:
            raise ValueError(f"unknown transport {self.transport_name!r}")
        if listener is not None and self.transport_name != "http2":
            raise ValueError("only the http2 transport serves on a given listening socket")
        self._listener = listener
        self._transport = None
        self._pending = None  # the simulator call we owe an answer
        self._deciding: dict[str, int] = {}  # agents per behavior that wait for an action
        self._dropped: dict = {}  # {behavior: codec.Dropped}: deciding agents left out for NaN/Inf
        self._messages_received = 0
        self._closed = False

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Check the port is free, then serve UnityToExternalProto on ``bind:port`` (on the
        given listening socket, if any: it is bound already)."""
        if self.transport_name == "grpcio":
            self._check_port_free()  # grpcio's own bind would not fail on every taken port
            transport = _GrpcioTransport(self.bind, self.port, MAX_MESSAGE_BYTES)
        else:
            transport = Http2Transport(self.bind, self.port, EXCHANGE_PATH, MAX_MESSAGE_BYTES, self.spin_wait,
                                       listener=self._listener)
            self._listener = None  # the transport owns it now (and closes it)
        try:
            transport.start()
        except OSError:
            raise self._port_in_use_error() from None
        self.port = transport.port
        self._transport = transport

    def _check_port_free(self) -> None:
        family = socket.AF_INET6 if ":" in self.bind else socket.AF_INET
        probe = socket.socket(family, socket.SOCK_STREAM)
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((self.bind, self.port))
        except OSError:
            raise self._port_in_use_error() from None
        finally:
            probe.close()

    def _port_in_use_error(self) -> PortInUseError:
        describe = self.describe() if callable(self.describe) else self.describe
        return port_in_use_error(self.bind, self.port, self.editor, describe)

    def close(self) -> None:
        """Answer any pending simulator call with status 400, then stop serving. Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._listener is not None:  # never started
            self._listener.close()
            self._listener = None
        if self._pending is not None:
            self._pending.answer(_status_message(STATUS_CLOSING).SerializeToString())
            self._pending = None
        if self._transport is not None:
            # answers queued calls with 400; the grace period lets answers reach the simulator
            self._transport.close(grace=2.0)

    @property
    def client_gone(self) -> bool:
        """The simulator dropped a call before it was answered (crash, cancel)."""
        if self._transport is None:
            return False
        self._transport.poll()
        return self._transport.client_gone

    def __enter__(self) -> "UnityEndpoint":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ handshake
    def handshake(self, seed: int, num_areas: int):
        """Answer M1 with our initialization input, then wait for M2 and leave it pending.

        Returns M1's UnityRLInitializationOutputProto. Raises UnityVersionError for an
        incompatible communication API (the M1 call stays pending; ``close()`` answers it).
        """
        first = self._wait_for_call().message
        if not first.unity_output.HasField("rl_initialization_output"):
            raise ProtocolError(
                f"The first message from the simulator{self._for()} carried no initialization "
                "output; is it an ML-Agents environment speaking communication API 1.x?"
            )
        init = first.unity_output.rl_initialization_output
        codec.check_communication_version(init.communication_version)
        if not init.capabilities.baseRLCapabilities:
            logger.warning(
                "The Unity environment%s (package %s) does not report the base RL capabilities; "
                "upgrade its ML-Agents package to one compatible with Python package %s.",
                self._for(), init.package_version, PACKAGE_VERSION,
            )
        logger.debug(
            "Connected to Unity environment with package version %s and communication version %s",
            init.package_version, init.communication_version,
        )
        response = _status_message(STATUS_OK)
        init_input = response.unity_input.rl_initialization_input
        init_input.seed = seed
        init_input.communication_version = COMMUNICATION_VERSION
        init_input.package_version = PACKAGE_VERSION
        init_input.capabilities.CopyFrom(all_true_capabilities())
        init_input.num_areas = num_areas
        self._answer(response)
        self._wait_for_call()  # M2: no output; answered by the first reset
        self.init_output = init
        return init

    # ------------------------------------------------------------------ exchanges
    def send_reset(self, side_channel: bytes = b"") -> None:
        """Answer the pending simulator call with RESET (no actions). Does not block."""
        self._answer_bytes(codec.encode_answer({}, side_channel, codec.RESET))

    def send_step(self, actions: Mapping[str, ActionTuple], side_channel: bytes = b"") -> None:
        """Answer the pending call with STEP. Does not block.

        ``actions[behavior]`` needs one row per agent of the last DecisionSteps, in order; a
        behavior with deciding agents but no entry gets all-zero actions (as the reference).
        """
        full_actions = dict(actions)
        for name, n_deciding in self._deciding.items():
            if name not in full_actions and n_deciding > 0:
                full_actions[name] = self.behavior_specs[name].action_spec.empty_action(n_deciding)
        for name, action in full_actions.items():
            rows = {len(p) for p in (action.continuous, action.discrete)
                    if p is not None and getattr(p, "size", 1) > 0}
            if rows and rows != {self._deciding.get(name, 0)}:
                raise ValueError(
                    f"{name}: {rows.pop()} action rows for {self._deciding.get(name, 0)} deciding agents"
                )
        for name, dropped in self._dropped.items():
            # the simulator matches actions to its agents by position: the agents left out for
            # NaN/Inf get zero actions in their places (docs/protocol.md, "Simulator → trainer")
            owed = self.behavior_specs[name].action_spec.empty_action(dropped.deciding)
            if len(dropped.kept):
                continuous, discrete = codec.as_action_matrices(full_actions[name])
                owed.continuous[dropped.kept] = continuous
                owed.discrete[dropped.kept] = discrete
            full_actions[name] = owed
        self._answer_bytes(codec.encode_answer(full_actions, side_channel))

    def receive(self) -> StepResult:
        """Wait for the simulator's next message and decode it (leaves that call pending)."""
        result = self._wait_for_call().result
        self.behavior_specs.update(result.specs)
        self._deciding = {name: len(steps[0]) for name, steps in result.steps.items()}
        self._dropped = {name: d for name, d in result.dropped.items() if d.deciding}
        return result

    def reset(self, side_channel: bytes = b"") -> StepResult:
        self.send_reset(side_channel)
        return self.receive()

    def step(self, actions: Mapping[str, ActionTuple], side_channel: bytes = b"") -> StepResult:
        self.send_step(actions, side_channel)
        return self.receive()

    # ------------------------------------------------------------------ internals
    def _answer(self, response: unity_message_pb2.UnityMessageProto) -> None:
        self._answer_bytes(response.SerializeToString())

    def _answer_bytes(self, payload: bytes) -> None:
        if self._pending is None:
            raise RuntimeError("no simulator call is pending: receive() before sending again")
        call, self._pending = self._pending, None
        call.answer(payload)

    def _wait_for_call(self) -> codec.DecodedMessage:
        """Block until the simulator's next call arrives; it becomes the pending call, its
        message is decoded (once, here, by the codec) and returned."""
        if self._transport is None or self._closed:
            raise RuntimeError("UnityEndpoint is not started or already closed")
        if self._pending is not None:
            raise RuntimeError("the previous simulator call has not been answered yet")
        started = time.monotonic()
        poll_interval = min(max(self.timeout_wait / 10.0, 0.001), _STOP_POLL_S)
        wait = 0.0  # first look without waiting, so a dead simulator is reported at once
        while True:
            call = self._transport.take(wait)
            if call is not None:
                break
            STOP.check()  # a stop signal while waiting: no call is half-taken here
            if self._transport.closed:
                raise UnityCommunicatorStoppedError(f"The endpoint on port {self.port} was closed.")
            self._raise_if_simulator_died()
            if self._transport.client_gone:
                raise UnityCommunicatorStoppedError(
                    f"The simulator{self._for()} on port {self.port} dropped its connection."
                )
            remaining = started + self.timeout_wait - time.monotonic()
            if remaining <= 0:
                raise self._timeout_error(time.monotonic() - started)
            wait = min(poll_interval, remaining)
        self._pending = call  # pending before decoding: close() answers it if the data is bad
        self._messages_received += 1
        try:
            decoded = codec.decode_message(call.payload, self.behavior_specs)
        except codec.NotAMessageError as error:
            self._pending = None
            call.fail(GRPC_INTERNAL, "the message is not a valid UnityMessageProto")
            raise ProtocolError(
                f"The simulator{self._for()} on port {self.port} sent a message that is "
                f"{error}; is it an ML-Agents environment speaking communication API 1.x? "
                "Rebuild it with the ML-Agents package of Release 22."
            ) from None
        except ProtocolError as error:  # the codec names the behavior and the fault; say which simulator
            raise ProtocolError(f"The simulator{self._for()} on port {self.port}: {error}") from None
        status = decoded.message.header.status
        if status != STATUS_OK:
            self._answer(_status_message(STATUS_CLOSING))
            raise UnityCommunicatorStoppedError(
                f"The simulator{self._for()} on port {self.port} closed the connection "
                f"(status {status})."
            )
        return decoded

    def _raise_if_simulator_died(self) -> None:
        if self.is_alive is not None and not self.is_alive():
            raise SimulatorExitedError(
                f"The simulator{self._for()} on port {self.port} exited while the trainer was "
                "waiting for it. Check its log (Player-<worker>.log in the run_logs folder)."
            )

    def _timeout_error(self, waited: float) -> UnityTimeOutError:
        what = "connected" if self._messages_received == 0 else "answered"
        return UnityTimeOutError(
            f"No simulator{self._for()} {what} on {self.bind}:{self.port} within {waited:.1f} s. "
            "Likely causes: the build was not made with ML-Agents or its Academy is not in the "
            "scene; the Unity Editor is not in Play mode; a firewall blocks the port; or "
            "--timeout-wait is too low for this environment to load."
        )

    def _for(self) -> str:
        describe = self.describe() if callable(self.describe) else self.describe
        return f" ({describe})" if describe else ""
