"""Named moments where a test can make the trainer die as if by ``kill -9``.

``MLAGENTS_LIKE_CRASH_AT=POINT:N`` (trainer/config/env_vars.py) arms one point: the Nth time the
trainer reaches it, it sends itself SIGKILL, so nothing runs afterwards (no handler, no ``finally``,
no flush), exactly as when a node dies or the OOM killer strikes. ``POINT:N:SIGTERM`` (or another
signal name) sends that signal instead, which lands in the middle of what follows the point (an
update, a checkpoint write): the way to test that a stop request there still ends with a loadable
checkpoint. ``POINT:N:SIGSTOP`` freezes the trainer there (it cannot be handled): a test then
kills the trainer and its simulators at once, as a node failure, at a moment known in steps
rather than in wall-clock time (tests/slurm/test_train_sbatch.py). Unarmed, ``reached`` costs one comparison. tests/integration/test_kill_and_resume.py walks these points to prove that
``--resume`` always finds the newest complete checkpoint (docs/reliability.md).
"""
from __future__ import annotations

import os
import signal

POINTS = (
    "act",               # before a batched forward pass (acting)
    "update",            # before a PPO update
    "update.done",       # right after a PPO update, before anything is written
    "checkpoint.pt",     # <Brain>-<step>.pt written, nothing else of this checkpoint yet
    "checkpoint.onnx",   # ... and <Brain>-<step>.onnx
    "checkpoint.latest", # ... and checkpoint.pt; training_status.json not yet
    "checkpoint.status", # ... and training_status.json: the checkpoint is complete
    "atomic.replace",    # a temp file written and fsynced, not yet renamed onto its target
)

_armed: tuple | None = None
_seen = 0


def arm(crash_at: tuple | None) -> None:
    """Arm (point, occurrence[, signal name]), or disarm with None."""
    global _armed, _seen
    _armed, _seen = crash_at, 0


def reached(point: str) -> None:
    """SIGKILL this process if ``point`` is armed and this is its Nth occurrence."""
    global _seen
    if _armed is None or _armed[0] != point:
        return
    _seen += 1
    if _seen == _armed[1]:
        os.kill(os.getpid(), getattr(signal, _armed[2]) if len(_armed) > 2 else signal.SIGKILL)
