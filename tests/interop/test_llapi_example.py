"""docs/examples/python_llapi.py, the port of ML-Agents' Python-LLAPI page, runs; and run again
with its imports turned back into ``mlagents_envs`` under the real ML-Agents 1.1.0 it prints the
same summary (same spec, same episode rewards for the same seeds and random actions).

The page's code uses fixed ports: 5005 for the build (worker 0) and 5004 for the Editor, which the
stub plays here by connecting to 5004 (twice: the page opens the Editor twice)."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import pytest

from tests.interop.conftest import INTEROP_PYTHON, REPO, write_stub_executable
from tests.stub.conftest import start_stub

EXAMPLE = REPO / "docs" / "examples" / "python_llapi.py"


def port_taken(port: int) -> bool:
    with socket.socket() as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False


def run_example(python: str, script, cwd, env) -> dict:
    """The example in ``cwd`` (which holds ``3DBall``), with the stub pressing Play twice."""
    example = subprocess.Popen([python, str(script)], cwd=cwd, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(2):  # the Editor of snippets 2 and 3: it retries until the example listens
            editor = start_stub(5004, "basic", "--connect-timeout", "120")
            out, err = editor.communicate(timeout=180)
            assert editor.returncode == 0, err[-2000:]
        out, err = example.communicate(timeout=180)
    finally:
        if example.poll() is None:
            example.kill()
            example.communicate()
    assert example.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.may_skip_in_ci  # another program may hold port 5004 or 5005 on any machine
def test_the_python_llapi_page_ported_by_its_imports(tmp_path, interop_python):
    if port_taken(5004) or port_taken(5005):
        pytest.skip("port 5004 (the Editor's) or 5005 (worker 0's) is taken on this machine")
    build = write_stub_executable(tmp_path, "ball3d")
    build.rename(tmp_path / "3DBall.x86_64")
    ours = run_example(sys.executable, EXAMPLE, tmp_path, dict(os.environ, PYTHONPATH=str(REPO)))

    source = EXAMPLE.read_text()
    import_lines = [line for line in source.splitlines() if "mlagents_like_envs" in line]
    assert import_lines and all(line.startswith("from mlagents_like_envs.") for line in import_lines)
    theirs_script = tmp_path / "python_llapi_mlagents_envs.py"
    theirs_script.write_text(source.replace("from mlagents_like_envs.", "from mlagents_envs."))
    peer_env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    theirs = run_example(str(INTEROP_PYTHON), theirs_script, tmp_path, peer_env)

    assert ours == theirs
    assert ours["behavior"] == "3DBall?team=0" and ours["observation_shapes"] == [[8]]
    assert ours["action"] == [2, []]
    assert len(ours["episode_rewards"]) == 3 and all(r != 0 for r in ours["episode_rewards"])
    assert ours["editor_behaviors"] == ["Basic?team=0"] and ours["editor_reset_returns"] is None
