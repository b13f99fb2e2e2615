"""docs/examples/python_llapi.py, the port of ML-Agents' Python-LLAPI page, runs; and run again
with its imports turned back into ``mlagents_envs`` under the real ML-Agents 1.1.0 it prints the
same summary (same spec, same episode rewards for the same seeds and random actions).

The page's code uses fixed ports: 5005 for the build (worker 0) and 5004 for the Editor, which the
stub plays by connecting to 5004 (twice: the page opens the Editor twice). Each run gets a network
namespace of its own (``unshare -rn``) where the machine allows it, so other programs holding
those ports do not matter; otherwise it runs on the machine's ports if they are free."""
from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys

import pytest

from tests.interop.conftest import INTEROP_PYTHON, REPO, write_stub_executable

EXAMPLE = REPO / "docs" / "examples" / "python_llapi.py"


def port_taken(port: int) -> bool:
    with socket.socket() as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False


def own_network() -> list[str] | None:
    """The prefix that runs a command in a new network namespace with loopback up, or None."""
    if not (shutil.which("unshare") and shutil.which("ip")):
        return None
    prefix = ["unshare", "-rn", "sh", "-c", 'ip link set lo up && exec "$@"', "sh"]
    try:
        ok = subprocess.run(prefix + ["true"], capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        ok = False
    return prefix if ok else None


def run_example(prefix: list[str], python: str, script, folder) -> dict:
    done = subprocess.run(prefix + [sys.executable, "-m", "tests.interop.llapi_session", python, str(script),
                                    str(folder)], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.may_skip_in_ci  # without network namespaces, another program may hold port 5004 or 5005
def test_the_python_llapi_page_ported_by_its_imports(tmp_path, interop_python):
    prefix = own_network()
    if prefix is None:
        prefix = []
        if port_taken(5004) or port_taken(5005):
            pytest.skip("no network namespace (unshare -rn), and port 5004 (the Editor's) or 5005 "
                        "(worker 0's) is taken on this machine")
    build = write_stub_executable(tmp_path, "ball3d")
    build.rename(tmp_path / "3DBall.x86_64")
    ours = run_example(prefix, sys.executable, EXAMPLE, tmp_path)

    source = EXAMPLE.read_text()
    import_lines = [line for line in source.splitlines() if "mlagents_like_envs" in line]
    assert import_lines and all(line.startswith("from mlagents_like_envs.") for line in import_lines)
    theirs_script = tmp_path / "python_llapi_mlagents_envs.py"
    theirs_script.write_text(source.replace("from mlagents_like_envs.", "from mlagents_envs."))
    theirs = run_example(prefix, str(INTEROP_PYTHON), theirs_script, tmp_path)

    assert ours == theirs
    assert ours["behavior"] == "3DBall?team=0" and ours["observation_shapes"] == [[8]]
    assert ours["action"] == [2, []]
    assert len(ours["episode_rewards"]) == 3 and all(r != 0 for r in ours["episode_rewards"])
    assert ours["editor_behaviors"] == ["Basic?team=0"] and ours["editor_reset_returns"] is None
