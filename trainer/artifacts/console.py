"""Console output: the ML-Agents summary line per brain and a live progress line (docs/outputs.md, "Outputs").

Summary line, logged at INFO every summary_freq steps::

    Ball. Step: 1000. Time Elapsed: 10.136 s. Mean Reward: -12.173. Std of Reward: 3.446. Training.
    Ball. Step: 1000. Time Elapsed: 10.136 s. No episode was completed since last summary. Training.

``Training`` / ``Not Training`` comes from the ``Is Training`` stat (positive mean = training;
absent = not training), which :meth:`StatsReporter.write` records from its ``is_training``
argument. POCA replaces the Std part by ``Mean Group Reward: x``; self-play appends ``ELO: x``.

The progress line (our addition) shows, per behavior::

    Basic: step 1,200/5,000 (24%) · 3,456 steps/s · ETA 0:00:01 · mean reward 0.812
"""
from __future__ import annotations

import datetime
import logging
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping, TextIO

from trainer.artifacts.stats import (
    CUMULATIVE_REWARD,
    PROPERTY_HYPERPARAMETERS,
    PROPERTY_SELF_PLAY,
    StatsSummary,
    StatsWriter,
)

__all__ = ["ConsoleWriter", "ProgressLine", "format_summary_line", "hyperparameters_dump"]

GROUP_CUMULATIVE_REWARD = "Environment/Group Cumulative Reward"
ELO_KEY = "Self-play/ELO"
IS_TRAINING_KEY = "Is Training"


def format_summary_line(
    brain: str,
    summaries: Mapping[str, StatsSummary],
    step: int,
    elapsed_seconds: float,
    self_play: bool = False,
) -> str:
    """The one-line summary ML-Agents prints for a brain (without the ``[INFO]`` prefix)."""
    training = summaries.get(IS_TRAINING_KEY)
    status = "Training" if training is not None and training.aggregated_value > 0.0 else "Not Training"
    parts = [brain, f"Step: {int(step)}", f"Time Elapsed: {elapsed_seconds:0.3f} s"]
    reward = summaries.get(CUMULATIVE_REWARD)
    if reward is None:
        parts += ["No episode was completed since last summary", status]
        return ". ".join(parts) + "."
    parts.append(f"Mean Reward: {reward.mean:0.3f}")
    group = summaries.get(GROUP_CUMULATIVE_REWARD)
    if group is not None:
        parts.append(f"Mean Group Reward: {group.mean:0.3f}")
    else:
        parts.append(f"Std of Reward: {reward.std:0.3f}")
    parts.append(status)
    elo = summaries.get(ELO_KEY)
    if self_play and elo is not None:
        parts.append(f"ELO: {elo.mean:0.3f}")
    return ". ".join(parts) + "."


def hyperparameters_dump(settings: Any, depth: int = 0) -> str:
    """Tab-indented dump of a settings dict: ``\\tkey:\\tvalue`` per line, nested dicts on the
    following lines indented by two more spaces per level (the ML-Agents console layout)."""
    if not isinstance(settings, Mapping):
        return str(settings)
    lines = [
        "\t" + "  " * depth + f"{key}:\t{hyperparameters_dump(value, depth + 1)}"
        for key, value in settings.items()
    ]
    body = "\n".join(lines)
    return "\n" + body if depth > 0 else body


class ConsoleWriter(StatsWriter):
    """Logs the summary line of each brain; ``clock`` is wall time (injectable for tests).

    If a :class:`ProgressLine` is given, it is cleared before each log line so the two do not
    overwrite each other on a terminal.
    """

    def __init__(
        self,
        logger: logging.Logger | None = None,
        clock: Callable[[], float] = time.time,
        progress: ProgressLine | None = None,
    ) -> None:
        self.logger = logger or logging.getLogger("trainer")
        self.clock = clock
        self.start_time = clock()
        self.progress = progress
        self.self_play: dict[str, bool] = {}

    def write_stats(self, brain: str, summaries: Mapping[str, StatsSummary], step: int) -> None:
        elapsed = self.clock() - self.start_time
        line = format_summary_line(brain, summaries, step, elapsed, self.self_play.get(brain, False))
        self._log(line)

    def add_property(self, brain: str, key: str, value: Any) -> None:
        if key == PROPERTY_HYPERPARAMETERS:
            self._log(f"Hyperparameters for behavior name {brain}: \n{hyperparameters_dump(value)}")
        elif key == PROPERTY_SELF_PLAY:
            self.self_play[brain] = bool(value)

    def _log(self, message: str) -> None:
        if self.progress is not None:
            self.progress.clear()
        self.logger.info(message)


@dataclass
class _BehaviorProgress:
    first_time: float
    first_step: int
    step: int
    max_steps: int | None = None
    mean_reward: float | None = None
    last_emit: float | None = None

    def steps_per_second(self, now: float) -> float | None:
        elapsed = now - self.first_time
        if elapsed <= 0.0 or self.step <= self.first_step:
            return None
        return (self.step - self.first_step) / elapsed


def _format_eta(seconds: float) -> str:
    return str(datetime.timedelta(seconds=int(round(seconds))))


class ProgressLine:
    """Live per-behavior progress for a terminal or a log file.

    On a TTY all behaviors share one line rewritten in place with ``\\r`` (at most every
    ``tty_interval`` seconds); otherwise each behavior prints at most one line every
    ``interval`` seconds. The speed is the average since the behavior's first update.
    ``clock`` is a monotonic clock in seconds, injectable for tests.
    """

    def __init__(
        self,
        stream: TextIO | None = None,
        interval: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
        is_tty: bool | None = None,
        tty_interval: float = 0.2,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        if is_tty is None:
            isatty = getattr(self.stream, "isatty", None)
            is_tty = bool(isatty()) if isatty is not None else False
        self.is_tty = is_tty
        self.interval = interval
        self.tty_interval = tty_interval
        self.clock = clock
        self._behaviors: dict[str, _BehaviorProgress] = {}
        self._tty_width = 0
        self._tty_last_render: float | None = None

    def update(
        self,
        brain: str,
        step: int,
        max_steps: int | None = None,
        mean_reward: float | None = None,
    ) -> None:
        """Record the brain's step (and optionally its max_steps / latest mean reward); render
        if the rate limit allows."""
        now = self.clock()
        state = self._behaviors.get(brain)
        if state is None:
            state = self._behaviors[brain] = _BehaviorProgress(now, int(step), int(step))
        state.step = int(step)
        if max_steps is not None:
            state.max_steps = int(max_steps)
        if mean_reward is not None:
            state.mean_reward = float(mean_reward)
        if self.is_tty:
            if self._tty_last_render is None or now - self._tty_last_render >= self.tty_interval:
                self._render_tty(now)
        elif state.last_emit is None or now - state.last_emit >= self.interval:
            state.last_emit = now
            self.stream.write(self.render(brain, now) + "\n")
            self.stream.flush()

    def render(self, brain: str, now: float | None = None) -> str:
        """The progress text of one behavior at time ``now`` (default: the clock)."""
        state = self._behaviors[brain]
        now = self.clock() if now is None else now
        if state.max_steps:
            percent = min(100, int(100 * state.step / state.max_steps))
            parts = [f"{brain}: step {state.step:,}/{state.max_steps:,} ({percent}%)"]
        else:
            parts = [f"{brain}: step {state.step:,}"]
        rate = state.steps_per_second(now)
        parts.append(f"{rate:,.0f} steps/s" if rate is not None else "-- steps/s")
        if state.max_steps:
            remaining = max(0, state.max_steps - state.step)
            parts.append(f"ETA {_format_eta(remaining / rate)}" if rate else "ETA --")
        if state.mean_reward is not None:
            parts.append(f"mean reward {state.mean_reward:.3f}")
        return " · ".join(parts)

    def _render_tty(self, now: float) -> None:
        text = " | ".join(self.render(brain, now) for brain in self._behaviors)
        padding = " " * max(0, self._tty_width - len(text))
        self.stream.write("\r" + text + padding)
        self.stream.flush()
        self._tty_width = len(text)
        self._tty_last_render = now

    def clear(self) -> None:
        """Erase the in-place line (TTY only) so a log line can be printed; the next update
        redraws it."""
        if self.is_tty and self._tty_width:
            self.stream.write("\r" + " " * self._tty_width + "\r")
            self.stream.flush()
            self._tty_width = 0
            self._tty_last_render = None

    def close(self) -> None:
        """End the in-place line with a newline (TTY only)."""
        if self.is_tty and self._tty_width:
            self.stream.write("\n")
            self.stream.flush()
            self._tty_width = 0
