"""The ``mirror`` task (unity_stub_env/tasks/mirror.py): a behaviors.json replayed with learnable
synthetic dynamics, checked with hand-computed numbers and through the real codec."""
from __future__ import annotations

import numpy as np
import pytest

from protos.spec_file import SpecFile
from trainer.protocol.codec import steps_from_agent_infos
from unity_stub_env.academy import Academy
from unity_stub_env.agents import EpisodeIdCounter
from unity_stub_env.cli import main as stub_main
from unity_stub_env.tasks.mirror import DEFAULT_MAX_STEP, STEP_REWARD_SCALE, mirror_tasks

SPEC = SpecFile.from_dict({"format_version": 1, "num_areas": 1, "stats": ["Game/Score"], "behaviors": [
    {"name": "Seeker?team=0", "observations": [{"name": "Camera", "shape": [3, 8, 12], "compression": "png"},
                                                {"name": "Vec", "shape": [5]}],
     "actions": {"continuous": 2, "discrete_branches": [3, 2]}, "agents": 3, "max_step": 40},
    {"name": "Striker?team=1", "observations": [{"name": "Vec", "shape": [4]}, {"name": "Gray", "shape": [1, 6, 6],
                                                                               "compression": "png"}],
     "actions": {"discrete_branches": [4]}, "agents": 4, "agents_per_area": 2, "groups_per_area": 1,
     "action_mask": True},
]})


def _target_actions(task):
    continuous, branches = task.targets()
    discrete = np.stack(branches, axis=1) if branches else np.zeros((task.num_agents, 0), np.int64)
    return continuous.astype(np.float32), discrete.astype(np.int32)


def test_tasks_present_the_files_behaviors():
    seeker, striker = mirror_tasks(SPEC, num_areas=2, seed=3)
    assert (seeker.behavior_name, seeker.team_id, seeker.num_agents) == ("Seeker", 0, 6)  # 3 per area x 2
    assert (striker.behavior_name, striker.team_id, striker.num_agents) == ("Striker", 1, 4)
    assert seeker.observation_specs == SPEC.behaviors[0].spec.observation_specs
    assert seeker.observation_compressions == ("png", "none")
    assert [o.shape for o in seeker.observe()] == [(6, 3, 8, 12), (6, 5)]
    assert seeker.max_step == 40 and striker.max_step == DEFAULT_MAX_STEP
    assert striker.group_ids().tolist() == [1, 1, 2, 2]  # one group per area
    assert seeker.group_ids() is None and striker.action_mask().shape == (4, 4)


def test_the_target_policy_earns_the_full_reward_and_episodes_end_at_max_step():
    task = mirror_tasks(SPEC, num_areas=1, seed=0)[0]
    for step in range(1, 41):
        result = task.step(*_target_actions(task))
        assert np.all(result.rewards == np.float32(STEP_REWARD_SCALE))  # score 1: no error anywhere
        assert result.done.tolist() == [step == 40] * 3
    assert result.interrupted.all() and [(k, a) for k, _, a in result.stats] == [("Game/Score", 0)]
    assert result.stats[0][1] == pytest.approx(1.0, abs=1e-6)


def test_random_play_earns_less_and_one_wrong_branch_costs_its_share():
    task = mirror_tasks(SPEC, num_areas=4, seed=1)[0]
    rng = np.random.default_rng(0)
    rewards = []
    for _ in range(40):
        result = task.step(rng.normal(size=(12, 2)).astype(np.float32), rng.integers(0, 2, (12, 2)).astype(np.int32))
        rewards.append(result.rewards)
    assert np.mean(rewards) < 0.6 * STEP_REWARD_SCALE
    task.reset()
    continuous, discrete = _target_actions(task)
    discrete[:, 1] = 1 - discrete[:, 1]  # the second branch (of 4 components) always wrong: score 3/4
    assert np.allclose(task.step(continuous, discrete).rewards, 0.75 * STEP_REWARD_SCALE)


def test_cameras_show_the_hidden_state_in_stripes():
    task = mirror_tasks(SPEC, num_areas=1, seed=0)[0]
    camera = task.observe()[0]  # [3, 3, 8, 12]: 12 columns, 3 per hidden component
    level = 1 / (1 + np.exp(-2 * task.state))
    for k in range(4):
        expected = task.channel_gain[0][None, :, None, None] * level[:, k][:, None, None, None]
        assert np.allclose(camera[:, :, :, 3 * k:3 * k + 3], expected, atol=1e-6)


def test_same_seed_same_run_other_seed_other_run():
    def run(seed):
        task = mirror_tasks(SPEC, num_areas=1, seed=seed)[1]
        out = []
        for _ in range(5):
            out.append(task.observe()[0].copy())
            task.step(np.zeros((2, 0), np.float32), np.ones((2, 1), np.int32))
        return np.stack(out)
    assert np.array_equal(run(7), run(7)) and not np.array_equal(run(7), run(8))


def test_the_academy_sends_png_cameras_groups_and_teams_the_codec_reads_back():
    seeker, striker = mirror_tasks(SPEC, num_areas=1, seed=0)
    counter = EpisodeIdCounter()
    for task, key in ((seeker, "Seeker?team=0"), (striker, "Striker?team=1")):
        academy = Academy(task, episode_counter=counter)
        assert academy.behavior_key == key
        infos = academy.collect_infos()
        compressions = [o.compression_type for o in infos[0].observations]
        assert compressions == [1 if c == "png" else 0 for c in SPEC.behavior(key).compressions]
        decision, _ = steps_from_agent_infos(key, infos, SPEC.behavior(key).spec)
        for got, sent, projection in zip(decision.obs, task.observe(), task.projections):
            if got.ndim == 4:  # a camera: exact up to PNG's 8 bits per channel
                assert np.allclose(got, sent, atol=0.5 / 255 + 1e-6)
            else:  # a vector: W s plus N(0, 0.05^2) noise, drawn afresh by each observe()
                assert np.abs(got - task.state @ projection.T).max() < 0.25
        groups = task.group_ids()
        assert decision.group_id.tolist() == ([0] * task.num_agents if groups is None else groups.tolist())


def test_cli_mirror_usage_errors(tmp_path, capsys):
    assert stub_main(["--task", "mirror", "--mlagents-port", "1"]) == 2
    assert "--task mirror needs --spec FILE" in capsys.readouterr().err
    assert stub_main(["--task", f"mirror={tmp_path / 'none.json'}", "--mlagents-port", "1"]) == 2
    assert "cannot read the behavior spec file" in capsys.readouterr().err
    assert stub_main(["--list"]) == 0
    assert "mirror: replays the behaviors of a behaviors.json" in capsys.readouterr().out


@pytest.mark.parametrize("channels", [1, 2, 3, 4, 7])
def test_png_cameras_of_any_channel_count_decode_exactly(channels):
    from protos.types import DimensionProperty as D, ObservationSpec, ObservationType
    from trainer.protocol.codec import steps_from_agent_infos as decode
    from protos.types import ActionSpec, BehaviorSpec
    from unity_stub_env.agents import encode_agent_infos

    spec = ObservationSpec((channels, 5, 7), (D.NONE,) * 3, ObservationType.DEFAULT, "cam")
    pixels = np.random.default_rng(channels).integers(0, 256, (3, channels, 5, 7)) / 255.0
    infos = encode_agent_infos([spec], [pixels], np.zeros(3, np.float32), np.arange(3), False,
                               compressions=("png",)).protos()
    decision, _ = decode("X?team=0", infos, BehaviorSpec((spec,), ActionSpec(1, ())))
    assert np.allclose(decision.obs[0], pixels, atol=1e-6)
    mapping = list(infos[0].observations[0].compressed_channel_mapping)
    assert mapping == ([] if channels in (1, 3) else [c if c < channels else -1 for c in range(-(-channels // 3) * 3)])


def test_a_mirror_launcher_carries_its_spec(tmp_path, capsys):
    spec = tmp_path / "game.json"
    spec.write_text(SPEC.dumps())
    assert stub_main(["--task", f"mirror={spec}", "--write-launcher", str(tmp_path / "builds")]) == 0
    launcher = (tmp_path / "builds" / "StubMirror.x86_64").read_text()
    assert f"--task mirror --spec {spec}" in launcher
