"""The real mlagents_envs 1.1.0 (its own venv and process) drives the stub's ``creature`` task."""
from __future__ import annotations

import os

import pytest

from tests.stub.conftest import INTEROP_PYTHON, run_interop_script
from unity_stub_env.creatures import generate

# Runs inside .venv-interop: mlagents_envs listens (Editor mode), our stub connects.
_SCRIPT = r"""
import json, subprocess, sys
import numpy as np
from mlagents_envs.environment import UnityEnvironment
from mlagents_envs.base_env import ActionTuple
from mlagents_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel

port, stub_python, repo = int(sys.argv[1]), sys.argv[2], sys.argv[3]
out = {}
stub = subprocess.Popen([stub_python, "-m", "unity_stub_env.cli", "--task", "creature", "--num-areas", "2",
                         "--mlagents-port", str(port)], cwd=repo)
params = EnvironmentParametersChannel()
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=30, side_channels=[params])
params.set_float_parameter("creature_kind", 1.0)  # a biped, chosen before the task is built
params.set_float_parameter("creature_seed", 3.0)
env.reset()
out["behaviors"] = list(env.behavior_specs)
spec = env.behavior_specs["Creature?team=0"]
out["continuous"] = spec.action_spec.continuous_size
out["obs_shapes"] = [list(o.shape) for o in spec.observation_specs]
params.set_float_parameter("terrain_roughness", 0.5)
rng = np.random.default_rng(0)
steps = 0
for _ in range(20):
    decision, terminal = env.get_steps("Creature?team=0")
    steps += len(decision)
    env.set_actions("Creature?team=0", ActionTuple(continuous=rng.uniform(-1, 1, (len(decision), out["continuous"])).astype(np.float32)))
    env.step()
decision, terminal = env.get_steps("Creature?team=0")
out["finite"] = bool(np.isfinite(decision.obs[0]).all())
out["goal_speed"] = decision.obs[0][:, 3].tolist()
out["decisions"] = steps
env.close()
out["exit"] = stub.wait(timeout=20)
print("RESULT " + json.dumps(out))
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_drives_the_creature_task():
    out = run_interop_script(_SCRIPT, timeout=180)
    biped = generate("biped", 3)
    assert out["behaviors"] == ["Creature?team=0"]
    assert out["continuous"] == biped.num_hinges()
    assert out["obs_shapes"] == [[14 + 10 * len(biped.bones) + biped.num_hinges()]]
    assert out["finite"] and out["goal_speed"] == [1.0, 1.0]
    assert out["decisions"] == 40 and out["exit"] == 0
