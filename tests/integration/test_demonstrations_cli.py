"""mlagents-like-learn with demonstrations that cannot be used: one message naming the YAML key,
exit code 2, no traceback."""
from __future__ import annotations

import subprocess
import sys

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
