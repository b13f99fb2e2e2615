"""Round trip through the real ML-Agents 1.1.0: a spec captured by mlagents-like-learn from each
stub task, replayed by the stub's ``mirror`` task, presents the same BehaviorSpecs and agent
counts to mlagents_envs' UnityEnvironment as the tasks themselves; a hand-written spec's PNG
camera and two teams read back as written (docs/mirror.md)."""
from __future__ import annotations

import json
import sys

from protos.spec_file import SpecFile
from tests.integration.conftest import learn
from tests.interop.conftest import REPO

STUB = [sys.executable, "-m", "unity_stub_env.cli"]


def test_a_captured_spec_replays_the_same_behavior_specs(run_peer, free_port, tmp_path):
    capture = learn(["--capture-spec", "spec.json", "--env", "stub:basic,ball3d,dodge", "--num-areas", "2",
                     "--seed", "0", "--base-port", str(free_port())], tmp_path)
    assert capture.returncode == 0, capture.stdout + capture.stderr
    spec_path = str(tmp_path / "spec.json")
    assert [b.name for b in SpecFile.load(spec_path).behaviors] == ["Basic?team=0", "3DBall?team=0", "Dodge?team=0"]
    seen = {}
    for label, args in (("tasks", ["--task", "basic,ball3d,dodge"]), ("mirror", ["--task", "mirror", "--spec", spec_path])):
        done, out = run_peer("behavior_specs.py", {"port": free_port(), "cwd": str(REPO),
                                                   "stub": STUB + args + ["--num-areas", "2"]})
        assert out is not None, done.stdout[-3000:] + done.stderr[-3000:]
        assert out["stub_exit"] == 0
        seen[label] = out
    assert sorted(seen["mirror"]["specs"]) == ["3DBall?team=0", "Basic?team=0", "Dodge?team=0"]
    assert seen["mirror"]["specs"] == seen["tasks"]["specs"]
    agents = {name: step["agents"] for name, step in seen["tasks"]["steps"].items()}
    assert agents == {"Basic?team=0": 2, "3DBall?team=0": 24, "Dodge?team=0": 28}
    assert {name: step["agents"] for name, step in seen["mirror"]["steps"].items()} == agents


HAND = {"format_version": 1, "behaviors": [
    {"name": "Seeker?team=0", "observations": [{"name": "CameraSensor", "shape": [3, 20, 20], "compression": "png",
                                                 "dimension_properties": [1, 2, 2]},
                                                {"name": "Gray", "shape": [1, 8, 8], "compression": "png",
                                                 "dimension_properties": [0, 0, 0]},
                                                {"name": "Goal", "shape": [2], "observation_type": "goal_signal"}],
     "actions": {"continuous": 1, "discrete_branches": [3, 2]}, "agents": 3},
    {"name": "Striker?team=0", "observations": [{"name": "VectorSensor_size8", "shape": [8]}],
     "actions": {"discrete_branches": [3]}, "agents": 2, "groups_per_area": 1},
    {"name": "Striker?team=1", "observations": [{"name": "VectorSensor_size8", "shape": [8]}],
     "actions": {"discrete_branches": [3]}, "agents": 2, "groups_per_area": 1},
]}


def test_png_cameras_goals_teams_and_groups_read_back_in_mlagents(run_peer, free_port, tmp_path):
    (tmp_path / "hand.json").write_text(json.dumps(HAND))
    done, out = run_peer("behavior_specs.py", {"port": free_port(), "cwd": str(REPO),
                                               "stub": STUB + ["--task", f"mirror={tmp_path / 'hand.json'}"]})
    assert out is not None, done.stdout[-3000:] + done.stderr[-3000:]
    seeker = out["specs"]["Seeker?team=0"]
    assert [o["shape"] for o in seeker["observations"]] == [[3, 20, 20], [1, 8, 8], [2]]
    assert [o["dimension_property"] for o in seeker["observations"]] == [[1, 2, 2], [0, 0, 0], [1]]
    assert [o["observation_type"] for o in seeker["observations"]] == [0, 0, 1]
    assert (seeker["continuous"], seeker["discrete_branches"]) == (1, [3, 2])
    camera_range, gray_range, _ = out["steps"]["Seeker?team=0"]["obs_range"]
    assert 0.0 <= camera_range[0] < camera_range[1] <= 1.0 and 0.0 <= gray_range[0] <= gray_range[1] <= 1.0
    assert sorted(out["specs"]) == ["Seeker?team=0", "Striker?team=0", "Striker?team=1"]
    assert out["steps"]["Striker?team=1"] == {**out["steps"]["Striker?team=1"], "agents": 2, "group_ids": [1]}
    assert out["stub_exit"] == 0
