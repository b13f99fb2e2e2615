"""--record-video's CPU budget (trainer/artifacts/clips.py): which checkpoints get a clip, with a
hand-driven clock and a stand-in renderer that answers the CPU seconds it is told to, so every
number below is computed by hand: budget = 0.04 x 2 CPUs x elapsed = 0.08 s per second."""
from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest

from trainer.artifacts.clips import CPU_SHARE, ClipRecorder, within_budget

# Films nothing: for each request it waits for VIDEO.go (so a test decides when a clip is done),
# writes the request into VIDEO, and answers start-up 2 CPU-s plus 3 CPU-s per clip.
RENDERER = textwrap.dedent("""
    import json, os, sys, time
    made = 0
    for line in sys.stdin:
        request = json.loads(line)
        while not os.path.exists(request["video"] + ".go"):
            time.sleep(0.01)
        with open(request["video"], "w") as f:
            json.dump(request, f)
        made += 1
        print(json.dumps({"ok": True, "message": "made", "clip_cpu": 3.0, "cpu": 2.0 + 3.0 * made}), flush=True)
""")


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def setup(tmp_path):
    clock = Clock()
    model = tmp_path / "B" / "B-1.onnx"
    model.parent.mkdir()
    model.write_bytes(b"onnx")
    recorder = ClipRecorder("ball3d", 7, str(tmp_path / "run_logs" / "clips.log"), side_channel=lambda: b"\x01\x02",
                            stub_args=["--decision-period", "5"], clock=clock, cpus=2,
                            renderer=[sys.executable, "-c", RENDERER], first_estimate=4.0)
    yield recorder, clock, model
    for request in [recorder.in_flight, *recorder.waiting]:  # let a clip the test left waiting finish
        if request is not None:
            Path(request["video"] + ".go").touch()
    recorder.finish(timeout=60)


def release(model: Path, step: int) -> None:
    Path(f"{model.parent / f'B-{step}.mp4'}.go").touch()


def test_the_rule_in_numbers():
    assert CPU_SHARE == 0.04
    assert within_budget(0.0, 4.0, 50.0, 2)  # 4 <= 0.04 * 2 * 50 = 4
    assert not within_budget(0.0, 4.0, 49.0, 2)  # 4 > 3.92
    assert not within_budget(5.0, 3.0, 90.0, 2)  # 8 > 7.2
    assert within_budget(5.0, 3.0, 100.0, 2)  # 8 <= 8
    assert within_budget(5.0, 3.0, 50.0, 4)  # 8 <= 0.04 * 4 * 50 = 8


def test_checkpoints_are_filmed_as_the_budget_allows(setup):
    recorder, clock, model = setup
    clock.now = 1010.0  # 0 + 4 > 0.8
    assert not recorder.after_checkpoint("B", str(model), 10)
    assert recorder.process is None  # nothing started for a clip it does not make
    clock.now = 1050.0  # 0 + 4 <= 4.0
    assert recorder.after_checkpoint("B", str(model), 50)
    release(model, 50)
    assert recorder.wait_idle(60)
    assert (recorder.spent, recorder.estimate) == (5.0, 3.0)  # start-up 2 + the clip 3; the next ~3
    clock.now = 1090.0  # 5 + 3 > 7.2
    assert not recorder.after_checkpoint("B", str(model), 90)
    clock.now = 1100.0  # 5 + 3 <= 8.0
    assert recorder.after_checkpoint("B", str(model), 100)
    release(model, 100)
    assert recorder.wait_idle(60)
    assert recorder.spent == 8.0
    clock.now = 1101.0  # over budget (8 + 3 > 8.08), but the final checkpoint is always filmed
    assert recorder.after_checkpoint("B", str(model), 101, final=True)
    release(model, 101)
    recorder.finish(timeout=60)
    assert sorted(p.name for p in model.parent.glob("*.mp4")) == ["B-100.mp4", "B-101.mp4", "B-50.mp4"]
    request = json.loads((model.parent / "B-50.mp4").read_text())
    assert request["side_channel"] == "0102" and request["stub_args"] == ["--decision-period", "5"]
    assert request["seed"] == 7 and request["tensorboard"] == [str(model.parent / "clips"), "B/clip", 50]
    assert list((model.parent / "clips").iterdir()) == []  # the models' copies are gone


def test_a_busy_renderer_skips_checkpoints_but_the_final_one_waits_its_turn(setup):
    recorder, clock, model = setup
    clock.now = 2000.0  # a budget of 80 CPU-s: only the renderer being busy stops a clip
    assert recorder.after_checkpoint("B", str(model), 1)
    clock.now = 2001.0
    assert not recorder.after_checkpoint("B", str(model), 2)  # clip 1 is still being made
    assert recorder.after_checkpoint("B", str(model), 3, final=True)  # queued behind clip 1
    release(model, 1)
    release(model, 3)
    assert recorder.wait_idle(60)
    assert sorted(p.name for p in model.parent.glob("*.mp4")) == ["B-1.mp4", "B-3.mp4"]
    assert recorder.spent == 8.0  # 2 + 3 + 3


def test_a_renderer_that_dies_ends_the_clips_not_the_run(tmp_path, caplog):
    model = tmp_path / "B" / "B-1.onnx"
    model.parent.mkdir()
    model.write_bytes(b"onnx")
    clock = Clock()
    recorder = ClipRecorder("ball3d", 1, str(tmp_path / "clips.log"), clock=clock, cpus=2,
                            renderer=[sys.executable, "-c", "import sys; sys.exit(3)"], first_estimate=0.0)
    assert recorder.after_checkpoint("B", str(model), 1)
    assert recorder.wait_idle(60)  # the end of its answers counts as done
    assert recorder.broken and "the clip renderer stopped" in caplog.text
    assert not recorder.after_checkpoint("B", str(model), 2, final=True)
    recorder.finish(timeout=60)
    assert list((model.parent / "clips").iterdir()) == []
