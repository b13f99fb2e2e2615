"""mlagents-like-learn with demonstrations that cannot be used: one message naming the YAML key,
exit code 2, no traceback."""
from __future__ import annotations

import subprocess
import sys

import pytest

from tests.integration.conftest import free_port_block, learn

CONFIG = """behaviors:
  {behavior}:
    trainer_type: ppo
    hyperparameters: {{batch_size: 16, buffer_size: 64}}
    reward_signals:
      extrinsic: {{}}
      gail: {{demo_path: {path}}}
    max_steps: 200
"""


def test_a_missing_demo_path_stops_the_run_before_anything_starts(tmp_path, env_no_proxy):
    (tmp_path / "c.yaml").write_text(CONFIG.format(behavior="Basic", path="demos/none.demo"))
    r = learn(["c.yaml", "--env", "stub:basic", "--results-dir", str(tmp_path / "res")], cwd=tmp_path,
              timeout=60, env=env_no_proxy)
    assert r.returncode == 2, r.stderr
    assert ("'behaviors.Basic.reward_signals.gail.demo_path': the demonstration file or folder "
            "'demos/none.demo' does not exist") in r.stderr
    assert "Traceback" not in r.stderr + r.stdout
    assert not (tmp_path / "res").exists()


def test_a_demonstration_of_another_behavior_is_refused_when_the_behavior_connects(tmp_path, env_no_proxy):
    recorded = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "--task", "basic", "--record-demo",
                               "basic.demo", "--policy", "scripted", "--demo-steps", "20"],
                              cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env_no_proxy)
    assert recorded.returncode == 0, recorded.stderr
    (tmp_path / "c.yaml").write_text(CONFIG.format(behavior="3DBall", path="basic.demo"))
    r = learn(["c.yaml", "--env", "stub:ball3d", "--results-dir", str(tmp_path / "res"),
               "--base-port", str(free_port_block())], cwd=tmp_path, timeout=120, env=env_no_proxy)
    assert r.returncode == 2, r.stderr[-2000:]
    assert ("behaviors.3DBall.reward_signals.gail.demo_path: the demonstration 'basic.demo' was recorded with "
            "observations [(20,)], 0 continuous actions, discrete branches [3], but the behavior has "
            "observations [(8,)], 2 continuous actions") in r.stderr
    assert "Traceback" not in r.stderr + r.stdout


# per trainer: its hyperparameters and the tag of GAIL's value estimate (the reference's names)
TRAINERS = {
    "ppo": ("{batch_size: 32, buffer_size: 256}", "Policy/Gail Value Estimate"),
    "sac": ("{batch_size: 32, buffer_size: 2000, buffer_init_steps: 100, steps_per_update: 10.0}",
            "Policy/Gail Value"),
}


@pytest.mark.parametrize("trainer", sorted(TRAINERS))
def test_gail_and_cloning_train_report_and_resume_with_their_state(trainer, tmp_path, env_no_proxy):
    from trainer.artifacts.checkpoints import load_checkpoint
    from tests.integration.test_learn_features import tb_scalars

    recorded = subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "--task", "basic", "--record-demo",
                               "demos/basic.demo", "--policy", "scripted", "--demo-steps", "40"],
                              cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env_no_proxy)
    assert recorded.returncode == 0, recorded.stderr
    text = """behaviors:
  Basic:
    trainer_type: TRAINER
    hyperparameters: HYPER
    network_settings: {hidden_units: 20, num_layers: 1}
    reward_signals:
      extrinsic: {gamma: 0.9}
      gail: {strength: 0.1, demo_path: demos, use_vail: true, use_actions: true, network_settings: {hidden_units: 16}}
    behavioral_cloning: {demo_path: demos/basic.demo, steps: 2000}
    time_horizon: 3
    summary_freq: 300
    checkpoint_interval: 100000
    max_steps: MAX
"""
    hyper, value_tag = TRAINERS[trainer]
    text = text.replace("TRAINER", trainer).replace("HYPER", hyper)
    (tmp_path / "c.yaml").write_text(text.replace("MAX", "600"))
    (tmp_path / "c2.yaml").write_text(text.replace("MAX", "1200"))
    common = ["--env", "stub:basic", "--run-id", "g", "--seed", "2", "--results-dir", str(tmp_path / "results"),
              "--base-port", str(free_port_block())]
    r = learn(["c.yaml", *common], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(tmp_path / "results/g/Basic")
    for tag in ("Policy/Gail Reward", value_tag, "Losses/GAIL Loss", "Losses/GAIL KL Loss",
                "Policy/GAIL Beta", "Policy/GAIL Expert Estimate", "Policy/GAIL Policy Estimate",
                "Policy/GAIL Grad Mag Loss", "Losses/Pretraining Loss"):
        assert tag in tags, tag
    first = load_checkpoint(tmp_path / "results/g/Basic/checkpoint.pt")
    assert {"Module:GAIL", "Optimizer:GAIL", "Optimizer:BC"} <= set(first)
    r2 = learn(["c2.yaml", *common, "--resume"], cwd=tmp_path, env=env_no_proxy)
    assert r2.returncode == 0, r2.stderr[-3000:]
    output = r2.stdout + r2.stderr
    assert "starts untrained" not in output and "starts fresh" not in output  # both came back
    second = load_checkpoint(tmp_path / "results/g/Basic/checkpoint.pt")
    assert int(second["global_step"]["step"]) >= 1200
    # the resumed discriminator kept learning from where it was: its Adam counted on
    steps = lambda state: max(int(s["step"]) for s in state["Optimizer:GAIL"]["state"].values())  # noqa: E731
    assert steps(second) > steps(first) > 0
