"""timers.json (TimerTree) and training_status.json (TrainingStatus)."""
from __future__ import annotations

import json
import logging
import os

import pytest

import trainer
from trainer.artifacts.timers import TimerTree
from trainer.artifacts.training_status import CheckpointEntry, TrainingStatus
from trainer.errors import UserError


class FakeClock:
    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now


# ---------------------------------------------------------------------------------------------
# TimerTree
# ---------------------------------------------------------------------------------------------
def test_nested_scopes_counts_totals_and_self():
    clock = FakeClock(100.0)
    timers = TimerTree(clock=clock, wall_clock=lambda: 1_700_000_000.9, argv=["learn", "cfg.yaml"])
    for _ in range(3):
        with timers.scope("env_step"):
            clock.now += 1.0
            with timers.scope("communicate"):
                clock.now += 2.0
    with timers.scope("trainer_advance"):
        clock.now += 0.5
        with timers.scope("env_step"):  # same name elsewhere: a distinct node
            clock.now += 0.25
    clock.now += 0.25  # time in root itself
    tree = timers.to_dict()

    assert tree["name"] == "root"
    assert (tree["total"], tree["count"]) == (10.0, 1)  # 9 + 0.75 + 0.25
    assert tree["self"] == pytest.approx(0.25)
    env_step = tree["children"]["env_step"]
    assert (env_step["count"], env_step["total"], env_step["self"]) == (3, 9.0, 3.0)
    assert env_step["children"]["communicate"] == {"total": 6.0, "count": 3, "self": 6.0}
    advance = tree["children"]["trainer_advance"]
    assert (advance["total"], advance["self"]) == (0.75, 0.5)
    assert advance["children"]["env_step"]["count"] == 1
    assert list(tree) == ["name", "gauges", "metadata", "total", "count", "self", "children"]


def test_scope_records_time_even_when_block_raises():
    clock = FakeClock()
    timers = TimerTree(clock=clock)
    with pytest.raises(ValueError):
        with timers.scope("boom"):
            clock.now += 2.0
            raise ValueError
    with timers.scope("after"):
        pass
    children = timers.to_dict()["children"]
    assert children["boom"]["total"] == 2.0 and children["boom"]["count"] == 1
    assert "after" in children  # the stack was popped: "after" is a sibling, not a child


def test_gauges_value_min_max_count_and_nan_ignored():
    timers = TimerTree()
    for v in (3.0, -1.0, 7.5, 2.0, float("nan")):
        timers.set_gauge("Ball.Losses.ValueLoss.mean", v)
    assert timers.to_dict()["gauges"] == {
        "Ball.Losses.ValueLoss.mean": {"value": 2.0, "min": -1.0, "max": 7.5, "count": 4}
    }


def test_metadata_and_atomic_write(tmp_path):
    wall = FakeClock(1_700_000_000.7)
    timers = TimerTree(clock=FakeClock(), wall_clock=wall, argv=["mlagents-like-learn", "x.yaml", "--run-id=a"])
    wall.now = 1_700_000_123.2
    path = tmp_path / "run_logs" / "timers.json"
    timers.write(path)
    data = json.loads(path.read_text())
    meta = data["metadata"]
    assert meta["timer_format_version"] == "0.1.0"
    assert meta["start_time_seconds"] == "1700000000"
    assert meta["end_time_seconds"] == "1700000123"
    assert meta["command_line_arguments"] == "mlagents-like-learn x.yaml --run-id=a"
    assert meta["communication_protocol_version"] == "1.5.0"
    assert meta["mlagents_like_version"] == trainer.__version__
    assert meta["mlagents_version"] == trainer.__version__
    for key in ("python_version", "mlagents_envs_version", "pytorch_version", "numpy_version"):
        assert meta[key]
    assert os.listdir(path.parent) == ["timers.json"]  # no temp file left behind


# ---------------------------------------------------------------------------------------------
# TrainingStatus
# ---------------------------------------------------------------------------------------------
def entry(steps: int, reward: float | None = 1.0) -> CheckpointEntry:
    return CheckpointEntry(
        steps=steps,
        file_path=f"results/r/Ball/Ball-{steps}.onnx",
        reward=reward,
        creation_time=1_700_000_000.0 + steps,
        auxillary_file_paths=[f"results/r/Ball/Ball-{steps}.pt"],
    )


def test_round_trip_exact_layout(tmp_path):
    status = TrainingStatus()
    status.set_lesson_num("wall_height", 2)
    status.add_checkpoint("Ball", entry(792, reward=None), keep_checkpoints=5)
    status.set_final_checkpoint(
        "Ball", CheckpointEntry(1000, "results/r/Ball.onnx", 0.5, 1_700_000_500.0, ["results/r/Ball/Ball-1000.pt"])
    )
    path = tmp_path / "run_logs" / "training_status.json"
    status.save(path)
    raw = json.loads(path.read_text())
    assert raw["wall_height"] == {"lesson_num": 2}
    assert raw["Ball"]["checkpoints"] == [
        {
            "steps": 792,
            "file_path": "results/r/Ball/Ball-792.onnx",
            "reward": None,
            "creation_time": 1_700_000_792.0,
            "auxillary_file_paths": ["results/r/Ball/Ball-792.pt"],
        }
    ]
    assert raw["Ball"]["final_checkpoint"]["file_path"] == "results/r/Ball.onnx"
    assert raw["metadata"]["stats_format_version"] == "0.3.0"
    assert raw["metadata"]["mlagents_version"] == "1.1.0"
    assert set(raw["metadata"]) == {"stats_format_version", "mlagents_version", "torch_version"}
    assert os.listdir(path.parent) == ["training_status.json"]

    loaded = TrainingStatus.load(path)
    assert loaded.get_lesson_num("wall_height") == 2
    assert loaded.get_lesson_num("other") is None
    assert loaded.checkpoints("Ball") == [entry(792, reward=None)]
    assert loaded.final_checkpoint("Ball").steps == 1000
    assert loaded.to_dict() == raw


def test_keep_checkpoints_trims_oldest_and_returns_them():
    status = TrainingStatus()
    dropped_per_add = [status.add_checkpoint("Ball", entry(s), keep_checkpoints=2) for s in (100, 200, 300, 400)]
    assert dropped_per_add[:2] == [[], []]
    assert [[e.steps for e in d] for d in dropped_per_add[2:]] == [[100], [200]]
    assert dropped_per_add[2][0].auxillary_file_paths == ["results/r/Ball/Ball-100.pt"]
    assert [e.steps for e in status.checkpoints("Ball")] == [300, 400]
    # lowering keep_checkpoints (e.g. on resume) drops several at once
    assert [e.steps for e in status.add_checkpoint("Ball", entry(500), keep_checkpoints=1)] == [300, 400]
    # keep_checkpoints <= 0 keeps everything (ML-Agents behaviour)
    assert status.add_checkpoint("Ball", entry(600), keep_checkpoints=0) == []
    assert [e.steps for e in status.checkpoints("Ball")] == [500, 600]


def test_missing_metadata_is_a_user_error_naming_the_file(tmp_path):
    path = tmp_path / "training_status.json"
    path.write_text(json.dumps({"Ball": {"checkpoints": []}}))
    with pytest.raises(UserError, match="training_status.json has no 'metadata'"):
        TrainingStatus.load(path)
    path.write_text("{not json")
    with pytest.raises(UserError, match=str(path).replace("\\", "\\\\") + " is not valid JSON"):
        TrainingStatus.load(path)


def test_version_mismatch_only_warns_and_missing_file_is_empty(tmp_path, caplog):
    path = tmp_path / "training_status.json"
    saved = {
        "wall_height": {"lesson_num": 1},
        "Ball": {"elo": 1250.0},
        "metadata": {"stats_format_version": "0.3.0", "mlagents_version": "0.30.0", "torch_version": "1.0"},
    }
    path.write_text(json.dumps(saved))
    with caplog.at_level(logging.WARNING):
        status = TrainingStatus.load(path)
    assert status.get_lesson_num("wall_height") == 1
    assert status.state["Ball"] == {"elo": 1250.0}  # another trainer's values are kept as they are
    assert any("0.30.0" in m for m in caplog.messages)
    assert any("PyTorch 1.0" in m for m in caplog.messages)
    with caplog.at_level(logging.WARNING):
        empty = TrainingStatus.load(tmp_path / "nope.json")
    assert empty.state == {}
    assert any("not found" in m for m in caplog.messages)
