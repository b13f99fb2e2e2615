"""``unity-stub-env --task mimic --evaluate``: balance and reward terms per motion, standing under pushes."""
from __future__ import annotations

import json

import numpy as np
import pytest

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.artifacts.onnx_export import export_policy
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.policy import Policy
from unity_stub_env.cli import main
from unity_stub_env.tasks.mimic import MOTIONS, PUSH_LADDER, run_trials

pytest.importorskip("onnxruntime")
TRIALS = 8  # one area


def _tiny_policy() -> Policy:
    obs = ObservationSpec((170,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor")
    spec = BehaviorSpec((obs,), ActionSpec(continuous_size=26, discrete_branches=()))
    return Policy(spec, PPOHyperparams(hidden_units=8, num_layers=1, normalize=True), seed=0)


def test_evaluate_prints_and_writes_every_motion_the_push_ladder_and_the_baselines(tmp_path, capsys):
    policy = _tiny_policy()
    model = tmp_path / "Mimic.onnx"
    export_policy(policy, model)
    out_json = tmp_path / "eval.json"
    assert main(["--task", "mimic", "--evaluate", str(model), "--episodes", str(TRIALS), "--seed", "2",
                 "--json", str(out_json)]) == 0
    table = capsys.readouterr().out
    for name in (str(model), "zero", "random", "reference PD"):
        for motion in MOTIONS:
            assert f"| {name} | {motion} | {TRIALS} |" in table
    assert "under a push every 2 s" in table and "| 10 N s | 15 N s | 20 N s | 30 N s |" in table
    results = json.loads(out_json.read_text())["results"]
    zero, reference = results["zero"], results["reference PD"]
    # zero actions aim every axis at 0 rad, the standing pose: the PD holds it for 10 s, tracks the
    # stand clip and not the arms one (its arm is raised 75 deg); the walk falls within a second
    assert all(zero["motions"][m]["balance_kept"] == 1.0 for m in ("stand", "arms", "squat"))
    assert zero["motions"]["stand"]["r_r"] > 0.99 and zero["motions"]["arms"]["r_r"] < 0.2
    assert zero["motions"]["walk"]["mean_seconds"] < 1.0
    # the PD controllers on the reference keep stand, arms and squat for 10 s; pushes beyond 10 N s topple them
    for motion in ("stand", "arms", "squat"):
        assert reference["motions"][motion]["balance_kept"] == 1.0 and reference["motions"][motion]["r_r"] > 0.9
    assert reference["motions"]["stand"]["mean_seconds"] == pytest.approx(10.0)
    assert reference["pushed_stand"]["10"]["balance_kept"] == 1.0
    assert reference["pushed_stand"]["30"]["balance_kept"] < 0.5
    assert list(reference["pushed_stand"]) == [f"{impulse:g}" for impulse in PUSH_LADDER]
    # the model acts with its deterministic output: the torch policy's mean action gives the same numbers
    mean_action = lambda obs: policy.act([obs], None, deterministic=True).env_actions.continuous  # noqa: E731
    expected = run_trials(mean_action, motion=2, trials=TRIALS, seed=2)
    assert results[str(model)]["motions"]["squat"] == pytest.approx(expected, rel=1e-4)
    for term in ("r_r", "r_v", "r_m", "r_e", "r_t"):
        assert 0.0 <= results["random"]["motions"]["walk"][term] <= 1.0
    assert np.isfinite(results["random"]["motions"]["walk"]["mean_reward"])


def test_evaluate_options_reach_the_task_and_bad_ones_exit_2(tmp_path, capsys):
    out_json = tmp_path / "eval.json"
    # residual 1: the zero policy is the PD controllers on the reference, the same as the extra row
    assert main(["--task", "mimic", "--evaluate", "zero", "--episodes", "8", "--evaluate-option", "residual=1",
                 "--json", str(out_json)]) == 0
    saved = json.loads(out_json.read_text())
    assert saved["options"] == {"residual": 1.0}
    assert saved["results"]["zero"] == saved["results"]["reference PD"]
    assert saved["results"]["zero"]["motions"]["squat"]["balance_kept"] == 1.0
    capsys.readouterr()
    assert main(["--task", "mimic", "--evaluate", "zero", "--evaluate-option", "gain=3"]) == 2
    assert "task mimic takes residual=NUMBER" in capsys.readouterr().err
    assert main(["--task", "mimic", "--evaluate", "zero", "--evaluate-option", "residual=high"]) == 2
    assert "'high' is not a number" in capsys.readouterr().err
    assert main(["--task", "dodge", "--evaluate", "zero", "--evaluate-option", "residual=1"]) == 2
    assert "task dodge takes no options" in capsys.readouterr().err
    assert main(["--task", "dodge", "--evaluate", "scripted"]) == 2
    assert "task dodge has no scripted expert" in capsys.readouterr().err
