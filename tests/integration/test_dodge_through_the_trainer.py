"""``dodge`` through the real protocol with our trainer: 14 agents of one behavior, one process each."""
from __future__ import annotations

import textwrap

import yaml

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import free_port_block, learn

TINY_DODGE = """
behaviors:
  Dodge:
    trainer_type: ppo
    hyperparameters: {batch_size: 256, buffer_size: 1024}
    network_settings: {normalize: true, hidden_units: 16, num_layers: 1}
    max_steps: 2800
    time_horizon: 64
    summary_freq: 1400
"""


def test_fourteen_agents_train_one_behavior_through_grpc(tmp_path, env_no_proxy):
    cfg = tmp_path / "dodge.yaml"
    cfg.write_text(textwrap.dedent(TINY_DODGE))
    r = learn([str(cfg), "--env", "stub:dodge", "--seed", "2", "--run-id", "t",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=300, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    acc = EventAccumulator(str(tmp_path / "results" / "t" / "Dodge"), size_guidance={"scalars": 0})
    acc.Reload()
    steps = [e.step for e in acc.Scalars("Environment/Cumulative Reward")]
    assert steps == [1400, 2800]  # 14 agent-steps per decision: 100 and 200 decisions
    # each episode is one throw: 0.4-1.4 s of flight at 50 decisions/s, ended by a hit or a pass
    lengths = [e.value for e in acc.Scalars("Environment/Episode Length")]
    assert all(20 <= length <= 65 for length in lengths), lengths
    outcome = [a.value + b.value + c.value for a, b, c in zip(acc.Scalars("Dodge/Hit"), acc.Scalars("Dodge/Passed"),
                                                              acc.Scalars("Dodge/Balance Lost"))]
    assert all(total >= 1.0 for total in outcome)  # every episode ended by one of the three
    assert (tmp_path / "results" / "t" / "Dodge.onnx").exists()


TINY_DODGE_0X = """
default:
  trainer: ppo
  batch_size: 256
  buffer_size: 2048
  hidden_units: 16
  num_layers: 1
  normalize: true
  time_horizon: 64
Dodge:
  max_steps: 2000
  summary_freq: 500
"""


def test_a_0x_file_counts_environment_steps_so_2000_steps_of_14_agents_are_28000_agent_steps(tmp_path, env_no_proxy):
    cfg = tmp_path / "dodge_0x.yaml"
    cfg.write_text(textwrap.dedent(TINY_DODGE_0X))
    r = learn([str(cfg), "--env", "stub:dodge", "--seed", "2", "--run-id", "t",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    acc = EventAccumulator(str(tmp_path / "results" / "t" / "Dodge"), size_guidance={"scalars": 0})
    acc.Reload()
    steps = [e.step for e in acc.Scalars("Environment/Cumulative Reward")]
    # 0.x: 2000 environment steps, a summary every 500; each is 14 agent steps
    assert steps == [7000, 14000, 21000, 28000]
    log = r.stdout + r.stderr
    assert "environment steps of one simulator" in log  # said at load
    assert "14 agents in one simulator, so the 0.x max_steps 2000 and summary_freq 500" in log
    assert "are 28000 and 7000 agent steps" in log
    modern = log.split("with these values:\n", 1)[1]
    assert "max_steps: 28000" in modern and "summary_freq: 7000" in modern
    # the run's configuration.yaml is a modern file: it carries the agent-step counts the run used
    written = yaml.safe_load((tmp_path / "results" / "t" / "configuration.yaml").read_text())
    dodge = written["behaviors"]["Dodge"]
    assert (dodge["max_steps"], dodge["summary_freq"]) == (28000, 7000)
