"""Training statistics: per-brain aggregation between summaries, and fan-out to writers.

Vocabulary follows ML-Agents: a *category* is a brain (behavior name, one TensorBoard run), a
*key* is a stat name such as ``Environment/Cumulative Reward``. Values accumulate in a
:class:`StatsAggregator` until :meth:`StatsReporter.write` hands a ``{key: StatsSummary}`` dict to
every writer and clears the brain's aggregator.

Aggregation methods (docs/protocol.md, "Known channels"):

* ``AVERAGE``: the summary value is the mean of everything added since the last write.
* ``SUM``: the summary value is the sum.
* ``MOST_RECENT``: only the last value is kept (``set`` semantics).
* ``HISTOGRAM``: all values are kept; the summary value is the mean, writers may draw a histogram.

Writers are plain objects passed in; see :class:`StatsWriter` for the methods they may define.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from protos.types import StatsAggregationMethod

__all__ = [
    "StatsAggregationMethod",
    "StatsSummary",
    "StatsAggregator",
    "StatsWriter",
    "StatsReporter",
    "GaugeWriter",
    "PROPERTY_HYPERPARAMETERS",
    "PROPERTY_SELF_PLAY",
    "HIDDEN_KEYS",
    "HISTOGRAM_KEYS",
    "CUMULATIVE_REWARD",
]

PROPERTY_HYPERPARAMETERS = "hyperparameters"
"""``add_property`` key whose value is the behavior's settings dict (console dump, TB text)."""
PROPERTY_SELF_PLAY = "selfplay"
"""``add_property`` key whose bool value tells the console to append the ELO."""
HIDDEN_KEYS = ("Is Training", "Step")
"""Keys recorded for the console/gauges but never drawn in TensorBoard."""
CUMULATIVE_REWARD = "Environment/Cumulative Reward"
HISTOGRAM_KEYS = frozenset({CUMULATIVE_REWARD})
"""Keys always kept as HISTOGRAM (an AVERAGE add is upgraded; the scalar is the same mean)."""


@dataclass(frozen=True, eq=False)
class StatsSummary:
    """What was recorded for one key since the last write.

    ``values`` holds every value (float64, shape ``[count]``) for HISTOGRAM stats and is empty
    otherwise. ``std`` is the population standard deviation (ddof=0), as numpy's default.
    """

    mean: float
    std: float
    count: int
    sum: float
    most_recent: float
    aggregation: StatsAggregationMethod = StatsAggregationMethod.AVERAGE
    values: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float64))

    @property
    def aggregated_value(self) -> float:
        """The single number a scalar writer draws: the sum for SUM stats, else the mean."""
        if self.aggregation == StatsAggregationMethod.SUM:
            return self.sum
        return self.mean


class _KeyAccumulator:
    """Running count/mean/M2 (Chan et al. parallel merge) plus the last value.

    Batched merges keep AVERAGE/SUM stats O(1) in memory; HISTOGRAM keeps the raw chunks too.
    """

    __slots__ = ("aggregation", "count", "mean", "m2", "total", "last", "chunks", "scalars")

    def __init__(self, aggregation: StatsAggregationMethod) -> None:
        self.aggregation = aggregation
        self.count = 0
        self.mean = 0.0
        self.m2 = 0.0
        self.total = 0.0
        self.last = float("nan")
        self.chunks: list[np.ndarray] = []
        self.scalars: list[float] = []  # HISTOGRAM values from push() not yet in chunks

    def reset(self) -> None:
        self.count, self.mean, self.m2, self.total = 0, 0.0, 0.0, 0.0
        self.chunks = []
        self.scalars = []

    def _flush_scalars(self) -> None:
        if self.scalars:
            self.chunks.append(np.asarray(self.scalars, dtype=np.float64))
            self.scalars = []

    def merge(self, batch: np.ndarray) -> None:
        """Fold a float64 batch of shape ``[n]`` (n >= 1) into the running moments."""
        n = batch.shape[0]
        batch_sum = float(batch.sum())
        batch_mean = batch_sum / n
        centered = batch - batch_mean
        batch_m2 = float(np.dot(centered, centered))
        new_count = self.count + n
        delta = batch_mean - self.mean
        self.mean += delta * n / new_count
        self.m2 += batch_m2 + delta * delta * self.count * n / new_count
        self.count = new_count
        self.total += batch_sum
        self.last = float(batch[-1])
        if self.aggregation == StatsAggregationMethod.HISTOGRAM:
            self._flush_scalars()  # keep insertion order
            self.chunks.append(batch)

    def push(self, value: float) -> None:
        """Fold one value in (Welford's update; no numpy on this path)."""
        self.count += 1
        delta = value - self.mean
        self.mean += delta / self.count
        self.m2 += delta * (value - self.mean)
        self.total += value
        self.last = value
        if self.aggregation == StatsAggregationMethod.HISTOGRAM:
            self.scalars.append(value)

    def merge_from(self, other: "_KeyAccumulator") -> None:
        """Fold another accumulator of the same key in (Chan et al.'s parallel merge); a
        MOST_RECENT key keeps its own value when it has one (data-parallel ranks,
        trainer/distributed.py, bring each rank's stats to rank 0 this way)."""
        if other.count == 0:
            return
        if self.aggregation == StatsAggregationMethod.MOST_RECENT:
            if self.count == 0:
                self.count, self.mean, self.m2, self.total, self.last = 1, other.last, 0.0, other.last, other.last
            return
        new_count = self.count + other.count
        delta = other.mean - self.mean
        self.m2 += other.m2 + delta * delta * self.count * other.count / new_count
        self.mean += delta * other.count / new_count
        self.count = new_count
        self.total += other.total
        if self.aggregation == StatsAggregationMethod.HISTOGRAM:
            self._flush_scalars()
            other._flush_scalars()
            self.chunks.extend(other.chunks)

    def summary(self) -> StatsSummary:
        self._flush_scalars()
        if self.chunks:
            values = np.concatenate(self.chunks)
        else:
            values = np.zeros(0, dtype=np.float64)
        std = float(np.sqrt(max(self.m2, 0.0) / self.count))
        return StatsSummary(
            mean=self.mean,
            std=std,
            count=self.count,
            sum=self.total,
            most_recent=self.last,
            aggregation=self.aggregation,
            values=values,
        )


class StatsAggregator:
    """All stats of one brain (category) since the last summary. Not thread-safe on its own."""

    def __init__(self) -> None:
        self._keys: dict[str, _KeyAccumulator] = {}

    def add(
        self,
        key: str,
        value: float,
        aggregation: StatsAggregationMethod = StatsAggregationMethod.AVERAGE,
    ) -> None:
        """Record one value. MOST_RECENT replaces whatever the key held."""
        acc = self._accumulator(key, aggregation)
        if acc.aggregation == StatsAggregationMethod.MOST_RECENT:
            acc.reset()
        acc.push(float(value))

    def _accumulator(self, key: str, aggregation: StatsAggregationMethod) -> _KeyAccumulator:
        """The key's accumulator, switched to ``aggregation`` (the last method given wins)."""
        aggregation = StatsAggregationMethod(aggregation)
        if aggregation == StatsAggregationMethod.AVERAGE and key in HISTOGRAM_KEYS:
            aggregation = StatsAggregationMethod.HISTOGRAM
        acc = self._keys.get(key)
        if acc is None:
            acc = self._keys[key] = _KeyAccumulator(aggregation)
        elif acc.aggregation != aggregation:
            acc.aggregation = aggregation
        return acc

    def add_many(
        self,
        key: str,
        values: np.ndarray | Sequence[float],
        aggregation: StatsAggregationMethod = StatsAggregationMethod.AVERAGE,
    ) -> None:
        """Record a batch of values (any shape; flattened in order). Empty batches are ignored.

        For MOST_RECENT only the batch's last element is kept.
        """
        batch = np.asarray(values, dtype=np.float64).reshape(-1)
        if batch.shape[0] == 0:
            return
        acc = self._accumulator(key, aggregation)
        if acc.aggregation == StatsAggregationMethod.MOST_RECENT:
            acc.reset()
            batch = batch[-1:]
        acc.merge(batch)

    def summarize(self) -> dict[str, StatsSummary]:
        """Summaries of every key with at least one value, in first-added order."""
        return {key: acc.summary() for key, acc in self._keys.items() if acc.count > 0}

    def clear(self) -> None:
        self._keys.clear()

    def merge_from(self, other: "StatsAggregator") -> None:
        """Fold every key of ``other`` in (``_KeyAccumulator.merge_from``)."""
        for key, acc in other._keys.items():
            self._accumulator(key, acc.aggregation).merge_from(acc)

    def __len__(self) -> int:
        return len(self._keys)


class StatsWriter:
    """Base class for writers; every hook is optional (no-op here)."""

    def write_stats(self, brain: str, summaries: Mapping[str, StatsSummary], step: int) -> None:
        """Called by :meth:`StatsReporter.write` every summary_freq steps."""

    def write_text(self, brain: str, tag: str, text: str, step: int) -> None:
        """Free-form text (e.g. TensorBoard text summaries)."""

    def add_property(self, brain: str, key: str, value: Any) -> None:
        """A property of the brain, e.g. ``PROPERTY_HYPERPARAMETERS`` with the settings dict."""

    def close(self) -> None:
        """Flush and release files."""


class StatsReporter:
    """One :class:`StatsAggregator` per brain and a list of writers (no module globals).

    A re-entrant lock guards adds and writes so trainer threads and the env-stepping thread can
    share one reporter.
    """

    def __init__(self, writers: Iterable[Any] = ()) -> None:
        self.writers: list[Any] = list(writers)
        self._aggregators: dict[str, StatsAggregator] = {}
        self._lock = threading.RLock()

    def aggregator(self, brain: str) -> StatsAggregator:
        """The brain's aggregator (created on first use)."""
        agg = self._aggregators.get(brain)
        if agg is None:
            agg = self._aggregators.setdefault(brain, StatsAggregator())
        return agg

    def add(
        self,
        brain: str,
        key: str,
        value: float,
        aggregation: StatsAggregationMethod = StatsAggregationMethod.AVERAGE,
    ) -> None:
        with self._lock:
            self.aggregator(brain).add(key, value, aggregation)

    def add_many(
        self,
        brain: str,
        key: str,
        values: np.ndarray | Sequence[float],
        aggregation: StatsAggregationMethod = StatsAggregationMethod.AVERAGE,
    ) -> None:
        with self._lock:
            self.aggregator(brain).add_many(key, values, aggregation)

    def set(self, brain: str, key: str, value: float) -> None:
        """Keep only ``value`` for ``key`` (MOST_RECENT), e.g. ``Step``."""
        self.add(brain, key, value, StatsAggregationMethod.MOST_RECENT)

    def record_environment_stats(
        self,
        brains: Iterable[str],
        env_stats: Mapping[str, Sequence[tuple[float, StatsAggregationMethod]]],
        worker_id: int,
    ) -> None:
        """Stats-side-channel values from one env step (docs/protocol.md, "Known channels").

        Every stat is recorded under each brain in ``brains`` (the behaviors present in that
        step); MOST_RECENT stats are taken from worker 0 only.
        """
        brain_list = list(brains)
        with self._lock:
            for key, entries in env_stats.items():
                for value, aggregation in entries:
                    aggregation = StatsAggregationMethod(aggregation)
                    if aggregation == StatsAggregationMethod.MOST_RECENT and worker_id != 0:
                        continue
                    for brain in brain_list:
                        self.aggregator(brain).add(key, value, aggregation)

    def take(self, brain: str) -> StatsAggregator:
        """The brain's stats so far, handed over: this reporter starts afresh for it."""
        with self._lock:
            return self._aggregators.pop(brain, None) or StatsAggregator()

    def merge(self, brain: str, other: StatsAggregator) -> None:
        """Fold stats recorded elsewhere (another rank's ``take``) into the brain's."""
        with self._lock:
            self.aggregator(brain).merge_from(other)

    def write(self, brain: str, step: int, is_training: bool | None = None) -> None:
        """Hand the brain's summaries to every writer, then clear them.

        ``is_training`` (if given) is recorded as the ``Is Training`` stat first, which the
        console uses to print ``Training`` / ``Not Training``.
        """
        with self._lock:
            agg = self.aggregator(brain)
            if is_training is not None:
                agg.add("Is Training", float(is_training))
            summaries = agg.summarize()
            for writer in self.writers:
                writer.write_stats(brain, summaries, int(step))
            agg.clear()

    def write_text(self, brain: str, tag: str, text: str, step: int) -> None:
        with self._lock:
            for writer in self.writers:
                hook = getattr(writer, "write_text", None)
                if hook is not None:
                    hook(brain, tag, text, int(step))

    def add_property(self, brain: str, key: str, value: Any) -> None:
        with self._lock:
            for writer in self.writers:
                hook = getattr(writer, "add_property", None)
                if hook is not None:
                    hook(brain, key, value)

    def resume_from(self, brain: str, step: int) -> None:
        """The brain resumed from a checkpoint at ``step``: writers that keep a history drop what
        an earlier process wrote after it (``TensorboardWriter.resume_from``)."""
        with self._lock:
            for writer in self.writers:
                hook = getattr(writer, "resume_from", None)
                if hook is not None:
                    hook(brain, int(step))

    def close(self) -> None:
        with self._lock:
            for writer in self.writers:
                hook = getattr(writer, "close", None)
                if hook is not None:
                    hook()


class GaugeWriter(StatsWriter):
    """Mirrors every summary into timer gauges ``<brain>.<key>.mean`` / ``.sum``.

    Names drop spaces and turn ``/`` into ``.`` (``Ball.Policy.Entropy.mean``), as in timers.json.
    ``timer_tree`` is anything with ``set_gauge(name, value)`` (a :class:`TimerTree`).
    """

    def __init__(self, timer_tree: Any) -> None:
        self.timer_tree = timer_tree

    @staticmethod
    def gauge_name(brain: str, key: str, suffix: str) -> str:
        return f"{brain}.{key}.{suffix}".replace("/", ".").replace(" ", "")

    def write_stats(self, brain: str, summaries: Mapping[str, StatsSummary], step: int) -> None:
        for key, summary in summaries.items():
            self.timer_tree.set_gauge(self.gauge_name(brain, key, "mean"), summary.mean)
            self.timer_tree.set_gauge(self.gauge_name(brain, key, "sum"), summary.sum)
