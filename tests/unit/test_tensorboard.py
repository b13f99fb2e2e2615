"""TensorBoard events written by TensorboardWriter, read back with tensorboard's EventAccumulator."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.compat.proto import event_pb2

from trainer.artifacts.stats import StatsAggregationMethod as Agg, StatsReporter
from trainer.artifacts.tensorboard import TensorboardWriter, hyperparameters_markdown

EVERYTHING = {"scalars": 0, "histograms": 0, "tensors": 0, "compressedHistograms": 0, "images": 0, "audio": 0}


def load(directory: str) -> EventAccumulator:
    acc = EventAccumulator(directory, size_guidance=EVERYTHING)
    acc.Reload()
    return acc


def event_files(directory: str) -> list[str]:
    return sorted(n for n in os.listdir(directory) if n.startswith("events.out.tfevents"))


@pytest.fixture()
def reporter_and_writer(tmp_path):
    writer = TensorboardWriter(tmp_path / "run")
    reporter = StatsReporter([writer])
    yield reporter, writer
    writer.close()


def test_scalars_exact_values_and_steps(tmp_path, reporter_and_writer):
    reporter, _ = reporter_and_writer
    reporter.add("Ball", "Policy/Entropy", 1.0)
    reporter.add("Ball", "Policy/Entropy", 2.0)
    reporter.add_many("Ball", "Custom/Coins", np.array([0.25, 0.5, 2.0]), Agg.SUM)
    reporter.add("Ball", "Custom/Latest", 3.0, Agg.MOST_RECENT)
    reporter.add("Ball", "Custom/Latest", 7.0, Agg.MOST_RECENT)
    reporter.set("Ball", "Step", 1000.0)
    reporter.write("Ball", 1000, is_training=True)
    reporter.add("Ball", "Policy/Entropy", -0.5)
    reporter.write("Ball", 2000, is_training=False)

    acc = load(str(tmp_path / "run" / "Ball"))  # read back while the writer is still open
    entropy = [(e.step, e.value) for e in acc.Scalars("Policy/Entropy")]
    assert entropy == [(1000, 1.5), (2000, -0.5)]
    assert [(e.step, e.value) for e in acc.Scalars("Custom/Coins")] == [(1000, 2.75)]  # sum, not mean
    assert [(e.step, e.value) for e in acc.Scalars("Custom/Latest")] == [(1000, 7.0)]
    tags = acc.Tags()
    assert "Is Training" not in tags["scalars"]
    assert "Step" not in tags["scalars"]
    assert set(tags["scalars"]) == {"Policy/Entropy", "Custom/Coins", "Custom/Latest"}


def test_cumulative_reward_scalar_and_histogram(tmp_path, reporter_and_writer):
    reporter, _ = reporter_and_writer
    rewards = np.array([1.0, 2.0, 2.0, 5.0])
    reporter.add_many("Ball", "Environment/Cumulative Reward", rewards)
    reporter.write("Ball", 3000)
    acc = load(str(tmp_path / "run" / "Ball"))
    [scalar] = acc.Scalars("Environment/Cumulative Reward")
    assert (scalar.step, scalar.value) == (3000, 2.5)
    [hist_event] = acc.Histograms("Environment/Cumulative Reward_hist")
    hist = hist_event.histogram_value
    assert hist_event.step == 3000
    assert (hist.min, hist.max, hist.num) == (1.0, 5.0, 4.0)
    assert hist.sum == 10.0
    assert hist.sum_squares == 1.0 + 4.0 + 4.0 + 25.0
    # 4 values -> 4 equal buckets of width 1 over [1, 5]: [1,2) [2,3) [3,4) [4,5]
    assert list(hist.bucket_limit) == [2.0, 3.0, 4.0, 5.0]
    assert list(hist.bucket) == [1.0, 2.0, 0.0, 1.0]


def test_single_value_histogram_has_one_bucket(tmp_path, reporter_and_writer):
    reporter, _ = reporter_and_writer
    reporter.add("Ball", "Custom/Dist", 4.0, Agg.HISTOGRAM)
    reporter.add("Ball", "Custom/Dist", 4.0, Agg.HISTOGRAM)
    reporter.write("Ball", 1)
    acc = load(str(tmp_path / "run" / "Ball"))
    hist = acc.Histograms("Custom/Dist_hist")[0].histogram_value
    assert list(hist.bucket) == [2.0] and list(hist.bucket_limit) == [4.0]
    assert acc.Scalars("Custom/Dist")[0].value == 4.0


def test_hyperparameters_text_summary(tmp_path, reporter_and_writer):
    reporter, _ = reporter_and_writer
    settings = {"trainer_type": "ppo", "hyperparameters": {"batch_size": 64, "learning_rate": 0.0003}, "init_path": None}
    reporter.add_property("Ball", "hyperparameters", settings)
    acc = load(str(tmp_path / "run" / "Ball"))
    [event] = acc.Tensors("Hyperparameters/text_summary")
    text = event.tensor_proto.string_val[0].decode("utf-8")
    assert event.step == 0
    assert text == (
        "| Parameter | Value |\n|---|---|\n"
        "| trainer_type | ppo |\n"
        "| hyperparameters.batch_size | 64 |\n"
        "| hyperparameters.learning_rate | 0.0003 |\n"
        "| init_path | None |"
    )
    assert acc.summary_metadata["Hyperparameters/text_summary"].plugin_data.plugin_name == "text"


def test_write_text_any_tag(tmp_path, reporter_and_writer):
    reporter, _ = reporter_and_writer
    reporter.write_text("Ball", "Notes", "a | b", 42)
    acc = load(str(tmp_path / "run" / "Ball"))
    [event] = acc.Tensors("Notes/text_summary")
    assert (event.step, event.tensor_proto.string_val[0]) == (42, b"a | b")


def test_one_run_per_brain(tmp_path, reporter_and_writer):
    reporter, _ = reporter_and_writer
    reporter.add("Ball", "Policy/Entropy", 1.0)
    reporter.add("Crawler", "Policy/Entropy", 2.0)
    reporter.write("Ball", 10)
    reporter.write("Crawler", 20)
    assert len(event_files(str(tmp_path / "run" / "Ball"))) == 1
    assert len(event_files(str(tmp_path / "run" / "Crawler"))) == 1
    assert [(e.step, e.value) for e in load(str(tmp_path / "run" / "Crawler")).Scalars("Policy/Entropy")] == [(20, 2.0)]


def test_clear_existing_and_clear_past_data(tmp_path):
    brain_dir = tmp_path / "run" / "Ball"
    brain_dir.mkdir(parents=True)
    (brain_dir / "events.out.tfevents.1.old").write_bytes(b"stale")
    (brain_dir / "Ball-100.onnx").write_bytes(b"model")

    kept = TensorboardWriter(tmp_path / "run")  # default: keep old runs (--resume)
    StatsReporter([kept]).add("Ball", "x", 1.0)
    kept.write_stats("Ball", {}, 0)
    kept.add_property("Ball", "hyperparameters", {"a": 1})
    assert "events.out.tfevents.1.old" in event_files(str(brain_dir))
    assert len(event_files(str(brain_dir))) == 2
    deleted = kept.clear_existing("Ball")
    assert len(deleted) == 2 and event_files(str(brain_dir)) == []
    assert (brain_dir / "Ball-100.onnx").exists()
    kept.close()

    (brain_dir / "events.out.tfevents.2.old").write_bytes(b"stale")
    forced = TensorboardWriter(tmp_path / "run", clear_past_data=True)
    reporter = StatsReporter([forced])
    reporter.add("Ball", "Policy/Entropy", 0.75)
    reporter.write("Ball", 5)
    forced.close()
    files = event_files(str(brain_dir))
    assert len(files) == 1 and not files[0].endswith(".old")
    assert [(e.step, e.value) for e in load(str(brain_dir)).Scalars("Policy/Entropy")] == [(5, 0.75)]


def test_markdown_escapes_pipes_and_empty_dicts():
    assert hyperparameters_markdown({"a": "x|y", "b": {}}) == (
        "| Parameter | Value |\n|---|---|\n| a | x\\|y |\n| b | {} |"
    )


def test_crc32c_and_tfrecord_framing_by_hand(tmp_path):
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

    from trainer.artifacts.tensorboard import EventFile, crc32c, masked_crc32c

    assert crc32c(b"123456789") == 0xE3069283  # the standard CRC-32C check value
    assert crc32c(b"") == 0
    # masking: rotate right by 15, add 0xa282ead8 (mod 2**32)
    crc = 0xE3069283
    assert masked_crc32c(b"123456789") == (((crc >> 15) | (crc << 17)) + 0xA282EAD8) % 2**32
    events = EventFile(str(tmp_path), wall_clock=lambda: 1234567890.5)
    events.add_event(event_pb2.Event(step=7, wall_time=1.0))
    events.close()
    assert Path(events.path).name.startswith("events.out.tfevents.1234567890.")
    raw = Path(events.path).read_bytes()
    first = event_pb2.Event(wall_time=1234567890.5, file_version="brain.Event:2").SerializeToString()
    header = len(first).to_bytes(8, "little")
    assert raw.startswith(header + masked_crc32c(header).to_bytes(4, "little") + first
                          + masked_crc32c(first).to_bytes(4, "little"))
    loaded = list(EventFileLoader(events.path).Load())  # tensorboard's reader checks both CRCs
    assert [e.file_version for e in loaded] == ["brain.Event:2", ""] and loaded[1].step == 7


def test_resume_from_drops_what_a_killed_run_wrote_after_its_checkpoint(tmp_path):
    """A run killed at step 500 whose last checkpoint was at step 300: the resumed run writes
    400 and 500 again. TensorBoard's own loader must show each step once, with the new values."""
    killed = TensorboardWriter(tmp_path, wall_clock=lambda: 1000.0)
    reporter = StatsReporter([killed])
    for step in (100, 200, 300, 400, 500):
        reporter.add("Ball", "Policy/Entropy", float(step))
        reporter.write("Ball", step)
    killed.close()  # as a SIGKILL leaves it: flushed after every write
    resumed = TensorboardWriter(tmp_path, wall_clock=lambda: 2000.0)  # a later file
    reporter = StatsReporter([resumed])
    reporter.resume_from("Ball", 300)
    for step in (400, 500, 600):
        reporter.add("Ball", "Policy/Entropy", step + 0.5)
        reporter.write("Ball", step)
    resumed.close()
    assert len(event_files(str(tmp_path / "Ball"))) == 2
    curve = [(e.step, e.value) for e in load(str(tmp_path / "Ball")).Scalars("Policy/Entropy")]
    assert curve == [(100, 100.0), (200, 200.0), (300, 300.0), (400, 400.5), (500, 500.5), (600, 600.5)]


def test_resume_from_after_a_graceful_stop_drops_nothing(tmp_path):
    first = TensorboardWriter(tmp_path, wall_clock=lambda: 1000.0)
    reporter = StatsReporter([first])
    for step in (100, 200):
        reporter.add("Ball", "Policy/Entropy", float(step))
        reporter.write("Ball", step)
    first.close()
    second = TensorboardWriter(tmp_path, wall_clock=lambda: 2000.0)
    reporter = StatsReporter([second])
    reporter.resume_from("Ball", 250)  # the final checkpoint came after the last summary
    reporter.add("Ball", "Policy/Entropy", 300.0)
    reporter.write("Ball", 300)
    second.close()
    assert [e.step for e in load(str(tmp_path / "Ball")).Scalars("Policy/Entropy")] == [100, 200, 300]
