"""``--record-video`` (``--env stub:TASK`` only): clips of the checkpoints' ONNX, within a CPU budget.

The stub films them: one renderer process per run (``python -m unity_stub_env.render.clip_server``,
nice 19, started at the first clip) takes one request at a time. A clip goes next to the model as
``<Behavior>-<step>.mp4``; the same frames go into TensorBoard as an animated image under
``<run>/<Behavior>/clips`` (tag ``<Behavior>/clip``, step = the checkpoint's), beside the curves.
The clip plays the run's environment parameters (their current lessons) and the stub options of
``--env-args``.

The budget (docs/video.md, "Clips while training"): on 2 cores the trainer and the simulator use
both, so a clip's CPU time is taken from training even at nice 19. A checkpoint before the last
gets a clip only when the renderer is idle and

    spent + estimate <= CPU_SHARE x CPUs x elapsed

spent: the renderer's CPU seconds so far (its start-up included), as it reports them; estimate: the
last clip's CPU seconds (FIRST_ESTIMATE before the first); elapsed: wall seconds since the run
started; CPUs: the cores this process may use. So the clips' CPU stays within the share however
often checkpoints come (bench/record_video.py measures the slowdown). The final checkpoint's clip
is always made, after the previous one if need be: training is over by then.
"""
from __future__ import annotations

import json
import logging
import os
import queue
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Sequence

from trainer.envs.cpus import usable_cpus

logger = logging.getLogger("mlagents_like")  # the run's console and log
SECONDS = 10.0
FPS = 20.0
SIZE = (320, 240)
CPU_SHARE = 0.04  # of the machine's CPU time while training, under docs/video.md's 5 % slowdown
# before the first clip's cost is known: the renderer's start-up and a first clip of the dearest
# task, mimic (~5 CPU-s; ball3d and creature ~3; measured with the clip server's answers)
FIRST_ESTIMATE = 5.0
RENDERER = [sys.executable, "-m", "unity_stub_env.render.clip_server"]


def within_budget(spent: float, estimate: float, elapsed: float, cpus: int, share: float = CPU_SHARE) -> bool:
    """Whether a clip expected to cost ``estimate`` CPU seconds may start now (the module's rule)."""
    return spent + estimate <= share * cpus * elapsed


def lowest_priority() -> None:
    """In the renderer's process before it starts: nice 19. (Not Linux's SCHED_IDLE: on a saturated
    machine it starved the clip until keep_checkpoints had deleted its model, or past the run.)"""
    os.nice(19)


class ClipRecorder:
    """Decides which checkpoints get a clip and hands them to the renderer process.

    ``side_channel``: the environment-parameter messages the simulators get now (bytes);
    ``stub_args``: the run's --env-args; ``clock``, ``cpus``, ``renderer``, ``first_estimate``: for tests."""

    def __init__(self, task: str, seed: int, log_path: str, side_channel: Callable[[], bytes] = bytes,
                 stub_args: Sequence[str] = (), clock: Callable[[], float] = time.monotonic,
                 cpus: int | None = None, renderer: Sequence[str] = RENDERER,
                 first_estimate: float = FIRST_ESTIMATE) -> None:
        self.task, self.seed, self.log_path = task, seed, log_path
        self.side_channel, self.stub_args = side_channel, list(stub_args)
        self.clock, self.cpus, self.renderer = clock, cpus or usable_cpus(), list(renderer)
        self.started = clock()
        self.spent, self.estimate = 0.0, first_estimate
        self.process: subprocess.Popen | None = None
        self.log = None
        self.answers: queue.Queue = queue.Queue()
        self.in_flight: dict | None = None  # the request being filmed
        self.waiting: list[dict] = []  # final checkpoints that came while a clip was being made
        self.broken = False
        self.told_budget = False
        self.asked = self.skipped = 0  # checkpoints that asked for a clip / got none
        self.training: tuple[float, float] | None = None  # (CPU-s spent, s elapsed) at the final checkpoint

    @staticmethod
    def for_env(env_path: str | None, seed: int, run_dir: str, side_channel: Callable[[], bytes] = bytes,
                stub_args: Sequence[str] = ()) -> "ClipRecorder | None":
        """The recorder of a ``stub:TASK`` run; None (with a warning) for any other environment."""
        if env_path and env_path.startswith("stub:") and "=" not in env_path:
            return ClipRecorder(env_path[len("stub:"):].split(",")[0], seed,
                                os.path.join(run_dir, "run_logs", "clips.log"), side_channel, stub_args)
        logger.warning("--record-video films the stub's tasks only (--env stub:TASK); no clips for %s.",
                       env_path or "the Editor")
        return None

    # ------------------------------------------------------------------ the decision
    def busy(self) -> bool:
        self._collect()
        return self.in_flight is not None

    def after_checkpoint(self, brain: str, onnx_path: str, step: int, final: bool = False) -> bool:
        """Ask for the clip of ``onnx_path``; False when it gets none (the renderer is busy, or the
        budget is spent; a final checkpoint waits for the renderer instead)."""
        self.asked += 1
        if self.broken:
            self.skipped += 1
            return False
        busy = self.busy()
        if final and self.training is None:
            self.training = (self.spent, self.clock() - self.started)
        if not final:
            elapsed = self.clock() - self.started
            if not within_budget(self.spent, self.estimate, elapsed, self.cpus):
                if not self.told_budget:
                    self.told_budget = True
                    logger.info("--record-video: clips are kept within %g %% of the CPU time (docs/video.md); "
                                "checkpoints are filmed as that allows, the final one always.", 100 * CPU_SHARE)
                logger.debug("--record-video: no clip for %s step %d (%.1f CPU-s spent, next ~%.1f, %.0f s in).",
                             brain, step, self.spent, self.estimate, elapsed)
                self.skipped += 1
                return False
            if busy:
                logger.info("--record-video: the previous clip is still being made; none for %s step %d.",
                            brain, step)
                self.skipped += 1
                return False
        request = self._request(brain, onnx_path, step)
        if busy:
            self.waiting.append(request)
        else:
            self._send(request)
        return True

    # ------------------------------------------------------------------ the renderer
    def _request(self, brain: str, onnx_path: str, step: int) -> dict:
        folder = Path(onnx_path).parent
        (folder / "clips").mkdir(exist_ok=True)
        # a copy: keep_checkpoints may delete the model before the nice-19 renderer reads it
        model = folder / "clips" / f"{brain}-{step}.onnx"  # (its name is the clip's caption)
        shutil.copyfile(onnx_path, model)
        return {"task": self.task, "policy": str(model), "video": str(folder / f"{brain}-{step}.mp4"),
                "seconds": SECONDS, "fps": FPS, "width": SIZE[0], "height": SIZE[1], "samples": 0,
                "seed": self.seed, "tensorboard": [str(folder / "clips"), f"{brain}/clip", step],
                "side_channel": self.side_channel().hex(), "stub_args": self.stub_args}

    def _start(self) -> None:
        os.makedirs(os.path.dirname(self.log_path), exist_ok=True)
        self.log = open(self.log_path, "a")
        self.process = subprocess.Popen(self.renderer, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=self.log, text=True, bufsize=1, preexec_fn=lowest_priority)
        threading.Thread(target=self._read, args=(self.process.stdout,), name="clip-answers", daemon=True).start()

    def _read(self, stream) -> None:
        for line in stream:
            try:
                self.answers.put(json.loads(line))
            except ValueError:  # not an answer: the log has the renderer's output
                pass
        self.answers.put(None)  # the renderer exited

    def _send(self, request: dict) -> None:
        if self.process is None:
            self._start()
        try:
            self.process.stdin.write(json.dumps(request) + "\n")
            self.process.stdin.flush()
        except OSError:  # the renderer is gone; its answer queue says so
            pass
        self.in_flight = request

    def _collect(self, timeout: float = 0.0) -> None:
        """Take the renderer's answers; with ``timeout``, wait up to that long for one."""
        while self.in_flight is not None:
            try:
                answer = self.answers.get(timeout=timeout) if timeout > 0 else self.answers.get_nowait()
            except queue.Empty:
                return
            timeout = 0.0
            Path(self.in_flight["policy"]).unlink(missing_ok=True)
            if answer is None:
                self.broken, self.in_flight = True, None
                for request in self.waiting:
                    Path(request["policy"]).unlink(missing_ok=True)
                self.waiting = []
                logger.warning("--record-video: the clip renderer stopped; no more clips (see %s).", self.log_path)
                return
            self.spent, self.estimate = float(answer["cpu"]), float(answer["clip_cpu"])
            if not answer["ok"]:
                logger.warning("--record-video: %s", answer["message"])
            self.in_flight = None
            if self.waiting:
                self._send(self.waiting.pop(0))

    def wait_idle(self, timeout: float) -> bool:
        """Wait until every requested clip is made (True) or ``timeout`` s have passed (False)."""
        deadline = time.monotonic() + timeout
        while self.in_flight is not None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            self._collect(timeout=remaining)
        return True

    def finish(self, timeout: float = 300.0) -> None:
        """At the end of the run: let the clips asked for finish (the last is the final model's),
        then end the renderer."""
        if self.process is None:
            return
        spent, elapsed = self.training or (self.spent, self.clock() - self.started)
        done = self.wait_idle(timeout)
        # the share of the clips finished while training (the final clip comes after it)
        logger.info("--record-video: %d of %d checkpoints filmed; the clips finished while training used %.1f CPU-s, "
                    "%.1f %% of %d CPUs over %.0f s (%.1f CPU-s in all).", self.asked - self.skipped, self.asked,
                    spent, 100 * spent / max(elapsed * self.cpus, 1e-9), self.cpus, elapsed, self.spent)
        try:
            self.process.stdin.close()
        except OSError:
            pass
        try:
            self.process.wait(10.0 if done else 0.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        for request in [*([self.in_flight] if self.in_flight else []), *self.waiting]:
            Path(request["policy"]).unlink(missing_ok=True)
        self.log.close()
