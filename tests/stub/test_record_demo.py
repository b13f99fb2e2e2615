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
    from trainer.common.policy import Policy
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
    (["--task", "mimic", "--record-demo", "x.demo", "--policy", "scripted", "--env-param", "motion"], "KEY=NUMBER"),
    (["--task", "mimic", "--record-demo", "x.demo", "--policy", "scripted", "--env-param", "motion=7"],
     "motion must be 0..3"),
    (["--task", "mimic", "--record-demo", "x.demo", "--policy", "scripted", "--demo-noise", "-1"], "--demo-noise"),
])
def test_cli_refuses_bad_arguments_with_exit_code_2(tmp_path, args, message):
    done = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr


def test_mimic_inverse_action_map_round_trips_hand_computed_targets():
    from unity_stub_env.tasks.mimic import MimicTask
    from unity_stub_env.tasks.mimic.motions import JOINTS

    task = MimicTask(1, 0)
    knee, hip_x, elbow = JOINTS.index("knee_r"), JOINTS.index("hip_x_r"), JOINTS.index("elbow_l")
    targets = np.zeros((task.num_agents, len(JOINTS)))
    # knee 0..150 deg: 75 deg is half way up; hip x -30..120 deg: -15 deg half way down; elbow 0 = neutral
    targets[:, knee], targets[:, hip_x], targets[:, elbow] = np.radians(75.0), np.radians(-15.0), 0.0
    actions = task.absolute_actions(targets)
    assert actions[0, knee] == pytest.approx(0.5) and actions[0, hip_x] == pytest.approx(-0.5)
    assert actions[0, elbow] == 0.0
    assert np.abs(actions).max() <= 1.0
    np.testing.assert_allclose(task.targets(actions), targets, atol=1e-12)
    # targets at the limits map to +-1 and back
    np.testing.assert_allclose(task.absolute_actions(task.high), 1.0)
    np.testing.assert_allclose(task.targets(task.absolute_actions(task.low)), task.low, atol=1e-12)


def test_mimic_expert_tracks_the_squat_clip_with_the_reference_pd_pose_reward(tmp_path):
    # only the pose term in the reward: each record's reward is r_r of that decision
    weights = ["w_r=1", "w_v=0", "w_m=0", "w_e=0", "w_t=0"]
    path = str(tmp_path / "squat.demo")
    steps, episodes, mean = record_demo.record("mimic", path, "scripted", steps=400, env_params=["motion=2", *weights])
    # 8 ragdolls, RSI; the first whole episode is 500 decisions + its terminal record: it did not fall
    assert (steps, episodes) == (501, 1)
    assert 0.93 < mean / 500 < 0.97  # the reference PD's squat r_r (zero actions: 0.29)
    # the recorded actions are the inverse map of the clip, not zeros: the knees bend
    knee = 17
    actions = np.array([list(p.action_info.continuous_actions) for p in read_demo(path).pairs[:-1]])
    assert actions.shape == (500, 26) and np.abs(actions).max() <= 1.0 and actions[:, knee].max() > 0.3
    # the same motion with zero actions stays upright but far from the clip
    original = record_demo.SCRIPTED["mimic"]
    try:
        record_demo.SCRIPTED["mimic"] = lambda task: lambda obs, mask: (
            np.zeros((len(obs[0]), 26), np.float32), np.zeros((len(obs[0]), 0), np.int32))
        _, _, zero_mean = record_demo.record("mimic", str(tmp_path / "z.demo"), "scripted", steps=400,
                                             env_params=["motion=2", *weights])
    finally:
        record_demo.SCRIPTED["mimic"] = original
    assert zero_mean / 500 < 0.5


def test_demo_noise_acts_noisily_but_records_the_experts_clean_actions(tmp_path):
    from unity_stub_env.tasks.mimic import MimicTask

    path = str(tmp_path / "noisy.demo")
    steps, episodes, mean = record_demo.record("mimic", path, "scripted", steps=300, env_params=["motion=2"], noise=0.1)
    assert episodes >= 2 and mean < 100.0  # the noisy ragdolls fall long before the 500 decisions (clean: ~475)
    task = MimicTask(1, 0)
    frames, offset = task.ref.frames[2], task.ref.offset[2]
    for pair in read_demo(path).pairs:
        if pair.agent_info.done:
            continue
        phase = pair.agent_info.observations[0].float_data.data[-1]
        frame = round(phase * frames)
        expected = task.absolute_actions(task.ref.joints[offset + (frame + 1) % frames][None].repeat(task.num_agents, 0))[0]
        np.testing.assert_allclose(list(pair.action_info.continuous_actions), expected, atol=1e-6)


def test_mimic_expert_balances_the_pushed_stand_and_records_what_it_saw(tmp_path):
    from unity_stub_env.tasks.mimic import BalanceExpert

    path = str(tmp_path / "stand.demo")
    steps, episodes, mean = record_demo.record("mimic", path, "scripted", steps=400,
                                               env_params=["motion=0", "push_impulse=15"])
    assert (steps, episodes) == (501, 1) and mean > 490  # 10 s kept under five pushes; r_r ~0.99 a decision
    pairs = [p for p in read_demo(path).pairs if not p.agent_info.done]
    obs = np.array([list(p.agent_info.observations[0].float_data.data) for p in pairs], np.float32)
    actions = np.array([list(p.action_info.continuous_actions) for p in pairs])
    np.testing.assert_allclose(actions, BalanceExpert()(obs), atol=1e-6)  # each record: the expert's answer to it
    ankles = [18, 19, 24, 25]  # ankle_x_r, ankle_y_r, ankle_x_l, ankle_y_l: the only joints it moves
    assert np.abs(np.delete(actions, ankles, axis=1)).max() == 0.0 and np.abs(actions[:, ankles]).max() > 0.1
