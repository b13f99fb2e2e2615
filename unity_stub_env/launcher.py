"""Make the stub look like a built Unity player on disk, so any tool that launches Unity builds
(mlagents-learn, mlagents_envs.UnityEnvironment, our own --env) can start it.

``write_player_launcher(folder, ["ball3d"])`` writes ``folder/StubBall3D.x86_64``: a ``#!/bin/sh``
script that execs this Python with ``-m unity_stub_env.cli --task ball3d`` and passes on every
argument the launching tool adds (``--mlagents-port``, ``-logFile``, ``-nographics`` ...). The
folder holding this ``unity_stub_env`` leads the stub's PYTHONPATH, so the launcher runs this very
code even when the launching tool drops PYTHONPATH (the ML-Agents peers do; a source checkout
other than the one installed in the venv would otherwise run the installed one).
Point the tool at ``folder/StubBall3D`` (without the suffix), as at a Unity build.
"""
from __future__ import annotations

import shlex
import stat
import sys
from pathlib import Path


def player_name(tasks: list[str]) -> str:
    """``["basic"]`` -> ``StubBasic``, ``["ball3d"]`` -> ``StubBall3D`` (Unity builds are CamelCase)."""
    return "Stub" + "".join("".join(ch for ch in task.title() if ch.isalnum()) for task in tasks)


def spin_wait_args(spin_s: float) -> list[str]:
    """The stub's command-line arguments for a polling budget of ``spin_s`` s (none for 0): how
    a launcher (ours, or the trainer's for ``--env stub:TASK``) passes pacing on to the stub."""
    return ["--spin-wait-ms", f"{spin_s * 1e3:g}"] if spin_s > 0 else []


def transport_args(transport: str) -> list[str]:
    """The stub's command-line arguments for its gRPC client ``transport`` (none for the default,
    http2): how mlagents-like-learn passes MLAGENTS_LIKE_TRANSPORT on (the stub reads no
    environment variable)."""
    return ["--transport", transport] if transport != "http2" else []


def write_player_launcher(folder: str | Path, tasks: list[str], python: str | None = None,
                          extra_args: list[str] | None = None) -> Path:
    """Write ``folder/<player_name>.x86_64`` (executable) and return its path; ``extra_args``
    (stub flags such as ``--spin-wait-ms 1``) come before the launching tool's arguments."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{player_name(tasks)}.x86_64"
    root = Path(__file__).resolve().parents[1]
    command = [python or sys.executable, "-m", "unity_stub_env.cli", "--task", ",".join(tasks), *(extra_args or [])]
    path.write_text("#!/bin/sh\nexec env PYTHONPATH=" + shlex.quote(str(root)) + '"${PYTHONPATH:+:$PYTHONPATH}" '
                    + " ".join(shlex.quote(part) for part in command) + ' "$@"\n')
    path.chmod(path.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    return path
