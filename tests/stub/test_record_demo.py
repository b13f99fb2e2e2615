"""``unity-stub-env --record-demo``: the scripted experts' returns, whole episodes per file, the
ONNX policy's deterministic actions, and the CLI's refusals (exit code 2)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from protos.demo_file import read_demo
from unity_stub_env import record_demo
from unity_stub_env.tasks.basic import OPTIMAL_RETURN


def _episodes(demo):
    """[(rewards, actions)] per episode of a one-agent stream (the reward of each record)."""
    episodes, current = [], []
    for pair in demo.pairs:
        current.append(pair)
        if pair.agent_info.done:
            episodes.append(current)
            current = []
    assert not current, "a file holds whole episodes only"
    return episodes


def test_basic_expert_walks_right_seven_times_for_the_optimal_return(tmp_path):
    path = str(tmp_path / "basic.demo")
    steps, episodes, mean = record_demo.record("basic", path, "scripted", steps=20)
    # 8 records per episode (7 decisions + the terminal record): 3 whole episodes reach 20
    assert (steps, episodes) == (24, 3)
    assert mean == pytest.approx(OPTIMAL_RETURN, abs=1e-6)
    demo = read_demo(path)
    assert demo.metas[0].number_steps == 24 and demo.metas[0].number_episodes == 3
    for episode in _episodes(demo):
        assert [list(p.action_info.discrete_actions) for p in episode[:-1]] == [[2]] * 7
        assert sum(p.agent_info.reward for p in episode) == pytest.approx(OPTIMAL_RETURN, abs=1e-6)
        positions = [int(np.argmax(p.agent_info.observations[0].float_data.data)) for p in episode]
        assert positions == list(range(10, 18))


def test_ball3d_expert_keeps_the_ball_where_random_actions_drop_it(tmp_path):
    steps, episodes, mean = record_demo.record("ball3d", str(tmp_path / "e.demo"), "scripted", steps=1000, seed=3)
    assert episodes == 1 and mean == pytest.approx(100.0, abs=1e-3)  # 1000 decisions of +0.1, interrupted
    random_expert = lambda task: lambda obs, mask: (  # noqa: E731
        np.random.default_rng(0).uniform(-1, 1, (len(obs[0]), 2)).astype(np.float32), np.zeros((len(obs[0]), 0)))
    original = record_demo.SCRIPTED["ball3d"]
    try:
        record_demo.SCRIPTED["ball3d"] = random_expert
        _, _, random_mean = record_demo.record("ball3d", str(tmp_path / "r.demo"), "scripted", steps=200, seed=3)
    finally:
        record_demo.SCRIPTED["ball3d"] = original
    assert random_mean < 10.0


def test_an_onnx_policy_records_its_deterministic_actions(tmp_path):
    import torch

    from trainer.artifacts.onnx_export import export_policy
    from trainer.ppo.hyperparams import PPOHyperparams
    from trainer.ppo.policy import Policy
    from unity_stub_env.tasks import make_task

    task = make_task("basic")
    from protos.types import BehaviorSpec

    policy = Policy(BehaviorSpec(task.observation_specs, task.action_spec), PPOHyperparams(hidden_units=16), seed=5)
    with torch.no_grad():  # a policy that prefers "left" at some positions and "right" elsewhere
        for p in policy.actor.parameters():
            p.add_(torch.randn(p.shape, generator=torch.Generator().manual_seed(1)))
    model = str(tmp_path / "m.onnx")
    export_policy(policy, model)
    record_demo.record("basic", str(tmp_path / "m.demo"), model, steps=150)
    demo = read_demo(str(tmp_path / "m.demo"))
    deciding = [p for p in demo.pairs if not p.agent_info.done]
    obs = np.array([list(p.agent_info.observations[0].float_data.data) for p in deciding], np.float32)
    masks = np.array([list(p.agent_info.action_mask) for p in deciding], bool)
    expected = policy.act([obs], masks, deterministic=True).discrete
    assert np.array_equal(np.array([list(p.action_info.discrete_actions) for p in deciding]), expected)
    assert len(deciding) >= 100


@pytest.mark.parametrize("args, message", [
    (["--task", "dodge", "--record-demo", "x.demo", "--policy", "scripted"], "no scripted expert"),
    (["--task", "basic", "--record-demo", "x.demo", "--policy", "missing.onnx"], "neither 'scripted'"),
    (["--task", "basic", "--record-demo", "x.demo"], "--policy"),
    (["--task", "basic", "--record-demo", "x.txt", "--policy", "scripted"], "must end in .demo"),
])
def test_cli_refuses_bad_arguments_with_exit_code_2(tmp_path, args, message):
    done = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr
