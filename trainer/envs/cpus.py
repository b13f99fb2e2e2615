"""How the trainer and the simulators it launches share the machine's CPUs.

Pacing (``protos/pacing.py``) polls instead of sleeping while it waits for the peer; that only
pays when every busy process of the run (the trainer and each simulator) has a CPU of its own,
which ``spin_budget`` decides once per run. The same affinity count decides whether the PPO
update may fork a process of its own.
"""
from __future__ import annotations

import math
import os

DEFAULT_SPIN_S = 1.0e-3  # poll for at most this long past when the answer is due
SPIN_WAIT_ENV = "MLAGENTS_LIKE_SPIN_WAIT_MS"  # the user's choice of that budget; 0 turns pacing off


def usable_cpus() -> int:
    """CPUs this process may run on (the affinity mask: a Slurm allocation, taskset)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def configured_spin(environ=os.environ) -> float:
    """The polling budget in seconds: ``MLAGENTS_LIKE_SPIN_WAIT_MS`` if set, else 1 ms.
    Raises ConfigError for anything but a number >= 0."""
    value = environ.get(SPIN_WAIT_ENV, "").strip()
    if not value:
        return DEFAULT_SPIN_S
    try:
        ms = float(value)
    except ValueError:
        ms = math.nan
    if not 0.0 <= ms < math.inf:
        from trainer.errors import ConfigError

        raise ConfigError(f"{SPIN_WAIT_ENV}={value!r} is not a number of milliseconds >= 0; "
                          f"use e.g. {SPIN_WAIT_ENV}=1, or 0 to always sleep while waiting.")
    return ms / 1e3


def spin_budget(processes: int) -> float:
    """``configured_spin()`` if each of ``processes`` busy processes (the trainer and its
    simulators) has a CPU of its own, else 0: polling on a shared CPU would take it from the
    process we wait for."""
    return configured_spin() if usable_cpus() >= processes else 0.0
