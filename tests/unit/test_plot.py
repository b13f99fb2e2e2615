"""mlagents-like-plot: the CSV holds exactly the drawn values, checked against event files written
with known scalars (hand-computed means and Student-t bands), and the picture is drawn."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from tensorboard.compat.proto import event_pb2, summary_pb2

from trainer.artifacts.tensorboard import EventFile
from trainer.plot import DEFAULT_TAG, main

STEPS = (1000, 2000, 3000, 4000)


def write_run(folder, values, tag=DEFAULT_TAG, start=100.0, steps=STEPS):
    folder.mkdir(parents=True)
    clock = iter([start] + [start + 10.0 * i for i in range(1, len(values) + 1)])
    events = EventFile(str(folder), lambda: next(clock))
    for step, value in zip(steps, values):
        summary = summary_pb2.Summary(value=[summary_pb2.Summary.Value(tag=tag, simple_value=value)])
        events.add_event(event_pb2.Event(wall_time=next(clock), step=step, summary=summary))
    events.close()


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture
def sweep(tmp_path):
    runs = {"ppo-seed1": [0.0, 1.0, 2.0, 3.0], "ppo-seed2": [1.0, 2.0, 4.0, 4.0], "ppo-seed3": [2.0, 3.0, 3.0, 5.0],
            "sac-seed1": [0.5, 0.25, 0.75, 1.0]}
    for name, values in runs.items():
        write_run(tmp_path / "results" / name / "Basic", values)
    return tmp_path, runs


def test_csv_holds_each_runs_values(sweep, capsys):
    tmp, runs = sweep
    assert main([str(tmp / "results"), "-o", str(tmp / "c.png"), "--csv", str(tmp / "c.csv")]) == 0
    rows = read_csv(tmp / "c.csv")
    assert [r["curve"] for r in rows[::4]] == [f"results/{name}/Basic" for name in sorted(runs)]
    for name, values in runs.items():
        mine = [r for r in rows if r["curve"] == f"results/{name}/Basic"]
        assert [float(r["x"]) for r in mine] == list(STEPS)
        assert [float(r["y"]) for r in mine] == values
        assert all(r["y_low"] == "" and r["runs"] == "1" for r in mine)
    assert (tmp / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_groups_are_mean_and_student_t_band(sweep):
    tmp, runs = sweep
    assert main([str(tmp / "results"), "-o", str(tmp / "g.png"), "--csv", str(tmp / "g.csv"),
                 "--group", r"/(\w+)-seed"]) == 0
    rows = read_csv(tmp / "g.csv")
    ppo = [r for r in rows if r["curve"] == "ppo"]
    table = np.array([runs[f"ppo-seed{i}"] for i in (1, 2, 3)])
    for i, r in enumerate(ppo):
        mean = table[:, i].mean()
        half = 4.303 * table[:, i].std(ddof=1) / math.sqrt(3)  # t(0.975, 2 dof)
        assert r["runs"] == "3"
        assert float(r["y"]) == pytest.approx(mean, abs=1e-12)
        assert float(r["y_low"]) == pytest.approx(mean - half, abs=1e-12)
        assert float(r["y_high"]) == pytest.approx(mean + half, abs=1e-12)
    assert [float(r["y"]) for r in rows if r["curve"] == "sac"] == runs["sac-seed1"]  # a group of one: no band


def test_smoothing_and_time_axis(sweep):
    tmp, runs = sweep
    assert main([str(tmp / "results" / "ppo-seed2"), "-o", str(tmp / "s.png"), "--csv", str(tmp / "s.csv"),
                 "--smooth", "2", "--x", "time"]) == 0
    rows = read_csv(tmp / "s.csv")
    assert [float(r["y"]) for r in rows] == [1.0, 1.5, 3.0, 4.0]  # trailing mean of 2: 1, (1+2)/2, (2+4)/2, (4+4)/2
    assert [float(r["x"]) for r in rows] == [0.0, 10.0, 20.0, 30.0]  # seconds since the first summary


@pytest.mark.parametrize("args, words", [(["--tag", "Nope"], "no run has the scalar"),
                                          (["--group", "("], "not a regular expression"),
                                          (["--smooth", "0"], "--smooth must be 1 or more")])
def test_bad_input_is_one_message(sweep, capsys, args, words):
    tmp, _ = sweep
    assert main([str(tmp / "results"), "-o", str(tmp / "x.png"), *args]) == 2
    assert words in capsys.readouterr().err
    assert main([str(tmp / "nothing"), "-o", str(tmp / "x.png")]) == 2


def test_sweep_summary_and_plot_agree(tmp_path):
    """A sweep's folder: runs named by setting and seed, grouped by setting; sweep.sh summary's
    seed means are the plot's last drawn points."""
    import os
    import subprocess
    import sys

    results = tmp_path / "results"
    sweep = results / "sweeps" / "sw"
    sweep.mkdir(parents=True)
    rows = [(0, 4, 0.9, [0.0, 1.0, 2.0, 3.0]), (1, 5, 0.9, [1.0, 2.0, 4.0, 5.0]),
            (2, 4, 0.95, [0.0, 0.0, 1.0, 1.0]), (3, 5, 0.95, [0.0, 1.0, 1.0, 2.0])]
    (sweep / "plan.tsv").write_text("element\trun_id\tseed\tbehaviors.Basic.hyperparameters.lambd\n" + "".join(
        f"{i}\tsw_{i}\t{seed}\t{lambd}\n" for i, seed, lambd, _ in rows))
    for i, _, _, values in rows:
        write_run(results / f"sw_{i}" / "Basic", values)
    assert main([str(sweep), "-o", str(tmp_path / "p.png"), "--csv", str(tmp_path / "p.csv")]) == 0
    drawn = read_csv(tmp_path / "p.csv")
    last = {r["curve"]: r for r in drawn if float(r["x"]) == STEPS[-1]}
    assert sorted(last) == ["lambd=0.9/Basic", "lambd=0.95/Basic"]
    assert float(last["lambd=0.9/Basic"]["y"]) == 4.0 and last["lambd=0.9/Basic"]["runs"] == "2"
    half = 12.706 * np.std([3.0, 5.0], ddof=1) / math.sqrt(2)
    assert float(last["lambd=0.9/Basic"]["y_high"]) == pytest.approx(4.0 + half)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    out = subprocess.run([sys.executable, os.path.join(root, "docker", "slurm", "sweep.py"), "summary", str(sweep)],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": root}).stdout
    table = out.split("mean over seeds")[1].splitlines()[2:]
    summary = {line.split()[0]: line.split() for line in table if line.strip()}
    for name, r in last.items():
        assert summary[name][1:4] == [r["runs"], "4000", f"{float(r['y']):.4f}"]
        assert summary[name][4] == f"{float(r['y_low']):.4f}"
