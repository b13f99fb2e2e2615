"""trainer/envs/cpus.py: whether the trainer and its simulators may poll instead of sleeping."""
from __future__ import annotations

import os

import pytest

from trainer.envs import cpus as cpu_helpers
from trainer.envs.cpus import configured_spin, spin_budget
from trainer.errors import ConfigError


@pytest.mark.parametrize("cpus, processes, expected", [
    (2, 2, 0.001),  # trainer + one simulator on two CPUs: poll
    (2, 3, 0.0),    # two simulators + trainer on two CPUs: polling would steal a CPU
    (1, 2, 0.0),
    (16, 9, 0.001),
])
def test_spin_budget_needs_a_cpu_per_process(monkeypatch, cpus, processes, expected):
    monkeypatch.setattr(cpu_helpers, "usable_cpus", lambda: cpus)
    monkeypatch.delenv(cpu_helpers.SPIN_WAIT_ENV, raising=False)
    assert spin_budget(processes) == expected


@pytest.mark.parametrize("value, expected", [(None, 0.001), ("", 0.001), ("0", 0.0), ("2.5", 0.0025), (" 1 ", 0.001)])
def test_configured_spin_reads_milliseconds(value, expected):
    environ = {} if value is None else {"MLAGENTS_LIKE_SPIN_WAIT_MS": value}
    assert configured_spin(environ) == pytest.approx(expected)


@pytest.mark.parametrize("value", ["fast", "-1", "nan", "inf"])
def test_configured_spin_refuses_anything_else(value):
    with pytest.raises(ConfigError, match=f"MLAGENTS_LIKE_SPIN_WAIT_MS={value!r}"):
        configured_spin({"MLAGENTS_LIKE_SPIN_WAIT_MS": value})


def test_spin_budget_follows_the_setting(monkeypatch):
    monkeypatch.setattr(cpu_helpers, "usable_cpus", lambda: 4)
    monkeypatch.setenv("MLAGENTS_LIKE_SPIN_WAIT_MS", "0")
    assert spin_budget(2) == 0.0
    monkeypatch.setenv("MLAGENTS_LIKE_SPIN_WAIT_MS", "3")
    assert spin_budget(2) == pytest.approx(0.003)


def test_usable_cpus_is_the_affinity_mask():
    if not hasattr(os, "sched_getaffinity"):
        pytest.skip("no affinity masks on this OS")
    assert cpu_helpers.usable_cpus() == len(os.sched_getaffinity(0))
