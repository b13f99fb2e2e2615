"""The gRPC side of a Unity player: a CLIENT that calls ``Exchange`` like ``RpcCommunicator.cs``.

Handshake (docs/protocol.md, "Handshake, message by message"): M1 carries the academy's init output (no brain parameters, no rl_output);
the answer holds the trainer's seed, num_areas and versions. M2 is a bare status-200 header;
its answer is the first RESET. Every later message carries ``rl_output`` (agent infos keyed by
``Behavior?team=0`` plus side-channel bytes) and, the first time a behavior is sent with at
least one agent info, its ``brain_parameters``. A non-200 answer or the QUIT command ends the
session; ``request_stop`` (SIGTERM/SIGINT) makes the next wait send one status-400 message.
"""
from __future__ import annotations

import logging
import signal
import threading
import time
import uuid

from google.protobuf.message import DecodeError

from protos import side_channels as sc
from protos import wire
from protos.communicator_objects import (
    header_pb2,
    unity_message_pb2,
    unity_output_pb2,
    unity_rl_initialization_output_pb2,
)
from protos.versions import COMMUNICATION_VERSION, UNITY_PACKAGE_VERSION, all_true_capabilities
from unity_stub_env.http2_client import CallError, Http2Channel
from unity_stub_env.tasks.base import EnvironmentParameters, Stat

logger = logging.getLogger("unity_stub_env")

ACADEMY_NAME = "AcademySingleton"
STATUS_OK = 200
STATUS_CLOSING = 400
_CHANNEL_OPTIONS = [
    ("grpc.max_send_message_length", -1),
    ("grpc.max_receive_message_length", -1),
    ("grpc.initial_reconnect_backoff_ms", 100),
    ("grpc.min_reconnect_backoff_ms", 100),
    ("grpc.max_reconnect_backoff_ms", 1000),
]
_POLL_S = 0.2
_STOP_GRACE_S = 2.0
_CLOSE_TIMEOUT_S = 3.0


class SessionEnd(Exception):
    """The session is over. ``exit_code`` 0 = the trainer or a signal ended it cleanly."""

    def __init__(self, message: str, exit_code: int = 0) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def communication_versions_compatible(unity_version: str, trainer_version: str) -> bool:
    """Unity's semantic check: major 0 needs equal major.minor, otherwise equal majors.

    A version that does not parse as dot-separated integers is incompatible.
    """
    try:
        unity = [int(part) for part in unity_version.split(".")]
        trainer = [int(part) for part in trainer_version.split(".")]
    except ValueError:
        return False
    if len(unity) < 2 or len(trainer) < 2:
        return False
    if unity[0] == 0:
        return unity[:2] == trainer[:2]
    return unity[0] == trainer[0]


EXCHANGE_PATH = "/communicator_objects.UnityToExternalProto/Exchange"


class _GrpcioChannel:
    """grpcio's client with raw bytes (``--transport grpcio``); same calls as Http2Channel."""

    def __init__(self, host: str, port: int) -> None:
        import grpc  # only for this transport: ~0.1 s of the default stub's start-up otherwise

        self._grpc = grpc
        self._channel = grpc.insecure_channel(f"{host}:{port}", options=_CHANNEL_OPTIONS)
        self._exchange = self._channel.unary_unary(EXCHANGE_PATH)
        self._ready = grpc.channel_ready_future(self._channel)

    def connect(self, timeout: float) -> bool:
        try:
            self._ready.result(timeout=timeout)
            return True
        except self._grpc.FutureTimeoutError:
            return False

    def call(self, request: bytes, timeout: float | None = None) -> bytes:
        # A plain blocking call: gRPC runs Python signal handlers while it waits, so SIGTERM
        # still works.
        try:
            return self._exchange(request, timeout=timeout)
        except self._grpc.RpcError as error:
            raise CallError(error.code().name, error.details() or "") from None

    def close(self, abort: bool = False) -> None:
        """``abort`` is Http2Channel's (a reset instead of a FIN); grpcio does not expose how its
        connection closes, so here it closes the same way either way."""
        self._ready.cancel()
        self._channel.close()


TRANSPORTS = ("http2", "grpcio")


def _open_channel(port: int, spin_s: float = 0.0, transport: str = "http2"):
    """The stub's gRPC client (one of TRANSPORTS): our blocking HTTP/2 one (no threads; default)
    or grpcio's."""
    if transport not in TRANSPORTS:
        raise ValueError(f"unknown transport {transport!r}; use one of {', '.join(TRANSPORTS)}")
    if transport == "grpcio":
        return _GrpcioChannel("localhost", port)
    return Http2Channel("localhost", port, EXCHANGE_PATH.encode(), spin_s)


class _AbortExchange(BaseException):
    """Raised by SIGALRM inside a blocking exchange after a stop signal's grace period."""


def _abort_exchange(*_args) -> None:
    raise _AbortExchange()


class RpcCommunicator:
    """One connection to a trainer at ``localhost:port``; Unity is the caller of every RPC."""

    def __init__(self, port: int, connect_timeout: float = 60.0, spin_wait: float = 0.0,
                 transport: str = "http2") -> None:
        self.address = f"localhost:{port}"
        self.port = port
        self.connect_timeout = float(connect_timeout)
        self.spin_wait = float(spin_wait)  # s; see protos/pacing.py
        self.transport = transport  # one of TRANSPORTS
        self.stop_requested = False
        self._channel = None
        self._sent_brain_keys: set[str] = set()

    def request_stop(self, *_args) -> None:
        """Signal handler (SIGTERM/SIGINT): finish the pending exchange if the trainer answers
        within ``_STOP_GRACE_S``, else abort it (SIGALRM) and send the closing status 400."""
        self.stop_requested = True
        if threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer"):
            signal.signal(signal.SIGALRM, _abort_exchange)
            signal.setitimer(signal.ITIMER_REAL, _STOP_GRACE_S)

    # Connection and handshake ---------------------------------------------------------------
    def connect(self) -> None:
        """Open the channel, retrying until ``connect_timeout``; SessionEnd(exit 1) if it fails."""
        self._channel = _open_channel(self.port, self.spin_wait, self.transport)
        deadline = time.monotonic() + self.connect_timeout
        while True:
            started = time.monotonic()
            wait = min(_POLL_S, max(deadline - started, 0.001))
            if self._channel.connect(wait):
                return
            if self.stop_requested:
                self._close_channel()
                raise SessionEnd("Stopped by a signal before the trainer answered.", 0) from None
            if time.monotonic() >= deadline:
                self._close_channel()
                raise SessionEnd(
                    f"Could not connect to a trainer at {self.address} within "
                    f"{self.connect_timeout:g} s. Start the trainer first (it listens on that port) "
                    "or pass the port it uses with --mlagents-port; raise --connect-timeout if "
                    "the trainer starts slowly.", 1) from None
            time.sleep(max(0.0, min(0.05, wait - (time.monotonic() - started))))  # refused at once

    def initialize(self):
        """Send M1 and M2. Returns (init input from M1's answer, rl_input of M2's answer)."""
        academy = unity_rl_initialization_output_pb2.UnityRLInitializationOutputProto(
            name=ACADEMY_NAME, communication_version=COMMUNICATION_VERSION,
            package_version=UNITY_PACKAGE_VERSION, capabilities=all_true_capabilities(),  # Unity 3.0 reports all 7
        )
        first = self._exchange_raw(
            _wrap(unity_output_pb2.UnityOutputProto(rl_initialization_output=academy)).SerializeToString())
        init_input = first.unity_input.rl_initialization_input
        trainer_version = init_input.communication_version
        if not communication_versions_compatible(COMMUNICATION_VERSION, trainer_version):
            self.close(send_closing=True)
            raise SessionEnd(
                f"The trainer at {self.address} speaks communication API {trainer_version!r}, which is "
                f"incompatible with this simulator's {COMMUNICATION_VERSION}. Use a trainer for "
                "ML-Agents Release 22 (communication API 1.x).", 1)
        if trainer_version.split(".")[:2] != COMMUNICATION_VERSION.split(".")[:2]:
            logger.warning("The trainer's communication API %s differs from %s at the minor level; "
                           "some features may not work.", trainer_version, COMMUNICATION_VERSION)
        logger.info("Connected to trainer at %s (package version %s, communication version %s)",
                    self.address, init_input.package_version, trainer_version)
        second = self._exchange_raw(_wrap(None).SerializeToString())
        return init_input, second.unity_input.rl_input

    # Regular exchanges -----------------------------------------------------------------------
    def exchange_many(self, batches: list, side_channel: bytes):
        """Send one step's agent infos of every behavior, ``[(behavior_key, EncodedInfos, brain_parameters)]``.

        ``brain_parameters`` is attached only the first time a behavior is sent with at least one
        agent info (as Unity does). Raises SessionEnd on a non-200 answer, QUIT or a lost trainer.
        """
        first_time = [(key, brain) for key, infos, brain in batches
                      if key not in self._sent_brain_keys and len(infos) > 0]
        answer = self._exchange_raw(step_message_bytes(
            [(key, infos.data) for key, infos, _ in batches], side_channel, [brain for _, brain in first_time]))
        self._sent_brain_keys.update(key for key, _ in first_time)
        return answer.unity_input.rl_input

    def _exchange_raw(self, message: bytes) -> unity_message_pb2.UnityMessageProto:
        """Send a serialized UnityMessageProto; returns the parsed answer."""
        # A plain blocking call on this thread: no thread or future per exchange (the hot path);
        # a stop signal's SIGALRM interrupts it after the grace period.
        try:
            raw = self._channel.call(message)
        except _AbortExchange:
            self.close(send_closing=True)
            raise SessionEnd("Stopped by a signal; sent status 400 to the trainer.", 0) from None
        except CallError as error:
            self._close_channel()
            raise SessionEnd(f"The trainer at {self.address} went away ({error.code}); "
                             "quitting like a Unity player does.", 0) from None
        try:
            answer = unity_message_pb2.UnityMessageProto.FromString(raw)
        except DecodeError:
            self.close(send_closing=False)
            raise SessionEnd(f"The trainer at {self.address} answered with a message that is not a "
                             "UnityMessageProto; is it an ML-Agents trainer?", 1) from None
        if answer.header.status != STATUS_OK:
            self._close_channel(abort=True)
            raise SessionEnd(f"The trainer closed the session (status {answer.header.status}).", 0)
        if self.stop_requested:
            self.close(send_closing=True)
            raise SessionEnd("Stopped by a signal; sent status 400 to the trainer.", 0)
        return answer

    def close(self, send_closing: bool) -> None:
        """Like Unity's ``Dispose``: one status-400 message (answer ignored), then shut down."""
        if self.stop_requested and hasattr(signal, "setitimer"):
            signal.setitimer(signal.ITIMER_REAL, 0)  # the abort timer is no longer needed
        if send_closing and self._channel is not None:
            try:
                self._channel.call(_wrap(None, STATUS_CLOSING).SerializeToString(), timeout=_CLOSE_TIMEOUT_S)
            except (CallError, _AbortExchange):
                pass
        self._close_channel()

    def _close_channel(self, abort: bool = False) -> None:
        """``abort``: the trainer ended the session; the http2 transport then leaves no TIME_WAIT
        on the trainer's port (http2_client.py, ``close``)."""
        if self._channel is not None:
            pace = getattr(self._channel, "pace", None)
            if pace is not None and pace.spin_s > 0:
                logger.info("--spin-wait-ms %g: %d of %d answers were found by polling, not by a wake-up",
                            pace.spin_s * 1e3, pace.caught_polling, pace.arrivals)
            self._channel.close(abort=abort)
            self._channel = None


def _wrap(output, status: int = STATUS_OK) -> unity_message_pb2.UnityMessageProto:
    message = unity_message_pb2.UnityMessageProto(header=header_pb2.HeaderProto(status=status))
    if output is not None:
        message.unity_output.CopyFrom(output)
    return message


def step_message_bytes(lists: list[tuple[str, bytes]], side_channel: bytes, brain_parameters: list) -> bytes:
    """The serialized UnityMessageProto of one step, written directly (no protobuf objects):
    header status 200; unity_output (2) = rl_output (1) {one agentInfos (2) map entry per
    behavior, in the given order as Unity's C# map keeps it: key (1), serialized
    ListAgentInfoProto (2); side_channel (3) when not empty}, then rl_initialization_output (2)
    holding ``brain_parameters`` when there are any. The same bytes protobuf writes for the
    message built field by field (tests/stub/test_stub_wire.py); the agent infos are copied,
    never parsed."""
    parts = [wire.map_entry(2, key, data) for key, data in lists]
    if side_channel:
        parts.append(wire.field(3, side_channel))
    output = wire.field(1, b"".join(parts))
    if brain_parameters:
        output += wire.field(2, unity_rl_initialization_output_pb2.UnityRLInitializationOutputProto(
            brain_parameters=brain_parameters).SerializeToString())
    return wire.HEADER_OK_FIELD + wire.field(2, output)


# Side channels -------------------------------------------------------------------------------
class SideChannelState:
    """What the trainer told the simulator through side channels (applied like Unity does)."""

    def __init__(self, env_params: EnvironmentParameters) -> None:
        self.env_params = env_params
        self.engine_config: dict[str, object] = {}
        self.float_properties: dict[str, float] = {}
        self._warned: set[uuid.UUID] = set()

    def apply(self, data: bytes) -> None:
        for channel_id, payload in sc.unpack_messages(data):
            if channel_id == sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID:
                key, parameter = sc.decode_env_parameter(payload)
                self.env_params.set(key, parameter.sampler())
                logger.debug("Environment parameter %s = %s", key, parameter)
            elif channel_id == sc.ENGINE_CONFIG_CHANNEL_ID:
                name, value = sc.decode_engine_config(payload)
                self.engine_config[name] = value
            elif channel_id == sc.FLOAT_PROPERTIES_CHANNEL_ID:
                key, value = sc.decode_float_property(payload)
                self.float_properties[key] = value
            elif channel_id == sc.TRAINING_ANALYTICS_CHANNEL_ID:
                continue
            elif channel_id not in self._warned:
                self._warned.add(channel_id)
                logger.warning("Unknown side channel %s; its messages are ignored.", channel_id)


def encode_stats(stats: list[Stat]) -> bytes:
    """The stats channel messages for ``stats``, framed for ``rl_output.side_channel``."""
    return sc.pack_messages((sc.STATS_CHANNEL_ID, sc.encode_stat(key, value, aggregation))
                            for key, value, aggregation in stats)
