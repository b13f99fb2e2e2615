"""The heavy imports, in a background thread started once the simulators are launched and the
main thread begins to wait for their handshake (trainer/run.py).

Importing torch takes seconds on a small machine, longer than the stub (0.3 s) or a small Unity
build takes to boot and connect. Imported in the main thread before the handshake, it made the
simulator wait for the trainer (docs/performance.md, "Start-up and exit"). Imported here, it overlaps
with the rest of the simulator's boot, the handshake and the first RESET, which the main thread
does meanwhile (waiting on sockets mostly, which releases the GIL). The main
thread then simply imports what it needs: Python's import lock makes it wait for a module this
thread is still importing, and an import that failed here is tried again there, so its error is
raised where it always was.

The ONNX exporter is imported last: only the first checkpoint or the end of the run needs it, and
the main thread spends most of a run waiting for the simulators (``env.wait``).

torch's native libraries are loaded first, by a dlopen called through ctypes: a foreign call runs
without the GIL, whereas Python's own loading of an extension module (``import torch._C``) holds
it while the dynamic loader maps and initialises libtorch. Held, that stopped the main thread for
0.4-0.7 s at a time, and when that fell on the handshake it delayed the first actions; loaded this
way the longest stop measured 0.09-0.13 s. ``import torch`` then finds the libraries loaded.
Without the GIL, though, the load does not stop an exit either: a process that left by
interpreter finalization during it (an uncaught exception in the first second) ran libtorch's
static destructors while its constructors still ran, and aborted. So an exit waits for the load.
"""
from __future__ import annotations

import atexit
import ctypes
import importlib
import importlib.util
import os
import threading

# in the order the run needs them: torch and the networks for the first action, then the exporter
MODULES = ("torch", "trainer.behavior", "trainer.artifacts.onnx_export", "onnx")


_started: list[threading.Thread] = []
# held while torch's libraries load; taken at exit, so that an exit waits for the load to end (and
# no load starts after it)
_loading_libraries = threading.Lock()
atexit.register(_loading_libraries.acquire)


def finished() -> bool:
    """Whether the background imports are over (True if they were never started)."""
    return not any(thread.is_alive() for thread in _started)


def load_torch_libraries() -> None:
    """dlopen torch's Python binding library (and with it libtorch, libc10) without the GIL;
    RTLD_LOCAL, as ``import torch._C`` loads it. A layout other than the Linux wheel's, or any
    failure, leaves the loading to ``import torch``."""
    try:
        spec = importlib.util.find_spec("torch")  # finds the package without importing it
        folder = os.path.join(spec.submodule_search_locations[0], "lib")
        library = os.path.join(folder, "libtorch_python.so")
        if not os.path.isfile(library):
            return
        dlopen = ctypes.CDLL(None).dlopen
        dlopen.restype, dlopen.argtypes = ctypes.c_void_p, [ctypes.c_char_p, ctypes.c_int]
        dlopen(os.fsencode(library), os.RTLD_NOW | os.RTLD_LOCAL)
    except (AttributeError, OSError, TypeError, ValueError):
        return


def start(modules: tuple[str, ...] = MODULES) -> threading.Thread:
    """Import ``modules`` one after another in a daemon thread (errors are left to the main
    thread's own import of the same module)."""

    def run() -> None:
        if "torch" in modules:
            with _loading_libraries:
                load_torch_libraries()
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - the main thread's import raises it again, where it is handled
                return

    thread = threading.Thread(target=run, name="mlagents-like-warmup", daemon=True)
    thread.start()
    _started.append(thread)
    return thread
