"""behaviors.json: the format (protos/spec_file.py) and what a run records into it
(trainer/artifacts/behaviors.py), checked against hand-built specs and steps."""
from __future__ import annotations

import json

import numpy as np
import pytest

from protos.spec_file import BehaviorRecord, SpecFile, SpecFileError
from protos.types import (
    ActionSpec,
    BehaviorSpec,
    DecisionSteps,
    DimensionProperty as D,
    ObservationSpec,
    ObservationType,
    StepResult,
    TerminalSteps,
)
from trainer.artifacts.behaviors import COUNT_STEPS, BehaviorRecorder

CAMERA = ObservationSpec((3, 24, 32), (D.NONE, D.TRANSLATIONAL_EQUIVARIANCE, D.TRANSLATIONAL_EQUIVARIANCE),
                         ObservationType.DEFAULT, "Camera")
VECTOR = ObservationSpec((6,), (D.NONE,), ObservationType.GOAL_SIGNAL, "Goal")
SPEC = BehaviorSpec((CAMERA, VECTOR), ActionSpec(2, (3, 2)))


def _spec_file() -> SpecFile:
    return SpecFile(
        behaviors=(BehaviorRecord("Striker?team=1", SPEC, ("png", "none"), agents=4, agents_per_area=2,
                                  groups_per_area=1, action_mask=True, decision_period=5, max_step=3000),),
        num_areas=2, environment_parameters=("gravity",), stats=("Game/Goals",), source="builds/Soccer")


def test_a_spec_file_survives_json_unchanged():
    original = _spec_file()
    again = SpecFile.loads(original.dumps())
    assert again == original
    record = again.behaviors[0]
    assert (record.brain_name, record.team_id) == ("Striker", 1)
    assert record.spec.observation_specs[0].dimension_property == (1, 2, 2)
    assert record.spec.observation_specs[1].observation_type == ObservationType.GOAL_SIGNAL


def test_the_written_layout_is_the_documented_one():
    raw = json.loads(_spec_file().dumps())
    assert raw["format_version"] == 1 and raw["num_areas"] == 2
    assert raw["behaviors"][0]["observations"][0] == {
        "name": "Camera", "shape": [3, 24, 32], "dimension_properties": [1, 2, 2],
        "observation_type": "default", "compression": "png"}
    assert raw["behaviors"][0]["actions"] == {"continuous": 2, "discrete_branches": [3, 2]}


def test_a_hand_written_minimal_entry_gets_the_defaults():
    spec = SpecFile.from_dict({"format_version": 1, "behaviors": [
        {"name": "Walker", "observations": [{"shape": [12]}], "actions": {"continuous": 3}}]})
    record = spec.behaviors[0]
    assert record.name == "Walker?team=0" and record.agents == 1 and record.compressions == ("none",)
    assert record.spec.observation_specs[0].dimension_property == (D.NONE,)
    camera = SpecFile.from_dict({"format_version": 1, "behaviors": [
        {"name": "Eye", "observations": [{"shape": [3, 36, 36], "compression": "png"}],
         "actions": {"discrete_branches": [2]}}]}).behaviors[0].spec.observation_specs[0]
    assert camera.dimension_property == (D.NONE, D.TRANSLATIONAL_EQUIVARIANCE, D.TRANSLATIONAL_EQUIVARIANCE)
    assert record.decision_period is None and record.max_step is None


@pytest.mark.parametrize("raw, message", [
    ({"format_version": 2, "behaviors": []}, "format_version 2 is not supported"),
    ({"format_version": 1, "behaviors": []}, "'behaviors' must be a non-empty list"),
    ({"format_version": 1, "behaviors": [{"name": "A", "observations": [{"shape": [4], "compression": "png"}],
                                           "actions": {"continuous": 1}}]}, "png only for rank-3"),
    ({"format_version": 1, "behaviors": [{"name": "A", "observations": [{"shape": [0]}],
                                           "actions": {"continuous": 1}}]}, "positive integers"),
    ({"format_version": 1, "behaviors": [{"name": "A", "observations": [{"shape": [4]}], "actions": {}}]},
     "neither continuous actions nor discrete branches"),
    ({"format_version": 1, "behaviors": [{"name": "A", "observations": [{"shape": [4]}], "actions": {"continuous": 1}},
                                          {"name": "A?team=0", "observations": [{"shape": [4]}],
                                           "actions": {"continuous": 1}}]}, "appears twice"),
])
def test_a_bad_file_names_the_problem(raw, message):
    with pytest.raises(SpecFileError, match=message):
        SpecFile.from_dict(raw, "spec.json")


def test_a_missing_file_is_one_clear_error(tmp_path):
    with pytest.raises(SpecFileError, match="cannot read the behavior spec file"):
        SpecFile.load(str(tmp_path / "nope.json"))


def _steps(n: int, groups=None, mask_true=False) -> tuple[DecisionSteps, TerminalSteps]:
    masks = [np.zeros((n, 3), bool), np.zeros((n, 2), bool)]
    if mask_true:
        masks[0][0, 1] = True
    decision = DecisionSteps(
        obs=[np.zeros((n, *o.shape), np.float32) for o in SPEC.observation_specs],
        reward=np.zeros(n, np.float32), agent_id=np.arange(n), action_mask=masks,
        group_id=np.zeros(n, np.int32) if groups is None else np.asarray(groups, np.int32),
        group_reward=np.zeros(n, np.float32))
    return decision, TerminalSteps.empty(SPEC)


def test_the_recorder_counts_agents_groups_masks_and_stats(tmp_path):
    recorder = BehaviorRecorder(num_areas=2, source="stub:x", environment_parameters=("gravity",))
    name = "Striker?team=1"
    recorder.observe([StepResult(specs={name: SPEC}, steps={name: _steps(3)},
                                 compressions={name: ("png", "none")})])
    recorder.observe([StepResult(steps={name: _steps(4, groups=[1, 1, 2, 2])})])  # a fourth agent joined
    recorder.observe([StepResult(steps={name: _steps(2, mask_true=True)})])
    recorder.observe_stats(["Game/Goals", "Game/Goals", "Game/Fouls"])
    spec = recorder.spec_file()
    record = spec.behaviors[0]
    assert (record.agents, record.agents_per_area, record.groups_per_area, record.action_mask) == (4, 2, 1, True)
    assert record.compressions == ("png", "none") and record.spec == SPEC
    assert spec.stats == ("Game/Goals", "Game/Fouls") and spec.environment_parameters == ("gravity",)
    path = tmp_path / "run_logs" / "behaviors.json"
    assert recorder.write(str(path))
    assert SpecFile.load(str(path)) == spec


def test_the_recorder_stops_counting_after_its_window_but_still_sees_new_behaviors():
    recorder = BehaviorRecorder(num_areas=1)
    name = "Striker?team=0"
    recorder.observe([StepResult(specs={name: SPEC}, steps={name: _steps(2)})])
    for _ in range(COUNT_STEPS):
        recorder.observe([StepResult(steps={name: _steps(2)})])
    late = "Late?team=0"
    recorder.observe([StepResult(specs={late: SPEC}, steps={name: _steps(9), late: _steps(1)})])
    records = {b.name: b for b in recorder.spec_file().behaviors}
    assert records[name].agents == 2  # the 9 after the window are not counted
    assert records[late].agents == 1 and records[late].compressions == ("none", "none")


def test_nothing_is_written_before_a_behavior_was_met(tmp_path):
    assert not BehaviorRecorder(1).write(str(tmp_path / "b.json"))
    assert not (tmp_path / "b.json").exists()
