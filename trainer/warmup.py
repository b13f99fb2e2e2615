"""The heavy imports, in a background thread started as soon as the simulators are launched.

Importing torch takes seconds on a small machine, longer than the stub (0.3 s) or a small Unity
build takes to boot and connect. Imported in the main thread before the handshake, it made the
simulator wait for the trainer (docs/performance.md, "Start-up and exit"). Imported here, it overlaps
with the simulator's boot, the handshake, the first RESET and the results folder's set-up, which
the main thread does meanwhile (waiting on sockets mostly, which releases the GIL). The main
thread then simply imports what it needs: Python's import lock makes it wait for a module this
thread is still importing, and an import that failed here is tried again there, so its error is
raised where it always was.

The ONNX exporter is imported last: only the first checkpoint or the end of the run needs it, and
the main thread spends most of a run waiting for the simulators (``env.wait``).
"""
from __future__ import annotations

import importlib
import threading

# in the order the run needs them: torch and the networks for the first action, then the exporter
MODULES = ("torch", "trainer.behavior", "trainer.artifacts.onnx_export", "onnx")


_started: list[threading.Thread] = []


def finished() -> bool:
    """Whether the background imports are over (True if they were never started)."""
    return not any(thread.is_alive() for thread in _started)


def start(modules: tuple[str, ...] = MODULES) -> threading.Thread:
    """Import ``modules`` one after another in a daemon thread (errors are left to the main
    thread's own import of the same module)."""

    def run() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - the main thread's import raises it again, where it is handled
                return

    thread = threading.Thread(target=run, name="mlagents-like-warmup", daemon=True)
    thread.start()
    _started.append(thread)
    return thread
