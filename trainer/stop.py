"""Stop requests from signals, acted on at safe points of the training loop.

SIGINT, SIGTERM, SIGQUIT and SIGUSR1 (what Slurm sends before a time limit) all ask the trainer
to stop like Ctrl-C: finish the final checkpoint and ONNX, then exit with ``EXIT_STOPPED`` (75)
when a behavior had not reached its max_steps yet, so a batch script knows to requeue the run
(docs/cluster.md); 0 when training was complete anyway, or in --inference. The handler only records
the request; the trainer raises ``GracefulStop`` itself where that is safe (between steps and
while it waits for a simulator), never in the middle of a write, a lock or a half-read message.
So a signal that lands while the final checkpoint is being written does not cut that write
short: a second signal is reported and otherwise ignored; a third one stops at once (the final
checkpoint may then be missing).
"""
from __future__ import annotations

import os
import signal

SIGNALS = ("SIGINT", "SIGTERM", "SIGQUIT", "SIGUSR1")
HARD_STOP_AFTER = 3  # signals; the last one raises where it lands
# Exit status of a run that a stop signal ended before max_steps, after its final checkpoint:
# "unfinished, resume me". 75 is EX_TEMPFAIL of sysexits.h (a temporary failure; retry later).
EXIT_STOPPED = 75


class GracefulStop(KeyboardInterrupt):
    """Raised in the main thread at a safe point after a stop signal; handled like Ctrl-C."""


class StopRequests:
    def __init__(self) -> None:
        self.requested: str | None = None  # name of the first signal received
        self.received = 0
        self.raised = False
        # data-parallel ranks (trainer/distributed.py): ``check`` leaves the stop to the ranks'
        # agreement, so that all of them stop at the same exchange
        self.deferred = False

    def install(self) -> None:
        """Route the stop signals here (main thread only)."""
        # SIGINT too: a trainer started from a script in the background inherits SIGINT as
        # ignored, and would then not stop on kill -INT
        for name in SIGNALS:
            sig = getattr(signal, name, None)
            if sig is not None:
                signal.signal(sig, self.handle)

    def handle(self, signum: int, _frame=None) -> None:
        name = signal.Signals(signum).name
        self.received += 1
        if self.requested is None:
            self.requested = name
            return
        if self.received >= HARD_STOP_AFTER:
            raise GracefulStop(name)
        # not the logging module: its handler lock may be held by the code this interrupted
        os.write(2, (f"\n{name}: already stopping, the final checkpoint is being written; "
                     "send it once more to quit without waiting.\n").encode())

    def check(self) -> None:
        """Raise GracefulStop once, at a safe point, if a stop was requested."""
        if self.requested is not None and not self.raised and not self.deferred:
            self.raised = True
            raise GracefulStop(self.requested)

    def reset(self) -> None:
        self.requested, self.received, self.raised, self.deferred = None, 0, False, False


# One per process, like the signal handlers themselves; the trainer's wait loops consult it.
STOP = StopRequests()
