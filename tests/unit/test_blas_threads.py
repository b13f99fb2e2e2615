"""mlagents-like-learn keeps numpy's BLAS to one thread unless told otherwise (trainer.cli)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from trainer.cli import read_environment
from trainer.errors import ConfigError

# In a fresh interpreter: read the environment as main() does, then count the process's threads
# after a matrix product big enough for OpenBLAS to use every thread it was allowed.
PROBE = """
import json, os, sys
import trainer.cli
assert "numpy" not in sys.modules  # main() can still set the variables in time
trainer.cli.read_environment()
import numpy as np
a = np.ones((600, 600)); a @ a
print(json.dumps({"threads": len(os.listdir("/proc/self/task")),
                  "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS")}))
"""


def _probe(extra_env: dict) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "MLAGENTS_LIKE_BLAS_THREADS")}
    env.update(extra_env)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task") or (os.cpu_count() or 1) < 2,
                    reason="needs Linux /proc and two CPUs to tell one BLAS thread from several")
def test_one_blas_thread_by_default_and_the_users_choice_otherwise():
    assert _probe({}) == {"threads": 1, "OPENBLAS_NUM_THREADS": "1"}
    assert _probe({"MLAGENTS_LIKE_BLAS_THREADS": "2"}) == {"threads": 2, "OPENBLAS_NUM_THREADS": "2"}
    assert _probe({"OPENBLAS_NUM_THREADS": "2"}) == {"threads": 2, "OPENBLAS_NUM_THREADS": "2"}


def test_blas_thread_rules():
    env: dict = {}
    read_environment(env)
    assert env == {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env = {"OMP_NUM_THREADS": "4"}
    read_environment(env)
    assert env == {"OMP_NUM_THREADS": "4"}  # the user's own setting stands
    env = {"MLAGENTS_LIKE_BLAS_THREADS": "3", "OPENBLAS_NUM_THREADS": "8"}
    read_environment(env)
    assert env["OPENBLAS_NUM_THREADS"] == "3" and env["MKL_NUM_THREADS"] == "3"
    env = {"MLAGENTS_LIKE_BLAS_THREADS": "many"}
    with pytest.raises(ConfigError, match="MLAGENTS_LIKE_BLAS_THREADS='many'"):
        read_environment(env)
    assert "OPENBLAS_NUM_THREADS" not in env  # refused before anything was set
