"""TensorBoard output: one event file per brain under ``results/<run-id>/<brain>/`` (docs/outputs.md, "Outputs").

Event files are TFRecord files of ``Event`` protos (tensorboard's own protos; the framing is
written here by ``EventFile``: importing tensorboard's writer costs ~0.2 s of every run's
start-up). What is written, per :meth:`TensorboardWriter.write_stats` call:

* a scalar per key at ``step``: the mean, or the sum for SUM stats;
* for HISTOGRAM stats (``Environment/Cumulative Reward`` always is one) also a histogram
  ``<key>_hist`` of the values;
* nothing for the hidden keys ``Is Training`` and ``Step``.

The ``hyperparameters`` property becomes the text summary ``Hyperparameters`` (a markdown table;
stored under the tag ``Hyperparameters/text_summary`` as torch's SummaryWriter does).
Every write is flushed so TensorBoard and tests see it at once.
"""
from __future__ import annotations

import logging
import os
import socket
import struct
import time
from typing import Any, Iterable, Mapping

import numpy as np
from tensorboard.compat.proto import event_pb2, summary_pb2, tensor_pb2, tensor_shape_pb2
from tensorboard.plugins.text import plugin_data_pb2 as text_plugin_data_pb2

from trainer.artifacts.stats import (
    HIDDEN_KEYS,
    PROPERTY_HYPERPARAMETERS,
    StatsAggregationMethod,
    StatsSummary,
    StatsWriter,
)

__all__ = ["TensorboardWriter", "hyperparameters_markdown", "histogram_proto"]

logger = logging.getLogger(__name__)

EVENT_FILE_PREFIX = "events.out.tfevents"
HYPERPARAMETERS_TAG = "Hyperparameters"
MAX_HISTOGRAM_BUCKETS = 30


def histogram_proto(values: np.ndarray) -> summary_pb2.HistogramProto:
    """Histogram of ``values`` (shape ``[n]``, n >= 1) with up to 30 equal-width buckets.

    ``bucket_limit[i]`` is the right edge of bucket ``i``; the first bucket starts at ``min``.
    """
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    low, high = float(values.min()), float(values.max())
    if high > low:
        n_buckets = min(MAX_HISTOGRAM_BUCKETS, values.shape[0])
        counts, edges = np.histogram(values, bins=n_buckets, range=(low, high))
        limits = edges[1:]
    else:
        counts, limits = np.array([values.shape[0]]), np.array([high])
    return summary_pb2.HistogramProto(
        min=low,
        max=high,
        num=float(values.shape[0]),
        sum=float(values.sum()),
        sum_squares=float(np.square(values).sum()),
        bucket_limit=[float(x) for x in limits],
        bucket=[float(c) for c in counts],
    )


def _flatten(settings: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    for key, value in settings.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            yield from _flatten(value, name + ".")
        else:
            yield name, value


def hyperparameters_markdown(settings: Mapping[str, Any]) -> str:
    """Settings dict as a two-column markdown table; nested keys are joined with dots."""
    lines = ["| Parameter | Value |", "|---|---|"]
    for name, value in _flatten(settings):
        cell = str(value).replace("|", "\\|").replace("\n", " ")
        lines.append(f"| {name} | {cell} |")
    return "\n".join(lines)


def _text_summary(tag: str, text: str) -> summary_pb2.Summary:
    plugin = summary_pb2.SummaryMetadata.PluginData(
        plugin_name="text",
        content=text_plugin_data_pb2.TextPluginData(version=0).SerializeToString(),
    )
    tensor = tensor_pb2.TensorProto(
        dtype="DT_STRING",
        string_val=[text.encode("utf-8")],
        tensor_shape=tensor_shape_pb2.TensorShapeProto(
            dim=[tensor_shape_pb2.TensorShapeProto.Dim(size=1)]
        ),
    )
    value = summary_pb2.Summary.Value(
        tag=f"{tag}/text_summary",
        metadata=summary_pb2.SummaryMetadata(plugin_data=plugin),
        tensor=tensor,
    )
    return summary_pb2.Summary(value=[value])


class TensorboardWriter(StatsWriter):
    """Stats writer with one event file per brain in ``<base_dir>/<brain>/``.

    ``base_dir`` is ``results/<run-id>``. ``clear_past_data`` deletes old event files of a brain
    before its writer is opened (--force without --resume); :meth:`clear_existing` does it on
    demand.
    """

    def __init__(
        self,
        base_dir: str | os.PathLike[str],
        clear_past_data: bool = False,
        hidden_keys: Iterable[str] = HIDDEN_KEYS,
        wall_clock: Any = time.time,
    ) -> None:
        self.base_dir = os.fspath(base_dir)
        self.clear_past_data = clear_past_data
        self.hidden_keys = frozenset(hidden_keys)
        self._wall_clock = wall_clock
        self._writers: dict[str, EventFile] = {}

    def brain_dir(self, brain: str) -> str:
        return os.path.join(self.base_dir, brain)

    def _writer(self, brain: str) -> EventFile:
        writer = self._writers.get(brain)
        if writer is None:
            directory = self.brain_dir(brain)
            os.makedirs(directory, exist_ok=True)
            if self.clear_past_data:
                self.clear_existing(brain)
            writer = self._writers[brain] = EventFile(directory, self._wall_clock)
        return writer

    def clear_existing(self, brain: str) -> list[str]:
        """Delete ``events.out.tfevents.*`` left in the brain's folder; returns deleted paths.

        An open writer for that brain is closed first (a new file starts on the next write).
        """
        open_writer = self._writers.pop(brain, None)
        if open_writer is not None:
            open_writer.close()
        directory = self.brain_dir(brain)
        if not os.path.isdir(directory):
            return []
        deleted = []
        for name in sorted(os.listdir(directory)):
            if not name.startswith(EVENT_FILE_PREFIX):
                continue
            path = os.path.join(directory, name)
            logger.warning("Deleting TensorBoard data %s left over from a previous run.", path)
            try:
                os.remove(path)
                deleted.append(path)
            except OSError:
                logger.error("%s was left over from a previous run and could not be deleted.", path)
        return deleted

    def _emit(self, brain: str, summary: summary_pb2.Summary, step: int) -> None:
        event = event_pb2.Event(wall_time=self._wall_clock(), step=int(step), summary=summary)
        self._writer(brain).add_event(event)

    def write_stats(self, brain: str, summaries: Mapping[str, StatsSummary], step: int) -> None:
        values = []
        for key, summary in summaries.items():
            if key in self.hidden_keys:
                continue
            values.append(
                summary_pb2.Summary.Value(tag=key, simple_value=float(summary.aggregated_value))
            )
            if summary.aggregation == StatsAggregationMethod.HISTOGRAM and summary.values.size:
                histo = histogram_proto(summary.values)
                values.append(summary_pb2.Summary.Value(tag=f"{key}_hist", histo=histo))
        if values:
            self._emit(brain, summary_pb2.Summary(value=values), step)
            self._writers[brain].flush()

    def write_text(self, brain: str, tag: str, text: str, step: int) -> None:
        self._emit(brain, _text_summary(tag, text), step)
        self._writers[brain].flush()

    def add_property(self, brain: str, key: str, value: Any) -> None:
        if key == PROPERTY_HYPERPARAMETERS and isinstance(value, Mapping):
            self.write_text(brain, HYPERPARAMETERS_TAG, hyperparameters_markdown(value), 0)

    def resume_from(self, brain: str, step: int) -> None:
        """A SessionLog START event at ``step + 1``: TensorBoard then drops the events of earlier
        files with a step above ``step`` (its purge of orphaned data). A run killed without
        warning (SIGKILL, a node failure) wrote summaries after its last checkpoint; the resumed
        run writes those steps again, and the curve must show them once. After a graceful stop
        the checkpoint is the last step, so nothing is dropped."""
        start = event_pb2.SessionLog(status=event_pb2.SessionLog.START)
        self._writer(brain).add_event(event_pb2.Event(wall_time=self._wall_clock(), step=int(step) + 1,
                                                      session_log=start))
        self._writers[brain].flush()

    def flush(self) -> None:
        for writer in self._writers.values():
            writer.flush()

    def close(self) -> None:
        for writer in self._writers.values():
            writer.close()
        self._writers.clear()


# --------------------------------------------------------------------------- event files
def _crc32c_table() -> list[int]:
    table = []
    for index in range(256):
        crc = index
        for _ in range(8):
            crc = (crc >> 1) ^ 0x82F63B78 if crc & 1 else crc >> 1  # Castagnoli, reflected
        table.append(crc)
    return table


_CRC32C_TABLE = _crc32c_table()


def crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli) of ``data``: what TFRecord framing checks. Events are small and
    few (one per summary period and behavior), so a table-driven loop is fast enough."""
    crc = 0xFFFFFFFF
    table = _CRC32C_TABLE
    for byte in data:
        crc = table[(crc ^ byte) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def masked_crc32c(data: bytes) -> int:
    crc = crc32c(data)
    return (((crc >> 15) | (crc << 17)) + 0xA282EAD8) & 0xFFFFFFFF


class EventFile:
    """One ``events.out.tfevents.<time>.<host>`` file: TFRecord records (length, masked CRC of
    the length, serialized Event, masked CRC of it), starting with the file-version event.
    Written synchronously; ``flush`` hands the bytes to the OS."""

    def __init__(self, directory: str, wall_clock: Any = time.time) -> None:
        now = wall_clock()
        self.path = os.path.join(directory, f"{EVENT_FILE_PREFIX}.{int(now):010d}.{socket.gethostname()}")
        self._file = open(self.path, "ab")
        self.add_event(event_pb2.Event(wall_time=now, file_version="brain.Event:2"))
        self.flush()

    def add_event(self, event: event_pb2.Event) -> None:
        data = event.SerializeToString()
        header = struct.pack("<Q", len(data))
        self._file.write(header + struct.pack("<I", masked_crc32c(header))
                         + data + struct.pack("<I", masked_crc32c(data)))

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        self._file.close()
