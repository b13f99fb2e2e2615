"""Start-up marks with CPU-seconds (run by hand, not a test): usable on a loaded machine, where
bench/startup.py's wall times are not.

    PYTHONPATH=<tree> .venv/bin/python bench/startup_marks.py run <mlagents-like-learn arguments>
    .venv/bin/python bench/startup_marks.py gil [--preload]

``run``: runs the trainer's ``main`` in this process and prints, at the pool's launch, the call
of its handshake (``wait``: the main thread is ready for the simulator), the handshake's end
(``connected``), the first RESET's answer (``reset``) and the first ``send_step``, the wall time
since this script started, the process's CPU-seconds (getrusage: the main thread's and the
background import's together) and the main thread's alone; at the end, the simulator's own
"Connected to trainer" line (its log, Player-0.log, under --results-dir) in the same clock. The
pool is patched as soon as trainer/envs/pool.py has been imported, so the import order before the
launch is the trainer's own. ``PYTHONPATH`` chooses the tree (an A/B of two commits).

``gil``: how long a thread importing torch keeps the main thread from running: the main thread
ticks every 1 ms while another thread imports torch; prints the longest gaps. ``--preload`` loads
torch's libraries first as trainer/warmup.py does (a dlopen through ctypes, without the GIL).
"""
from __future__ import annotations

import builtins
import glob
import os
import resource
import sys
import threading
import time
from datetime import datetime

STARTED = time.time()


def cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def mark(name: str) -> None:
    print(f"mark {name}: wall {time.time() - STARTED:.3f} s, cpu {cpu(resource.RUSAGE_SELF):.3f} s, "
          f"main thread {cpu(resource.RUSAGE_THREAD):.3f} s", file=sys.stderr, flush=True)


def simulator_marks(argv: list[str]) -> None:
    """The stub's own "Connected to trainer" line, in this script's clock (its log's asctime)."""
    results = argv[argv.index("--results-dir") + 1] if "--results-dir" in argv else "results"
    for log in sorted(glob.glob(os.path.join(results, "*", "run_logs", "Player-*.log"))):
        for line in open(log, errors="replace"):
            if "Connected to trainer" in line:
                when = datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f").timestamp()
                print(f"mark simulator connected ({os.path.basename(log)}): wall {when - STARTED:.3f} s",
                      file=sys.stderr, flush=True)
                break


def patch_pool(pool) -> None:
    launch, connect, send_step = pool.EnvPool.launch, pool.EnvPool.connect, pool.EnvPool.send_step
    reset = pool.EnvPool.reset
    sent = []

    def timed_launch(self, *args, **kwargs):
        mark("launch")
        return launch(self, *args, **kwargs)

    def timed_connect(self, *args, **kwargs):
        mark("wait")
        result = connect(self, *args, **kwargs)
        mark("connected")
        return result

    def timed_reset(self, *args, **kwargs):
        result = reset(self, *args, **kwargs)
        if not sent:
            mark("reset")
        return result

    def timed_send_step(self, *args, **kwargs):
        result = send_step(self, *args, **kwargs)
        if not sent:
            sent.append(True)
            mark("first step")
        return result

    pool.EnvPool.launch, pool.EnvPool.connect, pool.EnvPool.send_step = timed_launch, timed_connect, timed_send_step
    pool.EnvPool.reset = timed_reset


def run(argv: list[str]) -> int:
    original_import = builtins.__import__
    patched = []

    def watching_import(*args, **kwargs):
        module = original_import(*args, **kwargs)
        pool = sys.modules.get("trainer.envs.pool")
        if not patched and hasattr(pool, "EnvPool"):  # fully imported (the imports it was inside go on)
            patched.append(True)
            builtins.__import__ = original_import
            patch_pool(pool)
        return module

    builtins.__import__ = watching_import
    from trainer.cli import main

    code = main(argv)
    mark("end")
    simulator_marks(argv)
    return code


def gil(preload: bool) -> int:
    def work() -> None:
        if preload:
            from trainer.warmup import load_torch_libraries

            load_torch_libraries()
        import torch  # noqa: F401

    thread = threading.Thread(target=work)
    thread.start()
    gaps, last = [], time.perf_counter()
    while thread.is_alive():
        time.sleep(0.001)
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    gaps.sort()
    print(f"preload {preload}: longest gaps {[round(g, 3) for g in gaps[-5:]]} s, "
          f"sum of gaps > 20 ms {sum(g for g in gaps if g > 0.02):.3f} s")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["run"]:
        sys.exit(run(sys.argv[2:]))
    if sys.argv[1:2] == ["gil"]:
        sys.exit(gil("--preload" in sys.argv))
    print(__doc__)
    sys.exit(2)
