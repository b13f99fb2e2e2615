"""``mlagents-like-learn CONFIG --check --spec FILE`` (trainer/config/spec_check.py): one line per
problem and exit 2, or one OK line and exit 0; no simulator and no results folder."""
from __future__ import annotations

import textwrap

import pytest

from protos.spec_file import BehaviorRecord, SpecFile
from protos.types import ActionSpec, BehaviorSpec, DimensionProperty as D, ObservationSpec, ObservationType
from trainer.cli import main

CAMERA = ObservationSpec((3, 30, 30), (D.NONE, D.TRANSLATIONAL_EQUIVARIANCE, D.TRANSLATIONAL_EQUIVARIANCE),
                         ObservationType.DEFAULT, "CameraSensor")
VECTOR = ObservationSpec((8,), (D.NONE,), ObservationType.DEFAULT, "VectorSensor_size8")
SPEC = SpecFile(behaviors=(
    BehaviorRecord("Walker?team=0", BehaviorSpec((CAMERA, VECTOR), ActionSpec(2, ())), ("png", "none"), agents=4,
                   agents_per_area=4),
    BehaviorRecord("Striker?team=0", BehaviorSpec((VECTOR,), ActionSpec(0, (3,))), ("none",), agents=2,
                   agents_per_area=2),
    BehaviorRecord("Striker?team=1", BehaviorSpec((VECTOR,), ActionSpec(0, (3,))), ("none",), agents=2,
                   agents_per_area=2),
), num_areas=1)

GOOD = """
behaviors:
  Walker:
    trainer_type: ppo
    hyperparameters: {batch_size: 64, buffer_size: 640}
    network_settings: {vis_encode_type: simple, memory: {sequence_length: 16, memory_size: 32}}
    time_horizon: 32
  Striker:
    trainer_type: ppo
environment_parameters:
  difficulty:
    curriculum:
      - name: easy
        completion_criteria: {measure: reward, behavior: Striker, threshold: 0.5}
        value: 0.0
      - name: hard
        value: 1.0
"""

BAD = """
behaviors:
  Walker:
    trainer_type: ppo
    hyperparameters: {batch_size: 100, buffer_size: 1000}
    network_settings: {vis_encode_type: nature_cnn, memory: {sequence_length: 48, memory_size: 32}}
    time_horizon: 32
  Strikr:
    trainer_type: ppo
environment_parameters:
  difficulty:
    curriculum:
      - name: easy
        completion_criteria: {measure: reward, behavior: Strikr, threshold: 0.5}
        value: 0.0
      - name: hard
        value: 1.0
"""


@pytest.fixture
def files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "spec.json").write_text(SPEC.dumps())

    def write(name, text):
        (tmp_path / name).write_text(textwrap.dedent(text))
        return name
    return write


def test_a_fitting_yaml_passes_with_one_line(files, capsys):
    assert main([files("good.yaml", GOOD), "--check", "--spec", "spec.json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out == ["spec.json: good.yaml fits the 3 behavior(s) of the spec (Walker?team=0, Striker?team=0, "
                   "Striker?team=1)."]


def test_every_problem_is_one_line_and_the_exit_code_is_2(files, capsys, tmp_path):
    assert main([files("bad.yaml", BAD), "--check", "--spec", "spec.json", "--num-areas", "2"]) == 2
    lines = capsys.readouterr().out.strip().splitlines()
    assert all(line.startswith("spec.json: ") for line in lines)
    text = "\n".join(lines)
    expected = [
        "behavior 'Striker' is in the spec but not under 'behaviors'",
        "'behaviors.Strikr' in bad.yaml names no behavior of the spec",
        "'behaviors.Walker.network_settings.memory.sequence_length' (48) is longer than time_horizon (32)",
        "'behaviors.Walker.hyperparameters.batch_size' (100) is not a multiple of memory.sequence_length (48): "
        "it is rounded down to 96",
        "'behaviors.Walker.network_settings.vis_encode_type' nature_cnn needs cameras of at least 36x36, but "
        "'Walker?team=0' observation 'CameraSensor' is 30x30",
        "'environment_parameters.difficulty.curriculum[0].completion_criteria.behavior' names 'Strikr'",
        "--num-areas 2 x 4 agent(s) of 'Walker?team=0' = 8 agents, but the spec saw 4",
        "--num-areas 2 x 2 agent(s) of 'Striker?team=0' = 4 agents",
        "--num-areas 2 x 2 agent(s) of 'Striker?team=1' = 4 agents",
    ]
    for part in expected:
        assert part in text
    assert len(lines) == len(expected)
    assert not (tmp_path / "results").exists()  # nothing was started


def test_the_spec_can_come_from_the_mirror_env(files, capsys):
    assert main([files("good.yaml", GOOD), "--check", "--env", "stub:mirror=spec.json"]) == 0


def test_a_smaller_camera_suggests_the_encoders_that_take_it(files, capsys):
    yaml = GOOD.replace("vis_encode_type: simple", "vis_encode_type: nature_cnn")
    assert main([files("cnn.yaml", yaml), "--check", "--spec", "spec.json"]) == 2
    assert "choose simple or resnet or match3 or fully_connected" in capsys.readouterr().out


def test_check_without_a_spec_is_a_user_error(files, capsys):
    assert main([files("good.yaml", GOOD), "--check"]) == 2
    assert "--check needs the game's behavior specs" in capsys.readouterr().err


def test_a_broken_spec_file_is_a_user_error(files, capsys, tmp_path):
    (tmp_path / "broken.json").write_text("{")
    assert main([files("good.yaml", GOOD), "--check", "--spec", "broken.json"]) == 2
    assert "broken.json is not valid JSON" in capsys.readouterr().err


def test_what_the_yaml_alone_gets_wrong_is_the_loaders_one_line(files, capsys):
    yaml = GOOD.replace("buffer_size: 640", "buffer_size: 32")
    assert main([files("small.yaml", yaml), "--check", "--spec", "spec.json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mlagents-like-learn: error: small.yaml: 'behaviors.Walker.hyperparameters.batch_size' (64) "
                   "must not exceed 'behaviors.Walker.hyperparameters.buffer_size' (32)."]
