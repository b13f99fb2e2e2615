"""``--record-video`` (``--env stub:TASK`` only): after each checkpoint, a clip of its ONNX.

The stub renders it (``unity-stub-env --task TASK --play BEHAVIOR-STEP.onnx --video ...
--tensorboard ...``) in a background process at nice 19, one at a time (a checkpoint that comes
while the previous clip is still being made gets none), so training keeps its CPU
(bench/record_video.py measures the cost). The clip goes next to the model as
``<Behavior>-<step>.mp4``; the same frames go into TensorBoard as an animated image under
``<run>/<Behavior>/clips`` (tag ``<Behavior>/clip``, step = the checkpoint's), beside the curves."""
from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

logger = logging.getLogger(__name__)
SECONDS = 10.0
FPS = 20.0
SIZE = (320, 240)


def lowest_priority() -> None:
    """In the clip's process before it starts: nice 19. (Not Linux's SCHED_IDLE: on a saturated
    machine it starved the clip until keep_checkpoints had deleted its model, or past the run.)"""
    os.nice(19)


class ClipRecorder:
    def __init__(self, task: str, seed: int) -> None:
        self.task, self.seed = task, seed
        self.process: subprocess.Popen | None = None
        self.log = None
        self.model: Path | None = None

    @staticmethod
    def for_env(env_path: str | None, seed: int) -> "ClipRecorder | None":
        """The recorder of a ``stub:TASK`` run; None (with a warning) for any other environment."""
        if env_path and env_path.startswith("stub:") and "=" not in env_path:
            return ClipRecorder(env_path[len("stub:"):].split(",")[0], seed)
        logger.warning("--record-video films the stub's tasks only (--env stub:TASK); no clips for %s.",
                       env_path or "the Editor")
        return None

    def busy(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def after_checkpoint(self, brain: str, onnx_path: str, step: int) -> bool:
        """Start the clip of ``onnx_path``; False when the previous one is still running."""
        if self.busy():
            logger.info("--record-video: the previous clip is still being made; none for %s step %d.", brain, step)
            return False
        self.close_log()
        folder = Path(onnx_path).parent
        video = folder / f"{brain}-{step}.mp4"
        # a copy: keep_checkpoints may delete the model before the idle-priority process reads it
        (folder / "clips").mkdir(exist_ok=True)
        self.model = folder / "clips" / f".{brain}-{step}.onnx"
        shutil.copyfile(onnx_path, self.model)
        command = [sys.executable, "-m", "unity_stub_env.cli", "--task", self.task, "--play", str(self.model),
                   "--video", str(video), "--seconds", f"{SECONDS:g}", "--fps", f"{FPS:g}",
                   "--width", str(SIZE[0]), "--height", str(SIZE[1]), "--antialias", "0", "--seed", str(self.seed),
                   "--tensorboard", str(folder / "clips"), "--tensorboard-tag", f"{brain}/clip",
                   "--tensorboard-step", str(step)]
        self.log = open(folder / "clips.log", "a")
        self.process = subprocess.Popen(command, stdout=self.log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        preexec_fn=lowest_priority)
        return True

    def close_log(self) -> None:
        """After a clip: its log closed, its copy of the model gone."""
        if self.log is not None:
            self.log.close()
            self.log = None
        if self.model is not None:
            self.model.unlink(missing_ok=True)
            self.model = None

    def finish(self, timeout: float = 300.0) -> None:
        """At the end of the run: let the last clip finish (its checkpoint is the final model)."""
        if self.process is not None:
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.close_log()
