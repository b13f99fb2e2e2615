"""Every ``MLAGENTS_LIKE_*`` environment variable, read once, at start, into one frozen object.

``mlagents-like-learn`` calls ``EnvVars.from_environ()`` first thing (trainer/cli.py), before it
parses its flags or imports numpy; a bad value is a ConfigError like a bad flag (one message naming
the variable, its value and what is allowed; exit code 2), raised before the results folder or a
simulator exists. The object is then handed down to whatever needs one of its values; no other
module reads these variables. The stub launched by the trainer gets the choices that concern it as
command-line flags (``--spin-wait-ms``, ``--transport``), never from the environment.

An empty value counts as unset. A variable of the ``MLAGENTS_LIKE_`` family that is not one of these
is refused too: a typo would otherwise be ignored without a word. Two names belong to the Slurm job
template (docker/slurm/train.sbatch, docs/cluster.md) and reach the trainer through the job's
environment: ``MLAGENTS_LIKE_IMAGE`` (run inside that container image) and ``MLAGENTS_LIKE_VENV``
(the venv to run); the trainer accepts and ignores them.

The variables, their defaults and what each does: docs/configuration.md, "Environment variables"
(tests/unit/test_config_docs.py checks that table against ``KNOWN`` and ``EnvVars``).

Data-parallel ranks (docs/cluster.md) are found from variables of other families, read here too:
torchrun's ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK``, ``MASTER_ADDR``, ``MASTER_PORT`` first, else
the tasks of an ``srun`` step: ``SLURM_PROCID``, ``SLURM_STEP_NUM_TASKS``, ``SLURM_LOCALID``,
``SLURM_JOB_NODELIST`` and ``SLURM_JOB_ID`` (MASTER_ADDR / MASTER_PORT are derived from the last
two when not set). A batch script alone (no srun step) is one rank, however many tasks it asked for.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from typing import Mapping

from trainer.errors import ConfigError

PREFIX = "MLAGENTS_LIKE_"
TORCH_THREADS = PREFIX + "TORCH_THREADS"
BLAS_THREADS = PREFIX + "BLAS_THREADS"
SPIN_WAIT_MS = PREFIX + "SPIN_WAIT_MS"
TRANSPORT = PREFIX + "TRANSPORT"
NUMPY_UPDATE = PREFIX + "NUMPY_UPDATE"
DIST_TIMEOUT_S = PREFIX + "DIST_TIMEOUT_S"
DIST_SYNC_EVERY = PREFIX + "DIST_SYNC_EVERY"
DEBUG_WEIGHTS = PREFIX + "DEBUG_WEIGHTS"
CRASH_AT = PREFIX + "CRASH_AT"
KNOWN = (TORCH_THREADS, BLAS_THREADS, SPIN_WAIT_MS, TRANSPORT, NUMPY_UPDATE, DIST_TIMEOUT_S, DIST_SYNC_EVERY,
         DEBUG_WEIGHTS, CRASH_AT)
JOB_TEMPLATE_ONLY = (PREFIX + "IMAGE", PREFIX + "VENV")  # read by docker/slurm/train.sbatch only

TRANSPORTS = ("http2", "grpcio")  # the gRPC transports of trainer/protocol/server.py
DEFAULT_SPIN_WAIT_S = 1.0e-3
DEFAULT_DIST_TIMEOUT_S = 300.0
DEFAULT_DIST_SYNC_EVERY = 8


@dataclass(frozen=True)
class RankEnv:
    """Where this process is in a data-parallel run, as its launcher said (defaults: alone).
    ``job_nodelist`` / ``job_id``: Slurm's, for MASTER_ADDR / MASTER_PORT when those are unset
    (trainer/distributed.py resolves them)."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    master_addr: str | None = None
    master_port: int | None = None
    job_nodelist: str | None = None
    job_id: int | None = None
    launcher: str = "none"  # "torchrun" (RANK/WORLD_SIZE), "srun" (SLURM_PROCID/...) or "none"

    @classmethod
    def from_environ(cls, environ: Mapping[str, str]) -> "RankEnv":
        get = lambda name: environ.get(name, "").strip()  # noqa: E731
        if get("WORLD_SIZE") and get("RANK"):
            launcher, rank, world, local = "torchrun", get("RANK"), get("WORLD_SIZE"), get("LOCAL_RANK") or "0"
        elif get("SLURM_STEP_NUM_TASKS") and get("SLURM_PROCID"):
            launcher, rank, world = "srun", get("SLURM_PROCID"), get("SLURM_STEP_NUM_TASKS")
            local = get("SLURM_LOCALID") or "0"
        else:
            return cls()
        names = ("RANK", "WORLD_SIZE", "LOCAL_RANK") if launcher == "torchrun" else (
            "SLURM_PROCID", "SLURM_STEP_NUM_TASKS", "SLURM_LOCALID")
        numbers = []
        for name, value in zip(names, (rank, world, local)):
            if not re.fullmatch(r"[0-9]+", value):
                raise ConfigError(f"{name}={value!r} is not a whole number >= 0; the launcher ({launcher}) "
                                  f"sets it: start the ranks with torchrun or srun, or unset it.")
            numbers.append(int(value))
        rank_n, world_n, local_n = numbers
        if world_n < 1 or rank_n >= world_n:
            raise ConfigError(f"{names[0]}={rank_n} does not fit {names[1]}={world_n} (a rank is 0 .. world size"
                              f" - 1); start the ranks with torchrun or srun, or unset them.")
        port = get("MASTER_PORT")
        if port and not (re.fullmatch(r"[0-9]+", port) and 0 < int(port) < 65536):
            raise ConfigError(f"MASTER_PORT={port!r} is not a port number (1-65535); set another or unset it.")
        job = get("SLURM_JOB_ID")
        return cls(rank=rank_n, world_size=world_n, local_rank=local_n, master_addr=get("MASTER_ADDR") or None,
                   master_port=int(port) if port else None, job_nodelist=get("SLURM_JOB_NODELIST") or None,
                   job_id=int(job) if re.fullmatch(r"[0-9]+", job) else None, launcher=launcher)


@dataclass(frozen=True)
class EnvVars:
    """The run's ``MLAGENTS_LIKE_*`` choices (defaults: none of the variables set)."""

    torch_threads: int = 1
    blas_threads: int | None = None  # None: 1, unless the user set OpenBLAS/OpenMP/MKL's own
    spin_wait_s: float = DEFAULT_SPIN_WAIT_S
    transport: str = "http2"
    numpy_update: bool = True
    dist_timeout_s: float = DEFAULT_DIST_TIMEOUT_S
    dist_sync_every: int = DEFAULT_DIST_SYNC_EVERY
    debug_weights: str | None = None
    ranks: RankEnv = RankEnv()
    crash_at: tuple | None = None  # test hook: (point, occurrence[, signal]), trainer/crash_points.py

    @classmethod
    def from_environ(cls, environ: Mapping[str, str] = os.environ) -> "EnvVars":
        """The choices in ``environ``; ConfigError naming the first bad or unknown variable."""
        unknown = sorted(name for name in environ if name.startswith(PREFIX)
                         and name not in KNOWN and name not in JOB_TEMPLATE_ONLY)
        if unknown:
            raise ConfigError(f"{unknown[0]}={environ[unknown[0]]!r} is not a variable mlagents-like-learn "
                              f"knows; unset it (known: {', '.join(KNOWN)}).")
        values = {name: environ.get(name, "").strip() for name in KNOWN}
        blas = values[BLAS_THREADS]
        return cls(
            torch_threads=_threads(TORCH_THREADS, values[TORCH_THREADS], "torch's threads for the networks")
            if values[TORCH_THREADS] else 1,
            blas_threads=_threads(BLAS_THREADS, blas, "numpy's BLAS threads") if blas else None,
            spin_wait_s=_spin_wait_s(values[SPIN_WAIT_MS]),
            transport=_transport(values[TRANSPORT]),
            numpy_update=_numpy_update(values[NUMPY_UPDATE]),
            dist_timeout_s=_seconds(DIST_TIMEOUT_S, values[DIST_TIMEOUT_S], DEFAULT_DIST_TIMEOUT_S),
            dist_sync_every=_threads(DIST_SYNC_EVERY, values[DIST_SYNC_EVERY], "exchanges per agreement of the "
                                     "data-parallel ranks") if values[DIST_SYNC_EVERY] else DEFAULT_DIST_SYNC_EVERY,
            debug_weights=values[DEBUG_WEIGHTS] or None,
            ranks=RankEnv.from_environ(environ),
            crash_at=_crash_at(values[CRASH_AT]),
        )


def _threads(name: str, value: str, what: str) -> int:
    if re.fullmatch(r"[0-9]+", value) and int(value) >= 1:
        return int(value)
    raise ConfigError(f"{name}={value!r} is not a whole number >= 1 ({what}); use e.g. {name}=2, "
                      f"or unset it for the default.")


def _spin_wait_s(value: str) -> float:
    if not value:
        return DEFAULT_SPIN_WAIT_S
    try:
        ms = float(value)
    except ValueError:
        ms = math.nan
    if not 0.0 <= ms < math.inf:
        raise ConfigError(f"{SPIN_WAIT_MS}={value!r} is not a number of milliseconds >= 0; "
                          f"use e.g. {SPIN_WAIT_MS}=1, or 0 to always sleep while waiting.")
    return ms / 1e3


def _transport(value: str) -> str:
    if not value:
        return "http2"
    if value.lower() in TRANSPORTS:
        return value.lower()
    raise ConfigError(f"{TRANSPORT}={value!r} is not a transport; use {TRANSPORT}=http2 (the default) "
                      f"or {TRANSPORT}=grpcio.")


def _numpy_update(value: str) -> bool:
    if value in ("", "1"):
        return True
    if value == "0":
        return False
    raise ConfigError(f"{NUMPY_UPDATE}={value!r} is neither 0 nor 1; use {NUMPY_UPDATE}=1 (the default: "
                      f"minibatch updates in numpy) or {NUMPY_UPDATE}=0 (torch autograd).")


def _seconds(name: str, value: str, default: float) -> float:
    if not value:
        return default
    try:
        seconds = float(value)
    except ValueError:
        seconds = math.nan
    if not 0.0 < seconds < math.inf:
        raise ConfigError(f"{name}={value!r} is not a number of seconds > 0; use e.g. {name}={default:g}, "
                          f"or unset it for the default.")
    return seconds


def _crash_at(value: str) -> tuple[str, int] | None:
    if not value:
        return None
    from trainer.crash_points import POINTS

    parts = value.split(":")
    if len(parts) in (2, 3) and parts[0] in POINTS and re.fullmatch(r"[0-9]+", parts[1]) and int(parts[1]) >= 1:
        if len(parts) == 2:
            return parts[0], int(parts[1])
        if parts[2] in ("SIGTERM", "SIGUSR1", "SIGINT", "SIGQUIT", "SIGKILL", "SIGSTOP"):
            return parts[0], int(parts[1]), parts[2]
    raise ConfigError(f"{CRASH_AT}={value!r} is not POINT:N[:SIGNAL] with N >= 1, POINT one of "
                      f"{', '.join(POINTS)} and SIGNAL a stop signal or SIGSTOP (a test hook that kills or stops the "
                      f"trainer; unset it for a normal run).")
