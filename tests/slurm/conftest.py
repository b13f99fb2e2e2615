"""Fixtures for the tests on a real (private, one-node) Slurm cluster: ``pytest -m "not slurm"``
leaves them out; ./test.sh and CI run them. A machine without Slurm gets it from
scripts/ensure_slurm.sh (Debian's slurm-wlm and munge; needs root or sudo)."""
from __future__ import annotations

import subprocess

import pytest

from tests.slurm.cluster import ROOT, Cluster


def _ensure_slurm() -> None:
    installed = subprocess.run(["bash", str(ROOT / "scripts" / "ensure_slurm.sh")], capture_output=True, text=True)
    if installed.returncode != 0:
        pytest.fail("Slurm/MUNGE are missing and scripts/ensure_slurm.sh could not install them "
                    f"(deselect these tests with -m 'not slurm'):\n{installed.stderr}")


@pytest.fixture(scope="session")
def cluster():
    """One node on 127.0.0.1."""
    _ensure_slurm()
    c = Cluster()
    try:
        c.start()
        yield c
    finally:
        c.stop()


@pytest.fixture(scope="session")
def cluster2():
    """Two nodes, na and nb, each in a network namespace of its own."""
    _ensure_slurm()
    c = Cluster(netns=True)
    try:
        c.start()
        yield c
    finally:
        c.stop()
