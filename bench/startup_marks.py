"""Start-up marks with CPU-seconds (run by hand, not a test): usable on a loaded machine, where
bench/startup.py's wall times are not.

    PYTHONPATH=<tree> .venv/bin/python bench/startup_marks.py run <mlagents-like-learn arguments>
    .venv/bin/python bench/startup_marks.py gil [--preload]

``run``: runs the trainer's ``main`` in this process and prints, at the pool's launch, its
handshake (connect) and the first ``send_step``, the wall time since this script started and the
process's CPU-seconds (getrusage: the main thread's and the background import's together). The
pool is patched as soon as trainer/envs/pool.py has been imported, so the import order before the
launch is the trainer's own. ``PYTHONPATH`` chooses the tree (an A/B of two commits).

``gil``: how long a thread importing torch keeps the main thread from running: the main thread
ticks every 1 ms while another thread imports torch; prints the longest gaps. ``--preload`` loads
torch's libraries first as trainer/warmup.py does (a dlopen through ctypes, without the GIL).
"""
from __future__ import annotations

import builtins
import resource
import sys
import threading
import time

STARTED = time.time()


def mark(name: str) -> None:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(f"mark {name}: wall {time.time() - STARTED:.3f} s, cpu {usage.ru_utime + usage.ru_stime:.3f} s",
          file=sys.stderr, flush=True)


def patch_pool(pool) -> None:
    launch, connect, send_step = pool.EnvPool.launch, pool.EnvPool.connect, pool.EnvPool.send_step
    sent = []

    def timed_launch(self, *args, **kwargs):
        mark("launch")
        return launch(self, *args, **kwargs)

    def timed_connect(self, *args, **kwargs):
        result = connect(self, *args, **kwargs)
        mark("connected")
        return result

    def timed_send_step(self, *args, **kwargs):
        result = send_step(self, *args, **kwargs)
        if not sent:
            sent.append(True)
            mark("first step")
        return result

    pool.EnvPool.launch, pool.EnvPool.connect, pool.EnvPool.send_step = timed_launch, timed_connect, timed_send_step


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
