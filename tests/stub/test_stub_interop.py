"""The stub driven by the REAL mlagents_envs 1.1.0 (its own venv and process) in Editor mode."""
from __future__ import annotations

import os

import pytest

from tests.stub.conftest import INTEROP_PYTHON, run_interop_script


# Runs inside .venv-interop: mlagents_envs listens (Editor mode, base_port = port), our stub connects.
_SCRIPT = r"""
import json, subprocess, sys
import numpy as np
from mlagents_envs.environment import UnityEnvironment
from mlagents_envs.base_env import ActionTuple
from mlagents_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel
from mlagents_envs.side_channel.engine_configuration_channel import EngineConfigurationChannel
from mlagents_envs.side_channel.stats_side_channel import StatsSideChannel

port, stub_python, repo = int(sys.argv[1]), sys.argv[2], sys.argv[3]
out = {}
def run_stub(task, *extra):
    return subprocess.Popen([stub_python, "-m", "unity_stub_env.cli", "--task", task,
                             "--mlagents-port", str(port), *extra], cwd=repo)

stub = run_stub("basic", "--num-areas", "2")
stats = StatsSideChannel()
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=30,
                       side_channels=[EnvironmentParametersChannel(), EngineConfigurationChannel(), stats])
env.reset()
out["behaviors"] = list(env.behavior_specs)
spec = env.behavior_specs["Basic?team=0"]
out["branches"] = list(spec.action_spec.discrete_branches)
out["obs_shapes"] = [list(o.shape) for o in spec.observation_specs]
decision, terminal = env.get_steps("Basic?team=0")
out["start"] = np.argmax(decision.obs[0], axis=1).tolist()
out["mask"] = [m.tolist() for m in decision.action_mask] if decision.action_mask else None
env.set_actions("Basic?team=0", ActionTuple(discrete=np.array([[1], [2]], dtype=np.int32)))
env.step()
decision, terminal = env.get_steps("Basic?team=0")
out["after_one"] = np.argmax(decision.obs[0], axis=1).tolist()
for _ in range(6):
    env.set_actions("Basic?team=0", ActionTuple(discrete=np.array([[0], [2]], dtype=np.int32)))
    env.step()
decision, terminal = env.get_steps("Basic?team=0")
out["terminal_ids"] = terminal.agent_id.tolist()
out["terminal_reward"] = terminal.reward.tolist()
out["terminal_interrupted"] = terminal.interrupted.tolist()
out["decision_ids"] = decision.agent_id.tolist()
out["stats"] = sorted(stats.get_and_reset_stats())
env.close()
out["basic_exit"] = stub.wait(timeout=20)

stub = run_stub("ball3d")
params = EnvironmentParametersChannel()
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=30, side_channels=[params])
params.set_float_parameter("gravity", 1.62)
env.reset()
env.set_actions("3DBall?team=0", ActionTuple(continuous=np.zeros((12, 2), dtype=np.float32)))
env.step()
decision, _ = env.get_steps("3DBall?team=0")
out["ball_vz"] = decision.obs[0][:, 7].tolist()
env.close()
out["ball_exit"] = stub.wait(timeout=20)
print("RESULT " + json.dumps(out))
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_drives_the_stub():
    out = run_interop_script(_SCRIPT)
    assert out["behaviors"] == ["Basic?team=0"]
    assert out["branches"] == [3] and out["obs_shapes"] == [[20]]
    assert out["start"] == [10, 10] and out["mask"] == [[[False, False, False]] * 2]
    assert out["after_one"] == [9, 11]  # actions matched by position: left, right
    assert len(out["terminal_ids"]) == 1 and out["terminal_interrupted"] == [False]
    assert out["terminal_reward"][0] == pytest.approx(0.99, abs=1e-6)
    assert out["terminal_ids"][0] not in out["decision_ids"] and len(out["decision_ids"]) == 2
    assert "Basic/Large Goal Reached" in out["stats"]
    assert out["basic_exit"] == 0 and out["ball_exit"] == 0
    assert out["ball_vz"] == pytest.approx([-0.162] * 12, abs=1e-4)
