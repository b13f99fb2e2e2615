"""The runner driven by the REAL mlagents_envs 1.1.0 (its own venv and process) in Editor mode,
with its track set through ML-Agents' own EnvironmentParametersChannel: the plain float keys
``track.count``, ``track.length``, ``track.i`` that the ``hmm`` sampler sends (docs/protocol.md, "Label sequences")."""
from __future__ import annotations

import os

import pytest

from tests.stub.conftest import INTEROP_PYTHON, run_interop_script

_SCRIPT = r"""
import json, subprocess, sys
import numpy as np
from mlagents_envs.environment import UnityEnvironment
from mlagents_envs.base_env import ActionTuple
from mlagents_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel
from mlagents_envs.side_channel.stats_side_channel import StatsSideChannel

port, stub_python, repo = int(sys.argv[1]), sys.argv[2], sys.argv[3]
out = {}
stub = subprocess.Popen([stub_python, "-m", "unity_stub_env.cli", "--task", "runner", "--mlagents-port", str(port)],
                        cwd=repo)
params, stats = EnvironmentParametersChannel(), StatsSideChannel()
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=30, side_channels=[params, stats])
for key, value in {"track.count": 1, "track.length": 3, "track.0": 0, "track.1": 0, "track.2": 0}.items():
    params.set_float_parameter(key, float(value))  # three Left platforms
env.reset()
out["behaviors"] = list(env.behavior_specs)
spec = env.behavior_specs["Runner?team=0"]
out["continuous"] = spec.action_spec.continuous_size
out["obs_shapes"] = [list(o.shape) for o in spec.observation_specs]
decision, _ = env.get_steps("Runner?team=0")
out["ahead"] = decision.obs[0][:, 4::5].tolist()  # turn of the current platform and 4 ahead
rewards, ended = [], []
for _ in range(20):
    env.set_actions("Runner?team=0", ActionTuple(continuous=np.zeros((len(decision), 1), dtype=np.float32)))
    env.step()
    decision, terminal = env.get_steps("Runner?team=0")
    ended += terminal.reward.tolist()
out["terminal_rewards"] = ended
out["stats"] = {key: [v for v, _ in values] for key, values in stats.get_and_reset_stats().items()}
env.close()
out["exit"] = stub.wait(timeout=20)
print("RESULT " + json.dumps(out))
"""


@pytest.mark.interop
@pytest.mark.skipif(not os.path.exists(INTEROP_PYTHON), reason="needs .venv-interop with mlagents 1.1.0")
def test_real_mlagents_envs_drives_the_runner_on_a_track_it_sent():
    out = run_interop_script(_SCRIPT)
    assert out["behaviors"] == ["Runner?team=0"]
    assert out["continuous"] == 1 and out["obs_shapes"] == [[29]]
    # every agent sees: the start platform (straight), three Left platforms, then the end
    assert out["ahead"] == [[0.0, 1.0, 1.0, 1.0, 0.0]] * 4
    # not steering, all four agents fall off in the first bend: -1 (plus a little progress)
    assert len(out["terminal_rewards"]) >= 4 and all(r < -0.9 for r in out["terminal_rewards"])
    assert set(out["stats"]["Runner/Track Length"]) == {4.0}
    assert set(out["stats"]["Runner/Track Completed"]) == {0.0}
    assert out["exit"] == 0
