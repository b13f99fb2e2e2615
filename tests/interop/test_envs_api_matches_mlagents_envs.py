"""``mlagents_like_envs`` against the real ``mlagents_envs`` 1.1.0, each in its own venv and process.

The same script (peer_scripts/envs_api_episode.py, which imports ``<package>.environment`` and
the rest by mlagents_envs' module paths) drives the same stub build through the same seeded
session with the same actions, once under each package. Specs, every observation, reward, id,
group and termination of every step, the stats side channel and the exception classes of three
misuses must be the same; the only differences allowed are the two dtypes docs/python-api.md
("Porting a script") names.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.interop.conftest import PEER_SCRIPTS, REPO

STEPS = 60


def run_ours(options: dict, cwd) -> dict:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run([sys.executable, str(PEER_SCRIPTS / "envs_api_episode.py"), json.dumps(options)],
                          capture_output=True, text=True, timeout=180, cwd=cwd, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("task, behaviors", [
    ("ball3d", ["3DBall?team=0"]),
    ("basic", ["Basic?team=0"]),
    ("soccer_twos", ["SoccerTwos?team=0", "SoccerTwos?team=1"]),
])
def test_the_same_seeded_session_step_by_step(task, behaviors, stub_executable, free_port, run_peer, tmp_path):
    build = stub_executable(task)
    options = {"file_name": str(build.with_suffix("")), "seed": 3, "steps": STEPS, "action_seed": 7,
               "float_parameters": {"gravity": 9.81}, "time_scale": 20.0}
    completed, theirs = run_peer("envs_api_episode.py", {**options, "package": "mlagents_envs",
                                                         "base_port": free_port()}, timeout=180)
    assert theirs is not None, completed.stderr[-3000:]
    ours = run_ours({**options, "package": "mlagents_like_envs", "base_port": free_port()}, tmp_path)

    assert ours["specs_before_reset"] == theirs["specs_before_reset"] == {}  # specs arrive with the reset
    assert list(ours["specs"]) == behaviors
    assert ours["specs"] == theirs["specs"]
    assert len(ours["steps"]) == len(theirs["steps"]) == STEPS + 1
    for index, (mine, peer) in enumerate(zip(ours["steps"], theirs["steps"])):
        assert mine == peer, f"message {index} (0 = the reset) differs"
    deciding = sum(s[name]["decision"]["len"] for s in ours["steps"] for name in behaviors)
    assert deciding >= (STEPS + 1) * len(behaviors)  # every behavior decided at every message
    if task == "ball3d":  # random tilts drop balls: episodes end inside the compared window
        assert sum(s[behaviors[0]]["terminal"]["len"] for s in ours["steps"]) >= 10
        assert ours["stats"]["3DBall/Ball Fell"]
    assert ours["stats"] == theirs["stats"]
    for misuse, classes in theirs["errors"].items():
        if isinstance(classes, list):  # ours is the same class or a subclass of it
            assert set(classes) <= set(ours["errors"][misuse]), misuse
        else:
            assert ours["errors"][misuse] == classes, misuse
    assert theirs["errors"]["agent not deciding"] == ["Exception", "IndexError", "LookupError"]
    assert theirs["errors"]["second close"] == "UnityEnvironmentException"
    differ = {key: (ours["dtypes"][key], theirs["dtypes"][key]) for key in theirs["dtypes"]
              if ours["dtypes"][key] != theirs["dtypes"][key]}
    assert differ == {"decision.agent_id": ("int64", "int32"), "decision.group_id": ("ndarray:int32", "list:int64")}
