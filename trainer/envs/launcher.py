"""Launching simulators: find the executable, build its command line, run it, and decide restarts.

docs/protocol.md, "Launching an executable" (executable lookup, argument order) and "Timeouts and
liveness" (close timeouts, restart limits).
``--env stub:TASK`` launches the built-in MuJoCo stub (``python -m unity_stub_env.cli --task TASK``)
with the same Unity-style arguments, so everything downstream treats both alike.
"""
from __future__ import annotations

import errno
import glob
import logging
import os
import signal
import subprocess
import sys
from collections import deque
from typing import IO

from trainer.errors import ConfigError, EnvironmentNotFoundError, UserError
from unity_stub_env import spin_wait_args, transport_args

logger = logging.getLogger("mlagents_like")

STUB_PREFIX = "stub:"
PORT_ARG = "--mlagents-port"
_EXECUTABLE_SUFFIXES = (".app", ".exe", ".x86_64", ".x86")


def is_stub_env(env_path: str) -> bool:
    return env_path.startswith(STUB_PREFIX)


# --------------------------------------------------------------------------------------------
# Finding the executable
# --------------------------------------------------------------------------------------------
def _strip_executable_suffix(path: str) -> str:
    for suffix in _EXECUTABLE_SUFFIXES:
        if path.endswith(suffix):
            return path[: -len(suffix)]
    return path


def _is_executable_file(path: str) -> bool:
    return os.path.isfile(path) and os.access(path, os.X_OK)


def _linux_candidates(base: str) -> list[str]:
    candidates = [base + ".x86_64", base + ".x86", base]
    if os.path.isdir(base):
        inside = sorted(glob.glob(os.path.join(glob.escape(base), "*.x86_64")))
        if len(inside) == 1:
            candidates.append(inside[0])
        else:
            candidates.append(os.path.join(base, "*.x86_64"))
    return candidates


def _macos_candidates(base: str) -> list[str]:
    macos_dir = os.path.join(base + ".app", "Contents", "MacOS")
    named = os.path.join(macos_dir, os.path.basename(os.path.normpath(base)))
    others = [p for p in sorted(glob.glob(os.path.join(glob.escape(macos_dir), "*"))) if p != named]
    return [named] + (others or [os.path.join(macos_dir, "*")])


def _windows_candidates(base: str) -> list[str]:
    found = sorted(glob.glob(os.path.join(glob.escape(base), "*.exe")))
    inside = [p for p in found if not os.path.basename(p).startswith("UnityCrashHandler")]
    return [base + ".exe"] + (inside or [os.path.join(base, "*.exe")])


def mirror_spec_path(env_path: str | None) -> str | None:
    """The FILE of ``--env stub:mirror=FILE`` (None for any other --env)."""
    from unity_stub_env import MIRROR_TASK

    if env_path is None or not is_stub_env(env_path):
        return None
    prefix = MIRROR_TASK + "="
    return next((name[len(prefix):] for name in env_path[len(STUB_PREFIX):].split(",")
                 if name.startswith(prefix)), None)


def _absolute_spec(name: str, mirror: str) -> str:
    """``mirror=FILE`` with FILE made absolute and checked to exist; other task names unchanged."""
    if not name.startswith(mirror + "="):
        return name
    path = os.path.abspath(os.path.expanduser(name[len(mirror) + 1:]))
    if not os.path.isfile(path):
        raise EnvironmentNotFoundError(
            f"--env stub:{mirror}=FILE: the behavior spec file {path!r} does not exist. Capture one with "
            "mlagents-like-learn --capture-spec FILE --env BUILD, or take run_logs/behaviors.json of a run."
        )
    return f"{mirror}={path}"


def resolve_env_path(env_path: str, platform: str | None = None) -> str:
    """The absolute path of the simulator to run for ``--env env_path`` (``stub:TASK`` unchanged).

    Raises EnvironmentNotFoundError naming every candidate tried.
    """
    if is_stub_env(env_path):
        from unity_stub_env import MIRROR_TASK, TASK_NAMES

        given = env_path[len(STUB_PREFIX):].strip()
        names = given.split(",")  # TASK[,TASK...]; mirror=FILE replays a behaviors.json
        unknown = [name for name in names if name not in TASK_NAMES and not name.startswith(MIRROR_TASK + "=")]
        if not given or unknown:
            what = f"names the unknown stub task {', '.join(map(repr, unknown))}" if given else "names no stub task"
            raise EnvironmentNotFoundError(
                f"--env {env_path!r} {what}; use --env stub:TASK with one of: {', '.join(TASK_NAMES)} "
                f"(unity-stub-env --list describes them), or --env stub:{MIRROR_TASK}=FILE to replay a "
                "behaviors.json (docs/mirror.md)."
            )
        return STUB_PREFIX + ",".join(_absolute_spec(name, MIRROR_TASK) for name in names)
    platform = platform or sys.platform
    base = os.path.abspath(os.path.expanduser(_strip_executable_suffix(env_path.strip())))
    if platform.startswith("darwin"):
        candidates = _macos_candidates(base)
    elif platform.startswith("win"):
        candidates = _windows_candidates(base)
    else:
        candidates = _linux_candidates(base)
    for candidate in candidates:
        if _is_executable_file(candidate):
            return candidate
    not_executable = [c for c in candidates if os.path.isfile(c)]
    hint = (
        f" Found {', '.join(not_executable)} but it is not executable: run `chmod +x` on it."
        if not_executable
        else ""
    )
    raise EnvironmentNotFoundError(
        f"Could not find a simulator executable for --env {env_path!r}. Tried: {', '.join(candidates)}."
        f"{hint} Check the --env path (a player built for this OS), use `--env stub:TASK` for the "
        "built-in stub simulator, or omit --env to train against the Unity Editor (press Play)."
    )


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------
def build_launch_command(
    env_path: str,
    worker_id: int,
    base_port: int,
    no_graphics: bool = False,
    no_graphics_monitor: bool = False,
    log_folder: str | None = None,
    env_args: list[str] | None = None,
    seed: int | None = None,
    num_areas: int = 1,
    stub_spin_wait: float = 0.0,
    stub_transport: str = "http2",
) -> list[str]:
    """The argv for worker ``worker_id``, in the order of docs/protocol.md, "Launching an executable".

    ``env_path`` is a resolved executable path or ``stub:TASK``. ``seed`` and ``num_areas`` are
    not command-line arguments (they travel in the initialization message); they are accepted so
    one set of env settings can be passed through, and ``num_areas`` is checked here.
    ``stub_spin_wait`` (s) is passed to the stub as ``--spin-wait-ms``, ``stub_transport`` as
    ``--transport`` unless it is the stub's default http2 (never to a Unity build).
    """
    if num_areas < 1:
        raise ConfigError(f"--num-areas must be at least 1, got {num_areas}.")
    if is_stub_env(env_path):
        command = [sys.executable, "-m", "unity_stub_env.cli", "--task", env_path[len(STUB_PREFIX):]]
        command += spin_wait_args(stub_spin_wait) + transport_args(stub_transport)
    else:
        command = [env_path]
    extra = list(env_args or [])
    if no_graphics or (no_graphics_monitor and worker_id != 0):
        command += ["-nographics", "-batchmode"]
    command += [PORT_ARG, str(base_port + worker_id)]
    if log_folder is not None and "-logfile" not in (arg.lower() for arg in extra):
        command += ["-logFile", player_log_path(log_folder, worker_id)]
    return command + extra


def player_log_path(log_folder: str, worker_id: int) -> str:
    return os.path.join(os.path.abspath(log_folder), f"Player-{worker_id}.log")


def log_file_of(command: list[str]) -> str | None:
    """The -logFile value in ``command`` (case-insensitive flag), or None."""
    for flag, value in zip(command, command[1:]):
        if flag.lower() == "-logfile":
            return value
    return None


# --------------------------------------------------------------------------------------------
# The process
# --------------------------------------------------------------------------------------------
class SimulatorProcess:
    """One simulator child process (Unity player or stub), in its own session.

    Output: with ``debug`` it is inherited (shown on the terminal); otherwise the stub's
    stdout/stderr are appended to its -logFile (if any; opened in append mode, so the stub may
    also append to it) and an executable's go to DEVNULL (Unity writes its own -logFile).
    """

    def __init__(self, command: list[str], worker_id: int = 0, *, log_folder: str | None = None,
                 debug: bool = False, output_to_log: bool | None = None) -> None:
        """``output_to_log``: append stdout/stderr to the log file; defaults to True for the stub.
        The log file is the command's -logFile, else ``<log_folder>/Player-<worker_id>.log``."""
        self.command = list(command)
        self.worker_id = worker_id
        self.debug = debug
        self.is_stub = len(command) >= 5 and command[1:4] == ["-m", "unity_stub_env.cli", "--task"]
        self.name = f"stub task {command[4]}" if self.is_stub else os.path.basename(command[0])
        self.log_path = log_file_of(self.command)
        if self.log_path is None and log_folder is not None:
            self.log_path = player_log_path(log_folder, worker_id)
        self.output_to_log = self.is_stub if output_to_log is None else output_to_log
        self._process: subprocess.Popen | None = None
        self._log_handle: IO[bytes] | None = None

    @property
    def port(self) -> int | None:
        for flag, value in zip(self.command, self.command[1:]):
            if flag == PORT_ARG:
                return int(value)
        return None

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process is not None else None

    @property
    def returncode(self) -> int | None:
        return self._process.poll() if self._process is not None else None

    def _output_target(self):
        if self.debug:
            return None
        if self.output_to_log and self.log_path is not None:
            os.makedirs(os.path.dirname(self.log_path) or ".", exist_ok=True)
            self._log_handle = open(self.log_path, "ab")
            return self._log_handle
        return subprocess.DEVNULL

    def start(self) -> "SimulatorProcess":
        if self._process is not None:
            raise RuntimeError(f"{self.describe()} was already started.")
        if self.log_path is not None:
            os.makedirs(os.path.dirname(self.log_path) or ".", exist_ok=True)
        target = self._output_target()
        logger.debug("Launching %s", " ".join(self.command))
        try:
            self._process = subprocess.Popen(
                self.command, start_new_session=True, stdout=target, stderr=target
            )
        except PermissionError as error:
            self._close_log()
            raise EnvironmentNotFoundError(
                f"Cannot run {self.command[0]!r}: permission denied. Make it executable with "
                f"`chmod -R 755 {os.path.dirname(self.command[0]) or self.command[0]}`."
            ) from error
        except FileNotFoundError as error:
            self._close_log()
            raise EnvironmentNotFoundError(
                f"Cannot run {self.command[0]!r}: no such file. Check the --env path."
            ) from error
        except OSError as error:
            self._close_log()
            if error.errno != errno.E2BIG:
                raise
            longest = max(len(os.fsencode(a)) for a in self.command)
            raise UserError(
                f"Cannot start simulator worker {self.worker_id} ({self.name}): its command line is too long for the operating system "
                f"({sum(len(os.fsencode(a)) + 1 for a in self.command)} bytes in {len(self.command)} arguments, "
                f"the longest {longest} bytes). Shorten --env-args (env_settings.env_args), e.g. pass the "
                f"values in a file the game reads."
            ) from None
        return self

    def is_alive(self) -> bool:
        return self._process is not None and self._process.poll() is None

    def wait_for_exit(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for the process to exit on its own; True if it did."""
        if self._process is None:
            return True
        try:
            self._process.wait(timeout=timeout)
            return True
        except subprocess.TimeoutExpired:
            return False

    def close(self, timeout: float = 10.0) -> int | None:
        """SIGTERM, wait up to ``timeout`` s, then SIGKILL. Returns the exit code (None if never started)."""
        if self._process is None:
            return None
        if self._process.poll() is None:
            try:
                self._process.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass
            if not self.wait_for_exit(timeout):
                logger.warning("%s did not exit within %.0f s of SIGTERM; killing it.", self.describe(), timeout)
                self._process.kill()
                self._process.wait()
        self._close_log()
        return self._process.returncode

    def _close_log(self) -> None:
        if self._log_handle is not None:
            self._log_handle.close()
            self._log_handle = None

    def describe(self) -> str:
        """E.g. ``simulator worker 0 (3DBall.x86_64, port 5005, pid 1234, running; log /r/Player-0.log)``."""
        if self._process is None:
            state = "not started"
        elif self._process.poll() is None:
            state = f"pid {self._process.pid}, running"
        else:
            state = f"pid {self._process.pid}, exited with code {self._process.returncode}"
        log = f"; log {self.log_path}" if self.log_path else ""
        if self._process is not None and self._process.poll() is not None:
            last = self.last_log_line()
            log += f"; its log ends: {last!r}" if last else ""
        return f"simulator worker {self.worker_id} ({self.name}, port {self.port}, {state}{log})"

    def last_log_line(self, limit: int = 300) -> str:
        """The last non-empty line of the log file (at most ``limit`` characters), or ''."""
        if not self.log_path:
            return ""
        try:
            with open(self.log_path, "rb") as f:
                f.seek(max(0, os.fstat(f.fileno()).st_size - 4096))
                lines = f.read().decode("utf-8", "replace").splitlines()
        except OSError:
            return ""
        last = next((line.strip() for line in reversed(lines) if line.strip()), "")
        return last[:limit]


# --------------------------------------------------------------------------------------------
# Restarts
# --------------------------------------------------------------------------------------------
class RestartPolicy:
    """Whether a crashed simulator may be restarted (docs/protocol.md, "Timeouts and liveness"); the
    pool keeps one per worker.

    A restart is allowed while fewer than ``max_lifetime_restarts`` restarts happened in total
    (-1: unlimited) and fewer than ``rate_limit_n`` happened in the last ``rate_limit_period_s``
    seconds, i.e. at times t with t > now - period (-1: no rate limit).
    """

    def __init__(self, max_lifetime_restarts: int = 10, rate_limit_n: int = 1,
                 rate_limit_period_s: float = 60) -> None:
        self.max_lifetime_restarts = max_lifetime_restarts
        self.rate_limit_n = rate_limit_n
        self.rate_limit_period_s = rate_limit_period_s
        self.restart_count = 0
        self._recent: deque[float] = deque()

    def has_quota(self, now: float) -> bool:
        """True if a restart at time ``now`` (seconds, any monotonic clock) would be allowed."""
        while self._recent and self._recent[0] <= now - self.rate_limit_period_s:
            self._recent.popleft()
        lifetime_ok = self.max_lifetime_restarts == -1 or self.restart_count < self.max_lifetime_restarts
        rate_ok = self.rate_limit_n == -1 or len(self._recent) < self.rate_limit_n
        return lifetime_ok and rate_ok

    def record_restart(self, now: float) -> None:
        self.restart_count += 1
        self._recent.append(now)

    def allow_restart(self, now: float) -> bool:
        """Check the quota at ``now``; if allowed, count this restart and return True."""
        if not self.has_quota(now):
            return False
        self.record_restart(now)
        return True
