"""A clip as a TensorBoard animated image: a GIF in an image summary (TensorBoard's Images tab plays
it), written with tensorboard's own event writer to an event file of its own in ``folder``.

``unity-stub-env --play MODEL.onnx --video FILE --tensorboard DIR --tensorboard-step N`` writes
one; mlagents-like-learn --record-video points DIR at ``results/<run-id>/<Behavior>/clips`` (a
folder of its own: TensorBoard reads the event files of one folder one after another, so a second
writer beside the trainer's file would hide the trainer's later summaries)."""
from __future__ import annotations

import time

import numpy as np
from PIL import Image

from unity_stub_env.render.video import gif_bytes

GIF_EVERY = 2  # every second frame of the clip ...
GIF_SCALE = 0.5  # ... at half its size: a 10 s clip is ~1-2 MB in the event file, not ~10


class GifFrames:
    """Collects the frames of the GIF while the clip is filmed (``film``'s on_frame)."""

    def __init__(self) -> None:
        self.frames: list[np.ndarray] = []

    def __call__(self, index: int, frame: np.ndarray) -> None:
        if index % GIF_EVERY == 0:
            h, w = frame.shape[:2]
            size = (max(2, int(w * GIF_SCALE)), max(2, int(h * GIF_SCALE)))
            self.frames.append(np.asarray(Image.fromarray(frame).resize(size, Image.BILINEAR)))


def write_clip_summary(folder: str, tag: str, step: int, frames: list[np.ndarray], fps: float) -> None:
    """One image summary ``tag`` at ``step`` holding ``frames`` as an animated GIF."""
    from tensorboard.compat.proto import event_pb2, summary_pb2
    from tensorboard.summary.writer.event_file_writer import EventFileWriter

    height, width = frames[0].shape[:2]
    image = summary_pb2.Summary.Image(height=height, width=width, colorspace=3,
                                      encoded_image_string=gif_bytes(frames, fps / GIF_EVERY))
    summary = summary_pb2.Summary(value=[summary_pb2.Summary.Value(tag=tag, image=image)])
    writer = EventFileWriter(folder)
    writer.add_event(event_pb2.Event(wall_time=time.time(), step=int(step), summary=summary))
    writer.close()
