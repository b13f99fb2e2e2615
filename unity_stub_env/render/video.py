"""Frames to a file: ``.mp4`` as H.264 by the ffmpeg binary that imageio-ffmpeg's wheel ships,
``.gif`` through Pillow (also the encoder of the animated images the trainer puts in TensorBoard),
and the caption drawn on each frame."""
from __future__ import annotations

import functools
import io
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from unity_stub_env.render import RenderError

FORMATS = (".mp4", ".gif")


def check_output(path: str) -> str:
    """The output's format (``.mp4`` or ``.gif``); RenderError for another extension or a place that
    cannot be written, before any frame is drawn."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise RenderError(f"--video {path!r}: the file name must end in .mp4 (H.264) or .gif")
    folder = Path(path).parent
    if not folder.is_dir():
        raise RenderError(f"--video {path!r}: the folder {str(folder)!r} does not exist; create it first")
    probe = folder / f".{Path(path).name}.probe"
    try:  # a real write: permissions, read-only mounts and pseudo file systems all answer it
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        raise RenderError(f"--video {path!r}: cannot write there ({error.strerror}); choose another file") from None
    if Path(path).is_dir():
        raise RenderError(f"--video {path!r} is a folder; give a file name ending in .mp4 or .gif")
    return suffix


def caption(frame: np.ndarray, text: str) -> np.ndarray:
    """The frame with ``text`` in a small dark box at its top left."""
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    font = _font(max(10, frame.shape[0] // 32))
    left, top, right, bottom = draw.textbbox((6, 4), text, font=font)
    draw.rectangle((left - 4, top - 3, right + 4, bottom + 3), fill=(0, 0, 0))
    draw.text((6, 4), text, fill=(255, 255, 255), font=font)
    return np.asarray(image)


@functools.lru_cache(maxsize=8)
def _font(size: int):
    """Pillow's default font at ``size``, loaded once: loading it is most of a caption's cost."""
    return ImageFont.load_default(size=size)


def gif_bytes(frames: list[np.ndarray], fps: float) -> bytes:
    """An endlessly looping animated GIF of ``frames``. Each frame gets its own 256-colour palette by
    Pillow's fast octree (a tenth of the CPU of its default median cut, which Pillow uses for RGB
    frames otherwise; the pictures look the same at a clip's sizes)."""
    images = [Image.fromarray(f).quantize(256, method=Image.Quantize.FASTOCTREE) for f in frames]
    buffer = io.BytesIO()
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:], loop=0,
                   duration=max(20, int(round(1000 / fps))), optimize=False)
    return buffer.getvalue()


class VideoWriter:
    """Append frames, then ``close``: the file appears complete (written beside, then renamed) or
    not at all. ``.mp4`` frames go to ffmpeg's stdin (imageio-ffmpeg's binary) in a process
    started here rather than through imageio's writer, which neither checks ffmpeg's exit status
    nor keeps its message: a disk that filled mid-clip published a truncated clip without an
    error, and one full from the start gave only a BrokenPipeError (docs/video.md, "A policy playing
    a task": its errors)."""

    def __init__(self, path: str, fps: float) -> None:
        self.path, self.fps, self.suffix = path, fps, check_output(path)
        self.partial = str(Path(path).with_name(f".{Path(path).stem}.partial{self.suffix}"))
        self.frames: list[np.ndarray] = []
        self.process: subprocess.Popen | None = None
        self.messages = None  # ffmpeg's stderr: a file, so a chatty ffmpeg cannot fill a pipe and stall
        self.count = 0

    def append(self, frame: np.ndarray) -> None:
        self.count += 1
        if self.suffix == ".gif":
            self.frames.append(frame)
            return
        if self.process is None:
            self._start(frame.shape[1], frame.shape[0])
        try:
            self.process.stdin.write(np.ascontiguousarray(frame, dtype=np.uint8).data)
        except BrokenPipeError:  # ffmpeg has stopped: its exit status and message say why
            self._fail()

    def close(self) -> None:
        if self.suffix == ".gif":
            if not self.frames:
                return
            Path(self.partial).write_bytes(gif_bytes(self.frames, self.fps))
        elif self.process is not None:
            try:
                self.process.stdin.close()  # end of input: ffmpeg writes the trailer and exits
            except BrokenPipeError:
                pass
            if self.process.wait() != 0:
                self._fail()
            self.messages.close()
        else:
            return
        os.replace(self.partial, self.path)

    def _start(self, width: int, height: int) -> None:
        import imageio_ffmpeg

        command = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-v", "error",
                   "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", f"{self.fps:g}", "-i", "-",
                   "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "15",
                   # half the encoder's CPU of its default preset (medium) for a file of about
                   # the same size at a clip's sizes
                   "-preset", "veryfast"]
        if width % 2 or height % 2:  # yuv420p needs even sides: one more pixel, as players expect
            command += ["-vf", f"scale={width + width % 2}:{height + height % 2}"]
        self.messages = tempfile.TemporaryFile()
        # its own process group: a Ctrl-C meant for the trainer does not cut the clip short
        self.process = subprocess.Popen(command + [self.partial], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                        stderr=self.messages, start_new_session=True)

    def _fail(self) -> None:
        """ffmpeg stopped early or failed: no clip is left behind, and the error says why."""
        try:
            self.process.stdin.close()
        except BrokenPipeError:
            pass
        status = self.process.wait()
        self.process = None  # close() after this (a caller's finally) has nothing to publish
        self.messages.seek(0)
        said = self.messages.read().decode(errors="replace").strip().splitlines()
        self.messages.close()
        Path(self.partial).unlink(missing_ok=True)
        folder = str(Path(self.path).parent) or "."
        free = shutil.disk_usage(folder).free / 2**20 if os.path.isdir(folder) else 0.0
        raise RenderError(f"--video {self.path!r}: ffmpeg stopped with exit status {status} after "
                          f"{self.count} frames ({free:.0f} MB free in {folder!r}): "
                          + (" / ".join(dict.fromkeys([said[0], said[-1]])) if said else "it printed no reason"))
