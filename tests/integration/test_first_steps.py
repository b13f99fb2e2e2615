"""A run's first actions are decided before torch is imported, and the run is the same as if
torch had been there from the start (trainer/first_steps.py; docs/performance.md, "Start-up and
exit"). Real processes: mlagents-like-learn and the stub over gRPC."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest
import torch

from tests.integration.conftest import free_port_block

# Runs trainer.cli in this process with two observers: at the first send_step, whether torch is
# imported; and a mode. "late": no background import (trainer/warmup.py), so torch can only come
# from the main thread's own path, which must not need it before the first trajectory; "torch-first":
# no StartingBehavior, the runner (and torch) from the first contact, as before.
DRIVER = """
import json, sys
from trainer import warmup, first_steps
from trainer.envs import pool

mode, out = sys.argv[1], sys.argv[2]
seen = {}
send_step = pool.EnvPool.send_step

def observed(self, *args, **kwargs):
    if "torch_at_first_send" not in seen:
        seen["torch_at_first_send"] = "torch" in sys.modules
    return send_step(self, *args, **kwargs)

pool.EnvPool.send_step = observed
if mode == "late":
    warmup.start = lambda *a, **k: None
else:
    first_steps.StartingBehavior.create = classmethod(lambda cls, *a, **k: None)
from trainer.cli import main
code = main(sys.argv[3:])
with open(out, "w") as f:
    json.dump(seen, f)
sys.exit(code)
"""

CONFIG = """
behaviors:
  {behavior}:
    trainer_type: {trainer}
    hyperparameters: {hyper}
    network_settings: {{normalize: {normalize}, hidden_units: 16, num_layers: 2{memory}}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    max_steps: {steps}
    time_horizon: {horizon}
    summary_freq: {steps}
"""
PPO = "{batch_size: 32, buffer_size: 128, num_epoch: 2, learning_rate: 3.0e-4}"
SAC = "{batch_size: 32, buffer_size: 2000, buffer_init_steps: 100, steps_per_update: 4, learning_rate: 3.0e-4}"


def run(tmp_path, mode: str, task: str, behavior: str, trainer: str, env: dict, normalize: bool = False,
        memory: bool = False):
    folder = tmp_path / mode
    folder.mkdir()
    config = folder / "c.yaml"
    config.write_text(textwrap.dedent(CONFIG.format(
        behavior=behavior, trainer=trainer, hyper=SAC if trainer == "sac" else PPO,
        normalize=str(normalize).lower(), steps=400, horizon=16,
        memory=", memory: {memory_size: 16, sequence_length: 8}" if memory else "")))
    (folder / "driver.py").write_text(DRIVER)
    seen = folder / "seen.json"
    r = subprocess.run([sys.executable, str(folder / "driver.py"), mode, str(seen), str(config),
                        "--env", f"stub:{task}", "--num-areas", "2", "--seed", "3", "--run-id", "r",
                        "--results-dir", str(folder / "results"), "--base-port", str(free_port_block())],
                       cwd=folder, capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    state = torch.load(folder / "results" / "r" / behavior / "checkpoint.pt", weights_only=True)
    return json.loads(seen.read_text()), state


@pytest.mark.parametrize("task, behavior, trainer, normalize, memory", [
    ("basic", "Basic", "ppo", False, False), ("ball3d", "3DBall", "ppo", True, False),
    ("basic", "Basic", "sac", False, False), ("pushblock", "PushBlock", "poca", True, False),
    ("pushblock", "PushBlock", "poca", False, True)])  # recurrent: each agent's memory handed over too
def test_first_actions_go_out_before_torch_and_the_run_is_unchanged(tmp_path, env_no_proxy, task, behavior,
                                                                   trainer, normalize, memory):
    late_seen, late = run(tmp_path, "late", task, behavior, trainer, env_no_proxy, normalize, memory)
    first_seen, first = run(tmp_path, "torch-first", task, behavior, trainer, env_no_proxy, normalize, memory)
    assert late_seen == {"torch_at_first_send": False}
    assert first_seen == {"torch_at_first_send": True}
    assert int(late["global_step"]["step"]) == int(first["global_step"]["step"]) >= 400
    # the same trained weights, bit for bit: the handover changed nothing
    assert late["Policy"].keys() == first["Policy"].keys()
    for name, value in late["Policy"].items():
        assert torch.equal(value, first["Policy"][name]), name
    assert torch.equal(late["RNG"]["policy_noise"], first["RNG"]["policy_noise"])
