"""All simulator connections of a run, stepped together as one batch.

One ``UnityEndpoint`` (gRPC server, one port) per worker, and for executables one
``SimulatorProcess`` each. Every step sends all workers their actions first and only then waits
for their replies, so N simulators run in parallel while the trainer waits once. The pool steps in
lockstep (every worker every step): with seeds fixed, a run is repeatable, which ML-Agents' "go on
when any worker replied" manager does not give.

A worker whose simulator dies is restarted under the restart policy (docs/protocol.md, "Timeouts and
liveness"); after a restart every worker is reset and the caller is told (``restarted``) so it drops
partial trajectories.
"""
from __future__ import annotations

import logging
import socket
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from trainer.config.env_vars import DEFAULT_SPIN_WAIT_S
from trainer.envs.cpus import spin_budget
from trainer.envs.launcher import RestartPolicy, SimulatorProcess, build_launch_command, resolve_env_path
from trainer.errors import SimulatorExitedError, UnityTimeOutError, UserError
from trainer.protocol.listen import listen, port_in_use_error

if TYPE_CHECKING:  # the server (numpy, protobuf) is imported after the launch: ``_Worker.serve``
    from protos.types import ActionTuple, BehaviorSpec, StepResult
    from trainer.protocol.server import UnityEndpoint

logger = logging.getLogger("mlagents_like")

DEFAULT_EDITOR_PORT = 5004


@dataclass(frozen=True)
class PoolSettings:
    env_path: str | None
    env_args: tuple[str, ...]
    base_port: int
    num_envs: int
    num_areas: int
    seed: int
    timeout_wait: float
    bind: str
    no_graphics: bool
    no_graphics_monitor: bool
    log_folder: str | None
    max_lifetime_restarts: int = 10
    restarts_rate_limit_n: int = 1
    restarts_rate_limit_period_s: float = 60
    debug: bool = False
    spin_wait_s: float = DEFAULT_SPIN_WAIT_S  # MLAGENTS_LIKE_SPIN_WAIT_MS (trainer.config.env_vars)
    transport: str = "http2"  # MLAGENTS_LIKE_TRANSPORT: the server's and the launched stubs'
    # data-parallel rank r numbers its workers from r x num_envs (trainer/distributed.py): their
    # ports (base + id), seeds (seed + id) and logs (Player-<id>.log) differ from every other rank's
    first_worker: int = 0


@dataclass
class PoolStep:
    results: list[StepResult]
    restarted: bool = False  # every worker was reset: drop in-progress trajectories


class _Worker:
    def __init__(self, worker_id: int, settings: PoolSettings, env_path: str | None, spin_wait: float = 0.0):
        self.worker_id = worker_id
        self.settings = settings
        self.env_path = env_path
        self.spin_wait = spin_wait  # s, both ends of the exchange (protos/pacing.py, trainer/envs/cpus.py)
        self.port = settings.base_port + worker_id if env_path else DEFAULT_EDITOR_PORT
        self.process: SimulatorProcess | None = None
        self.listener: socket.socket | None = None  # bound, not yet served (``launch``)
        self.endpoint: UnityEndpoint | None = None

    def connect(self) -> None:
        self.launch()
        self.handshake()

    def launch(self) -> None:
        """Listen on the port, then start the simulator (it boots while the trainer does other work).

        A simulator the HTTP/2 transport serves is started as soon as its port listens, before the
        gRPC server's modules are imported: the socket is bound with the standard library, and
        ``serve`` hands it to the server later (docs/performance.md, "Start-up and exit"). grpcio
        binds its own socket, and the Editor is started by the user: both are served at once."""
        s = self.settings
        if self.env_path:
            cmd = build_launch_command(
                self.env_path, self.worker_id, s.base_port, s.no_graphics, s.no_graphics_monitor,
                s.log_folder, list(s.env_args), s.seed + self.worker_id, s.num_areas, self.spin_wait,
                s.transport,
            )
            self.process = SimulatorProcess(cmd, self.worker_id, log_folder=s.log_folder, debug=s.debug)
        if self.process is not None and s.transport == "http2":
            try:
                self.listener = listen(s.bind, self.port)  # before launching: the simulator finds us listening
            except OSError:
                raise port_in_use_error(s.bind, self.port, False, self.process.describe()) from None
        else:
            self.serve()
        if self.process:
            self.process.start()
        else:
            logger.info("Listening on port %d. Start training by pressing the Play button in the Unity Editor.",
                        self.port)

    def serve(self) -> None:
        """The gRPC server on this worker's port (on the socket ``launch`` bound, if any)."""
        if self.endpoint is not None:
            return
        from trainer.protocol.server import UnityEndpoint

        s = self.settings
        is_alive = self.process.is_alive if self.process else None
        describe = self.process.describe if self.process else "the Unity Editor"
        listener, self.listener = self.listener, None
        self.endpoint = UnityEndpoint(self.port, bind=s.bind, timeout_wait=s.timeout_wait,
                                      is_alive=is_alive, describe=describe, spin_wait=self.spin_wait,
                                      transport=s.transport, editor=self.process is None, listener=listener)
        self.endpoint.start()

    def handshake(self) -> None:
        s = self.settings
        self.serve()
        init = self.endpoint.handshake(s.seed + self.worker_id, s.num_areas)
        logger.info("Connected to Unity environment with package version %s and communication version %s",
                    init.package_version, init.communication_version)

    def close(self, timeout: float) -> None:
        if self.endpoint is not None:
            self.endpoint.close()
        if self.listener is not None:
            self.listener.close()
        if self.process is not None:
            self.process.close(timeout)
        self.endpoint = None
        self.listener = None
        self.process = None


class EnvPool:
    def __init__(self, settings: PoolSettings, initial_side_channel: Callable[[], bytes] = lambda: b""):
        """``initial_side_channel`` returns the bytes a restarted simulator needs with its first
        RESET (engine configuration and current environment parameters); the run sets it once its
        state exists (trainer/run.py), after the launch."""
        if settings.env_path is None and settings.num_envs != 1:
            raise UserError("--num-envs > 1 needs --env: the Unity Editor is a single environment.")
        env_path = resolve_env_path(settings.env_path) if settings.env_path else None
        self.settings = settings
        # waiting sides poll instead of sleeping only if the trainer and every simulator have a CPU
        spin_wait = spin_budget(settings.num_envs + 1, settings.spin_wait_s)
        self.workers = [_Worker(settings.first_worker + i, settings, env_path, spin_wait)
                        for i in range(settings.num_envs)]
        self.initial_side_channel = initial_side_channel
        # each worker has its own restart quota, as in ML-Agents: two simulators that crash in the
        # same minute are both restarted under the default limit of 1 per 60 s
        self._restarts = [RestartPolicy(settings.max_lifetime_restarts, settings.restarts_rate_limit_n,
                                        settings.restarts_rate_limit_period_s) for _ in self.workers]

    @property
    def num_envs(self) -> int:
        return len(self.workers)

    def behavior_specs(self) -> dict[str, BehaviorSpec]:
        specs: dict[str, BehaviorSpec] = {}
        for w in self.workers:
            if w.endpoint is not None:
                specs.update(w.endpoint.behavior_specs)
        return specs

    def start(self) -> None:
        self.launch()
        self.connect()

    def launch(self) -> None:
        """Listen and start every simulator without waiting for them: a Unity build takes seconds
        to boot, which the trainer spends importing torch and building its networks."""
        try:
            for w in self.workers:
                w.launch()
        except BaseException:
            self.close()
            raise

    def serve(self) -> None:
        """Serve every launched simulator's port (``_Worker.serve``): the gRPC server's modules
        are imported here if they were not yet, so call it once the simulators boot."""
        try:
            for w in self.workers:
                w.serve()
        except BaseException:
            self.close()
            raise

    def connect(self) -> None:
        """Handshake with every launched simulator (waits up to --timeout-wait for each)."""
        try:
            for w in self.workers:
                self._handshake(w)
        except BaseException:
            self.close()
            raise

    def _handshake(self, w: _Worker) -> None:
        """Handshake with ``w``; a simulator that dies before it (killed while it boots) is
        started again within its restart quota. One that never answers is not: it would again
        take --timeout-wait, and is most likely a wrong --env or a Unity build that hangs."""
        while True:
            try:
                w.handshake()
                return
            except SimulatorExitedError as err:
                if w.process is None or not self._restarts[w.worker_id].allow_restart(time.monotonic()):
                    raise
                logger.warning("Worker %d failed before its first message (%s); restarting it.", w.worker_id, err)
                w.close(timeout=2.0)
                w.launch()

    def reset(self, side_channel: bytes | list[bytes]) -> list[StepResult]:
        """RESET every worker; a simulator that dies meanwhile is restarted like in ``receive``."""
        chans = self._per_worker(side_channel)
        for w, sc in zip(self.workers, chans):
            w.endpoint.send_reset(sc)
        results, failed = self._receive_all()
        return self._recover(failed) if failed else results

    def step(self, actions: list[dict[str, ActionTuple]], side_channel: bytes | list[bytes]) -> PoolStep:
        self.send_step(actions, side_channel)
        return self.receive()

    def send_step(self, actions: list[dict[str, ActionTuple]], side_channel: bytes | list[bytes]) -> None:
        """Answer every worker now; the simulators step while the trainer does other work."""
        chans = self._per_worker(side_channel)
        for w, act, sc in zip(self.workers, actions, chans):
            w.endpoint.send_step(act, sc)

    def receive(self) -> PoolStep:
        """Wait for every worker's next message (restarting a dead simulator if allowed)."""
        results, failed = self._receive_all()
        if not failed:
            return PoolStep(results)
        return PoolStep(self._recover(failed), restarted=True)

    def _receive_all(self) -> tuple[list[StepResult], list[tuple[_Worker, Exception]]]:
        """Every worker's next message; the workers whose simulator died or went silent apart."""
        results: list[StepResult] = []
        failed: list[tuple[_Worker, Exception]] = []
        for w in self.workers:
            try:
                results.append(w.endpoint.receive())
            except (SimulatorExitedError, UnityTimeOutError) as err:
                failed.append((w, err))
        return results, failed

    def _recover(self, failed: list[tuple[_Worker, Exception]]) -> list[StepResult]:
        """Restart the failed simulators, each within its own quota (else its error is raised),
        then RESET every worker with a fresh configuration: the healthy ones wait for an answer to
        their last message, the restarted ones for their first RESET. Repeats if one dies again."""
        while failed:
            for w, err in failed:
                quota = self._restarts[w.worker_id - self.settings.first_worker]
                if w.process is None or not quota.allow_restart(time.monotonic()):
                    raise err
                logger.warning("Worker %d failed (%s); restarting it and resetting all environments.",
                               w.worker_id, err)
                self._restart_process(w)
            for w in self.workers:
                w.endpoint.send_reset(self.initial_side_channel())
            results, failed = self._receive_all()
        return results

    def _restart_process(self, failed: _Worker) -> None:
        failed.close(timeout=2.0)
        failed.launch()
        self._handshake(failed)

    def _per_worker(self, side_channel: bytes | list[bytes]) -> list[bytes]:
        if isinstance(side_channel, (bytes, bytearray)):
            return [bytes(side_channel)] * self.num_envs
        return list(side_channel)

    def close(self) -> None:
        for w in self.workers:
            try:
                w.close(timeout=self.settings.timeout_wait)
            except Exception as err:  # closing must never hide the original error
                logger.debug("closing worker %d: %s", w.worker_id, err)
