"""``unity-stub-env --task dodge --evaluate``: the scripted evaluation with a tiny exported model."""
from __future__ import annotations

import json

import numpy as np
import pytest

from trainer.artifacts.onnx_export import export_policy
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.policy import Policy
from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from unity_stub_env.cli import main
from unity_stub_env.tasks.dodge import SCRIPTED_THROWS, random_throws, run_throws, summarize

pytest.importorskip("onnxruntime")
EPISODES = 28  # random throws: two batches of 14 would be one model of 2 areas


def _spec(observations: int = 17) -> BehaviorSpec:
    obs = ObservationSpec((observations,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor")
    return BehaviorSpec((obs,), ActionSpec(continuous_size=9, discrete_branches=()))


def _tiny_policy(observations: int = 17) -> Policy:
    policy = Policy(_spec(observations), PPOHyperparams(hidden_units=8, num_layers=1, normalize=True), seed=0)
    for parameter in policy.actor.parameters():  # large weights: the mean action moves the body
        parameter.data.mul_(4.0)
    return policy


def test_evaluate_prints_and_writes_the_policy_and_both_baselines(tmp_path, capsys):
    policy = _tiny_policy()
    model = tmp_path / "Dodge.onnx"
    export_policy(policy, model)
    out_json = tmp_path / "eval.json"
    assert main(["--task", "dodge", "--evaluate", str(model), "--episodes", str(EPISODES), "--seed", "5",
                 "--json", str(out_json)]) == 0
    table = capsys.readouterr().out
    for name in (str(model), "zero", "random"):
        assert f"| {name} | scripted | 17 |" in table and f"| {name} | random | {EPISODES} |" in table
    results = json.loads(out_json.read_text())["results"]
    zero = results["zero"]
    # a character that does not move is hit by every throw, each aimed at it; the head throws
    # (2 front, 8 right, 13 left) hit the head
    assert zero["scripted"]["hit_rate"] == 1.0 and zero["random"]["hit_rate"] == 1.0
    assert zero["scripted"]["upper_body_throws"] == 13  # all but the three pelvis and the thigh marks
    assert 0 < zero["random"]["upper_body_throws"] < EPISODES
    assert [t["outcome"] for t in zero["scripted_throws"] if t["mark"] == "head"] == ["hit head"] * 3
    assert [(t["side"], t["mark"]) for t in zero["scripted_throws"]] == list(SCRIPTED_THROWS)
    # standing still costs only the balance term, ~0.0106 per step
    assert zero["random"]["mean_effort"] == pytest.approx(0.0106 * zero["random"]["mean_steps"], rel=0.01)
    assert results["random"]["random"]["mean_effort"] > 2 * zero["random"]["mean_effort"]
    # the model acts with its deterministic output: the same outcomes as the torch policy's mean action
    mean_action = lambda obs: policy.act([obs], None, deterministic=True).env_actions.continuous  # noqa: E731
    throws = random_throws(EPISODES, 5)
    expected = summarize(run_throws(throws, mean_action, seed=5), throws)
    assert results[str(model)]["random"] == pytest.approx(expected, rel=1e-4)
    assert results[str(model)]["random"]["mean_effort"] != pytest.approx(zero["random"]["mean_effort"], rel=0.05)


def test_evaluate_refuses_bad_policies_and_tasks_with_exit_2(tmp_path, capsys):
    assert main(["--task", "dodge", "--evaluate", str(tmp_path / "missing.onnx")]) == 2
    assert "neither 'zero', 'random' nor an existing .onnx file" in capsys.readouterr().err
    wrong = tmp_path / "Other.onnx"
    export_policy(_tiny_policy(observations=8), wrong)
    assert main(["--task", "dodge", "--evaluate", str(wrong)]) == 2
    assert "obs_0 has 8 values per agent, the task observes 17" in capsys.readouterr().err
    assert main(["--task", "basic", "--evaluate", "zero"]) == 2
    assert "has no scripted evaluation" in capsys.readouterr().err
    assert main(["--task", "dodge", "--evaluate", "zero", "--episodes", "0"]) == 2
    assert "--episodes must be 1 or more" in capsys.readouterr().err


def test_random_throws_are_seeded():
    a, b, c = random_throws(30, 1), random_throws(30, 1), random_throws(30, 2)
    assert np.array_equal(a.start, b.start) and np.array_equal(a.target, b.target)
    assert not np.array_equal(a.start, c.start)
