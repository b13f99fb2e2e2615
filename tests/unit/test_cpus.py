"""trainer/envs/cpus.py: whether the trainer and its simulators may poll instead of sleeping."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from trainer.envs import cpus as cpu_helpers
from trainer.envs.cpus import spin_budget


@pytest.mark.parametrize("cpus, processes, expected", [
    (2, 2, 0.001),  # trainer + one simulator on two CPUs: poll
    (2, 3, 0.0),    # two simulators + trainer on two CPUs: polling would steal a CPU
    (1, 2, 0.0),
    (16, 9, 0.001),
])
def test_spin_budget_needs_a_cpu_per_process(monkeypatch, cpus, processes, expected):
    monkeypatch.setattr(cpu_helpers, "usable_cpus", lambda: cpus)
    assert spin_budget(processes, 0.001) == expected


def test_spin_budget_follows_the_setting(monkeypatch):
    monkeypatch.setattr(cpu_helpers, "usable_cpus", lambda: 4)
    assert spin_budget(2, 0.0) == 0.0
    assert spin_budget(2, 0.003) == pytest.approx(0.003)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or (os.cpu_count() or 1) < 2,
                    reason="needs affinity masks and two CPUs to tell the mask from the CPU count")
def test_usable_cpus_is_the_affinity_mask():
    """In a child process pinned to one CPU (as taskset or a Slurm allocation would), the count
    is 1 though the machine has more."""
    code = ("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
            "from trainer.envs.cpus import usable_cpus; print(usable_cpus(), os.cpu_count())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out[0] == "1" and int(out[1]) >= 2
