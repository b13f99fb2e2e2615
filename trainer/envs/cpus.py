"""How the trainer and the simulators it launches share the machine's CPUs.

Pacing (``protos/pacing.py``) polls instead of sleeping while it waits for the peer; that only
pays when every busy process of the run (the trainer and each simulator) has a CPU of its own,
which ``spin_budget`` decides once per run. The same affinity count decides whether the PPO
update may fork a process of its own.
"""
from __future__ import annotations

import os


def usable_cpus() -> int:
    """CPUs this process may run on (the affinity mask: a Slurm allocation, taskset)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def spin_budget(processes: int, spin_s: float) -> float:
    """``spin_s`` (MLAGENTS_LIKE_SPIN_WAIT_MS: trainer.config.env_vars) if each of ``processes``
    busy processes (the trainer and its simulators) has a CPU of its own, else 0: polling on a
    shared CPU would take it from the process we wait for."""
    return spin_s if usable_cpus() >= processes else 0.0
