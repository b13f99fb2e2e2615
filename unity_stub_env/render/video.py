"""Frames to a file: ``.mp4`` as H.264 through imageio-ffmpeg (its wheel ships the ffmpeg binary),
``.gif`` through Pillow (also the encoder of the animated images the trainer puts in TensorBoard),
and the caption drawn on each frame."""
from __future__ import annotations

import functools
import io
import os
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
    """Append frames, then ``close``: the file appears complete (written beside, then renamed)."""

    def __init__(self, path: str, fps: float) -> None:
        self.path, self.fps, self.suffix = path, fps, check_output(path)
        self.partial = str(Path(path).with_name(f".{Path(path).stem}.partial{self.suffix}"))
        self.frames: list[np.ndarray] = []
        self.writer = None
        self.count = 0

    def append(self, frame: np.ndarray) -> None:
        self.count += 1
        if self.suffix == ".gif":
            self.frames.append(frame)
            return
        if self.writer is None:
            import imageio.v2 as imageio

            self.writer = imageio.get_writer(self.partial, format="FFMPEG", mode="I", fps=self.fps, codec="libx264",
                                             pixelformat="yuv420p", macro_block_size=2, quality=7,
                                             ffmpeg_log_level="error",
                                             # half the encoder's CPU of its default preset (medium)
                                             # for a file of about the same size at a clip's sizes
                                             output_params=["-preset", "veryfast"])
        self.writer.append_data(frame)

    def close(self) -> None:
        if self.suffix == ".gif":
            if not self.frames:
                return
            Path(self.partial).write_bytes(gif_bytes(self.frames, self.fps))
        elif self.writer is not None:
            self.writer.close()
        else:
            return
        os.replace(self.partial, self.path)
