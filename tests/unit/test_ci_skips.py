"""tests/conftest.py: under CI a skip is a failure with its reason, unless the test is marked
may_skip_in_ci; elsewhere it stays a skip, listed with its reason (-ra)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CONFTEST = Path(__file__).resolve().parents[1] / "conftest.py"
SUITE = '''
import pytest

def test_runs():
    pass

@pytest.mark.skipif(True, reason="needs two CPUs")
def test_skipped_by_a_mark():
    pass

def test_skipped_in_its_body():
    pytest.skip("the interop venv is missing")

@pytest.mark.may_skip_in_ci
def test_allowed_to_skip():
    pytest.skip("port 5004 is taken")
'''


def _run(tmp_path: Path, ci: str | None) -> subprocess.CompletedProcess:
    shutil.copy(CONFTEST, tmp_path / "conftest.py")
    (tmp_path / "test_suite.py").write_text(SUITE)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci is not None:
        env["CI"] = ci
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-ra", "-p", "no:cacheprovider", "-p", "no:timeout",
                           str(tmp_path)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("ci", [None, "", "false"])
def test_outside_ci_skips_stay_skips_and_are_listed_with_their_reason(tmp_path, ci):
    result = _run(tmp_path, ci)
    assert result.returncode == 0, result.stdout
    assert "1 passed, 3 skipped" in result.stdout
    skipped = [line for line in result.stdout.splitlines() if line.startswith("SKIPPED [1] test_suite.py")]
    for reason in ("needs two CPUs", "the interop venv is missing", "port 5004 is taken"):
        assert sum(line.endswith(reason) for line in skipped) == 1, result.stdout


def test_under_ci_a_skip_fails_with_its_reason_unless_marked(tmp_path):
    result = _run(tmp_path, "true")
    assert result.returncode == 1, result.stdout
    # the mark's skip happens in setup (an error), the body's in the call (a failure)
    assert "1 failed, 1 passed, 1 skipped, 1 error" in result.stdout
    assert "skipped under CI, where every test must run: needs two CPUs" in result.stdout
    assert "skipped under CI, where every test must run: the interop venv is missing" in result.stdout
    skipped = [line for line in result.stdout.splitlines() if line.startswith("SKIPPED [1] test_suite.py")]
    assert len(skipped) == 1 and skipped[0].endswith("port 5004 is taken"), result.stdout
