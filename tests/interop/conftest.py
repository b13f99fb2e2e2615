"""Fixtures for proving interop against the REAL ML-Agents 1.1.0 (its own venv, own processes).

* ``interop_python``  - the interop venv's python (tests/interop_venv.py: .venv-interop, or
                        INTEROP_VENV), or the test is skipped with the reason
* ``stub_executable`` - factory: task name -> ``<tmp>/Stub<Task>.x86_64``, a ``#!/bin/sh`` script
                        that execs this interpreter's ``-m unity_stub_env.cli --task <task> "$@"``,
                        laid out like a Linux Unity player build
* ``free_port``       - factory: a TCP port nothing listens on (v4 and v6 wildcard)
* ``is_gone``         - pid -> True once that process no longer runs (zombies count as gone)
* ``run_peer``        - runs a script of ``peer_scripts/`` in .venv-interop and returns its
                        CompletedProcess plus the JSON object printed on its last stdout line
"""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.interop_venv import INTEROP_PYTHON, INTEROP_VENV, REPO
from unity_stub_env.launcher import write_player_launcher

PEER_SCRIPTS = Path(__file__).resolve().parent / "peer_scripts"


def pytest_collection_modifyitems(config, items):
    here = Path(__file__).resolve().parent
    for item in items:
        if here in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.interop)


@pytest.fixture(scope="session")
def interop_python() -> Path:
    if not INTEROP_PYTHON.exists():
        pytest.skip(f"{INTEROP_PYTHON} is missing: run ./scripts/ensure_interop_venv.sh "
                    "(./test.sh does) to install the real ML-Agents 1.1.0 peer")
    return INTEROP_PYTHON


def write_stub_executable(folder: Path, task: str) -> Path:
    """``folder/Stub<Task>.x86_64``: a shell launcher that runs the stub with this Python."""
    return write_player_launcher(folder, [task])


@pytest.fixture(scope="session")
def stub_launcher():
    """(folder, task) -> path of a new ``Stub<Task>.x86_64`` in folder (usable at any scope)."""
    return write_stub_executable


@pytest.fixture
def stub_executable(tmp_path):
    def make(task: str) -> Path:
        return write_stub_executable(tmp_path, task)
    return make


def find_free_port() -> int:
    """A port free on 127.0.0.1 and on the IPv6 wildcard (mlagents binds ``[::]:port``)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        try:
            with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe6:
                probe6.bind(("::", port))
        except OSError:
            continue
        return port
    raise RuntimeError("no free TCP port found")


@pytest.fixture(scope="session")
def free_port():
    return find_free_port


def process_is_gone(pid: int) -> bool:
    """True if ``pid`` no longer runs (missing, or a zombie waiting for a reaper)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return True
    state = next((line for line in status.splitlines() if line.startswith("State:")), "")
    return "Z" in state.split(":", 1)[-1].split()[:1]


@pytest.fixture
def is_gone():
    return process_is_gone


def _peer_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the peer must never see our packages or our protobuf
    env["PATH"] = f"{INTEROP_VENV / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return env


@pytest.fixture
def run_peer(interop_python, tmp_path):
    def run(script: str, options: dict, timeout: float = 120.0):
        completed = subprocess.run(
            [str(interop_python), str(PEER_SCRIPTS / script), json.dumps(options)],
            capture_output=True, text=True, timeout=timeout, cwd=tmp_path, env=_peer_env(),
        )
        lines = completed.stdout.strip().splitlines()
        payload = None
        if completed.returncode == 0 and lines:
            payload = json.loads(lines[-1])
        return completed, payload
    return run
