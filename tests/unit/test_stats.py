"""Stats aggregation and reporter fan-out, checked against numbers worked out by hand."""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from trainer.artifacts.console import ConsoleWriter, ProgressLine, format_summary_line, hyperparameters_dump
from trainer.artifacts.stats import (
    GaugeWriter,
    StatsAggregationMethod as Agg,
    StatsAggregator,
    StatsReporter,
    StatsSummary,
    StatsWriter,
)
from trainer.artifacts.timers import TimerTree


class RecordingWriter(StatsWriter):
    def __init__(self) -> None:
        self.stats: list[tuple[str, dict, int]] = []
        self.texts: list[tuple[str, str, str, int]] = []
        self.properties: list[tuple[str, str, object]] = []

    def write_stats(self, brain, summaries, step):
        self.stats.append((brain, dict(summaries), step))

    def write_text(self, brain, tag, text, step):
        self.texts.append((brain, tag, text, step))

    def add_property(self, brain, key, value):
        self.properties.append((brain, key, value))


# ---------------------------------------------------------------------------------------------
# StatsAggregator
# ---------------------------------------------------------------------------------------------
def test_average_mean_and_population_std_by_hand():
    agg = StatsAggregator()
    for v in (1.0, 2.0, 3.0, 6.0):
        agg.add("Policy/Entropy", v)
    s = agg.summarize()["Policy/Entropy"]
    # mean = 12/4 = 3; squared deviations 4,1,0,9 -> 14/4 = 3.5
    assert s.mean == pytest.approx(3.0)
    assert s.std == pytest.approx(math.sqrt(3.5))
    assert s.count == 4
    assert s.sum == pytest.approx(12.0)
    assert s.most_recent == 6.0
    assert s.aggregation == Agg.AVERAGE
    assert s.aggregated_value == pytest.approx(3.0)
    assert s.values.size == 0  # AVERAGE keeps no raw values


def test_add_many_batches_merge_like_one_list():
    agg = StatsAggregator()
    agg.add_many("x", np.array([1.0, 2.0]))
    agg.add_many("x", np.array([[3.0], [10.0]]))  # any shape, flattened in order
    agg.add("x", -1.0)
    agg.add_many("x", np.zeros(0))  # ignored
    s = agg.summarize()["x"]
    # values 1,2,3,10,-1: sum 15, mean 3, deviations^2 4,1,0,49,16 = 70 -> var 14
    assert s.count == 5
    assert s.sum == pytest.approx(15.0)
    assert s.mean == pytest.approx(3.0)
    assert s.std == pytest.approx(math.sqrt(14.0))
    assert s.most_recent == -1.0


def test_sum_aggregated_value_is_the_sum():
    agg = StatsAggregator()
    agg.add("Custom/Coins", 2.0, Agg.SUM)
    agg.add_many("Custom/Coins", np.array([0.5, 4.0]), Agg.SUM)
    s = agg.summarize()["Custom/Coins"]
    assert s.sum == pytest.approx(6.5)
    assert s.aggregated_value == pytest.approx(6.5)
    assert s.mean == pytest.approx(6.5 / 3)


def test_most_recent_keeps_only_last_value():
    agg = StatsAggregator()
    agg.add("Step", 100.0, Agg.MOST_RECENT)
    agg.add("Step", 250.0, Agg.MOST_RECENT)
    agg.add_many("Step", np.array([300.0, 400.0]), Agg.MOST_RECENT)
    s = agg.summarize()["Step"]
    assert (s.count, s.mean, s.sum, s.most_recent, s.std) == (1, 400.0, 400.0, 400.0, 0.0)
    assert s.aggregated_value == 400.0


def test_histogram_keeps_values_in_order():
    agg = StatsAggregator()
    agg.add("Custom/Dist", 5.0, Agg.HISTOGRAM)
    agg.add_many("Custom/Dist", np.array([1.0, 3.0]), Agg.HISTOGRAM)
    s = agg.summarize()["Custom/Dist"]
    np.testing.assert_array_equal(s.values, [5.0, 1.0, 3.0])
    assert s.mean == pytest.approx(3.0)
    assert s.aggregated_value == pytest.approx(3.0)


def test_cumulative_reward_is_always_a_histogram():
    agg = StatsAggregator()
    agg.add_many("Environment/Cumulative Reward", np.array([1.0, -1.0]))
    s = agg.summarize()["Environment/Cumulative Reward"]
    assert s.aggregation == Agg.HISTOGRAM
    np.testing.assert_array_equal(s.values, [1.0, -1.0])


def test_clear_and_summarize_order():
    agg = StatsAggregator()
    agg.add("b", 1.0)
    agg.add("a", 2.0)
    assert list(agg.summarize()) == ["b", "a"]
    agg.clear()
    assert agg.summarize() == {}


def test_large_offset_std_is_stable():
    agg = StatsAggregator()
    base = 1e9
    agg.add_many("x", base + np.array([0.0, 2.0]))
    agg.add_many("x", base + np.array([4.0]))
    # values base+{0,2,4}: var = (4+0+4)/3
    assert agg.summarize()["x"].std == pytest.approx(math.sqrt(8.0 / 3.0), rel=1e-6)


# ---------------------------------------------------------------------------------------------
# StatsReporter
# ---------------------------------------------------------------------------------------------
def test_reporter_write_fans_out_per_brain_then_clears():
    w1, w2 = RecordingWriter(), RecordingWriter()
    reporter = StatsReporter([w1, w2])
    reporter.add("Ball", "Losses/Value Loss", 2.0)
    reporter.add("Ball", "Losses/Value Loss", 4.0)
    reporter.add("Crawler", "Losses/Value Loss", 9.0)
    reporter.set("Ball", "Step", 1000.0)
    reporter.write("Ball", 1000, is_training=True)
    assert len(w1.stats) == len(w2.stats) == 1
    brain, summaries, step = w1.stats[0]
    assert (brain, step) == ("Ball", 1000)
    assert summaries["Losses/Value Loss"].mean == pytest.approx(3.0)
    assert summaries["Step"].most_recent == 1000.0
    assert summaries["Is Training"].mean == 1.0
    # Ball cleared, Crawler untouched
    reporter.write("Ball", 2000)
    assert w1.stats[1][1] == {}
    reporter.write("Crawler", 2000)
    assert w1.stats[2][1]["Losses/Value Loss"].mean == pytest.approx(9.0)


def test_reporter_text_and_property_reach_writers():
    w = RecordingWriter()
    reporter = StatsReporter([w])
    reporter.write_text("Ball", "Notes", "hello", 5)
    reporter.add_property("Ball", "hyperparameters", {"batch_size": 64})
    assert w.texts == [("Ball", "Notes", "hello", 5)]
    assert w.properties == [("Ball", "hyperparameters", {"batch_size": 64})]


def test_environment_stats_go_to_every_brain_and_most_recent_only_from_worker_0():
    w = RecordingWriter()
    reporter = StatsReporter([w])
    stats = {"Custom/Avg": [(1.0, Agg.AVERAGE), (3.0, Agg.AVERAGE)], "Custom/Last": [(7.0, Agg.MOST_RECENT)]}
    reporter.record_environment_stats(["A", "B"], stats, worker_id=1)
    reporter.record_environment_stats(["A"], {"Custom/Last": [(5.0, Agg.MOST_RECENT)]}, worker_id=0)
    reporter.write("A", 10)
    reporter.write("B", 10)
    a, b = w.stats[0][1], w.stats[1][1]
    assert a["Custom/Avg"].mean == pytest.approx(2.0) and b["Custom/Avg"].mean == pytest.approx(2.0)
    assert a["Custom/Last"].most_recent == 5.0  # worker 1's 7.0 was dropped
    assert "Custom/Last" not in b


def test_gauge_writer_sanitizes_names_and_tracks_min_max():
    timers = TimerTree()
    reporter = StatsReporter([GaugeWriter(timers)])
    reporter.add("Ball", "Policy/Entropy", 1.5)
    reporter.write("Ball", 1)
    reporter.add("Ball", "Policy/Entropy", 0.5)
    reporter.add("Ball", "Policy/Entropy", 1.5)
    reporter.write("Ball", 2)
    gauges = timers.to_dict()["gauges"]
    assert gauges["Ball.Policy.Entropy.mean"] == {"value": 1.0, "min": 1.0, "max": 1.5, "count": 2}
    assert gauges["Ball.Policy.Entropy.sum"] == {"value": 2.0, "min": 1.5, "max": 2.0, "count": 2}


# ---------------------------------------------------------------------------------------------
# Console summary line
# ---------------------------------------------------------------------------------------------
def _summary(values, aggregation=Agg.HISTOGRAM) -> StatsSummary:
    agg = StatsAggregator()
    agg.add_many("k", np.asarray(values, dtype=float), aggregation)
    return agg.summarize()["k"]


def test_summary_line_with_rewards_exact():
    summaries = {
        "Environment/Cumulative Reward": _summary([-10.0, -14.346]),
        "Is Training": _summary([1.0], Agg.AVERAGE),
    }
    line = format_summary_line("Ball", summaries, 1000, 10.1364)
    # mean -12.173, std = 2.173
    assert line == "Ball. Step: 1000. Time Elapsed: 10.136 s. Mean Reward: -12.173. Std of Reward: 2.173. Training."


def test_summary_line_no_episode_and_not_training():
    assert (
        format_summary_line("Ball", {"Is Training": _summary([1.0], Agg.AVERAGE)}, 2000, 3.0)
        == "Ball. Step: 2000. Time Elapsed: 3.000 s. No episode was completed since last summary. Training."
    )
    rewards = {"Environment/Cumulative Reward": _summary([2.0]), "Is Training": _summary([0.0], Agg.AVERAGE)}
    assert (
        format_summary_line("Ball", rewards, 5, 0.5)
        == "Ball. Step: 5. Time Elapsed: 0.500 s. Mean Reward: 2.000. Std of Reward: 0.000. Not Training."
    )
    # no "Is Training" stat at all (inference) -> Not Training
    assert format_summary_line("Ball", {}, 5, 0.5).endswith("No episode was completed since last summary. Not Training.")


def test_summary_line_group_reward_and_elo():
    summaries = {
        "Environment/Cumulative Reward": _summary([1.0, 3.0]),
        "Environment/Group Cumulative Reward": _summary([4.5]),
        "Self-play/ELO": _summary([1210.25], Agg.AVERAGE),
        "Is Training": _summary([1.0], Agg.AVERAGE),
    }
    line = format_summary_line("Soccer", summaries, 7, 1.0, self_play=True)
    assert line == (
        "Soccer. Step: 7. Time Elapsed: 1.000 s. Mean Reward: 2.000. Mean Group Reward: 4.500. "
        "Training. ELO: 1210.250."
    )


def test_console_writer_logs_with_injected_clock(caplog):
    now = [100.0]
    logger = logging.getLogger("test.console")
    writer = ConsoleWriter(logger, clock=lambda: now[0])
    reporter = StatsReporter([writer])
    reporter.add("Ball", "Environment/Cumulative Reward", 1.0)
    now[0] = 112.5
    with caplog.at_level(logging.INFO, logger="test.console"):
        reporter.write("Ball", 500, is_training=True)
        reporter.add_property("Ball", "hyperparameters", {"trainer_type": "ppo", "hyperparameters": {"batch_size": 64}})
    assert caplog.messages[0] == (
        "Ball. Step: 500. Time Elapsed: 12.500 s. Mean Reward: 1.000. Std of Reward: 0.000. Training."
    )
    assert caplog.messages[1] == (
        "Hyperparameters for behavior name Ball: \n\ttrainer_type:\tppo\n\thyperparameters:\t\n\t  batch_size:\t64"
    )


def test_hyperparameters_dump_nesting():
    assert hyperparameters_dump({"a": {"b": {"c": 1}}, "d": None}) == "\ta:\t\n\t  b:\t\n\t    c:\t1\n\td:\tNone"


# ---------------------------------------------------------------------------------------------
# Progress line
# ---------------------------------------------------------------------------------------------
class FakeStream:
    def __init__(self) -> None:
        self.parts: list[str] = []

    def write(self, text: str) -> None:
        self.parts.append(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False

    @property
    def text(self) -> str:
        return "".join(self.parts)


def test_progress_line_text_matches_example():
    now = [0.0]
    progress = ProgressLine(FakeStream(), clock=lambda: now[0], is_tty=False)
    progress.update("Basic", 0, max_steps=5000)
    now[0] = 0.5
    progress.update("Basic", 1728, mean_reward=0.8124)
    # 1728 steps / 0.5 s = 3,456 steps/s; (5000-1728)/3456 = 0.95 s -> 0:00:01; 1728/5000 = 34%
    assert progress.render("Basic") == "Basic: step 1,728/5,000 (34%) · 3,456 steps/s · ETA 0:00:01 · mean reward 0.812"


def test_progress_line_non_tty_rate_limited_per_behavior():
    now = [0.0]
    stream = FakeStream()
    progress = ProgressLine(stream, interval=10.0, clock=lambda: now[0])
    progress.update("Basic", 0, max_steps=1000)
    now[0] = 4.0
    progress.update("Basic", 400)  # suppressed: 4 s < 10 s
    now[0] = 10.0
    progress.update("Basic", 1000)
    lines = stream.text.splitlines()
    assert lines == [
        "Basic: step 0/1,000 (0%) · -- steps/s · ETA --",
        "Basic: step 1,000/1,000 (100%) · 100 steps/s · ETA 0:00:00",
    ]
    assert "\r" not in stream.text


def test_progress_line_tty_rewrites_in_place_and_clears():
    now = [0.0]
    stream = FakeStream()
    progress = ProgressLine(stream, clock=lambda: now[0], is_tty=True, tty_interval=0.2)
    progress.update("A", 0)
    now[0] = 0.1
    progress.update("A", 5)  # within tty_interval: not drawn
    now[0] = 2.0
    progress.update("A", 5000)
    progress.update("B", 10, max_steps=20)  # same instant: not drawn
    now[0] = 2.5
    progress.update("B", 15)
    assert stream.parts[0] == "\rA: step 0 · -- steps/s"
    assert stream.parts[1] == "\rA: step 5,000 · 2,500 steps/s"
    expected = "A: step 5,000 · 2,000 steps/s | B: step 15/20 (75%) · 10 steps/s · ETA 0:00:00"
    assert stream.parts[2] == "\r" + expected
    progress.clear()
    assert stream.parts[3] == "\r" + " " * len(expected) + "\r"
    now[0] = 3.0
    progress.update("A", 6000)
    progress.close()
    assert stream.parts[-1] == "\n"


def test_console_writer_clears_tty_progress_before_logging(caplog):
    stream = FakeStream()
    progress = ProgressLine(stream, clock=lambda: 0.0, is_tty=True)
    progress.update("A", 3)
    writer = ConsoleWriter(logging.getLogger("test.console2"), clock=lambda: 0.0, progress=progress)
    with caplog.at_level(logging.INFO, logger="test.console2"):
        writer.write_stats("A", {}, 3)
    drawn = "A: step 3 · -- steps/s"
    assert stream.parts == ["\r" + drawn, "\r" + " " * len(drawn) + "\r"]
    assert caplog.messages == ["A. Step: 3. Time Elapsed: 0.000 s. No episode was completed since last summary. Not Training."]
