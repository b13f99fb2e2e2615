"""Skips that CI must not accept, and which tests pytest-xdist's workers must not run side by side.

A test skips when this machine lacks what it needs: the interop venv (.venv-interop), a second
CPU, Linux's fork or affinity masks. Every skip is listed with its reason at the end of a run
(``-ra`` in pyproject.toml's addopts). Under CI (``CI`` set, as ``CI=true bash .ci/run`` does) such
a skip is a failure with the same reason, so a CI run that silently skipped the interop or fork
tests cannot pass. A test whose skip depends on something outside the project's control on any
machine (the Unity Editor's fixed port 5004 held by another program) says so with
``@pytest.mark.may_skip_in_ci`` and stays a skip.

./test.sh runs the tests in pytest-xdist workers (``-n auto --dist loadgroup``). ``XDIST_GROUPS``
names the tests that share something no two workers may use at once; each group is sent to one
worker whole (docs/testing.md, "Workers and what they must not share").
"""
from __future__ import annotations

import os

import pytest

# Two workers each run a trainer and its simulators on the same two CPUs. A run polls for its peer
# only when each of its processes has a CPU of its own (trainer/envs/cpus.py), which each run
# believes but the workers together do not have; polling would take the CPU the other worker's
# processes wait for. So, in workers, runs sleep while they wait (MLAGENTS_LIKE_SPIN_WAIT_MS=0,
# docs/configuration.md), unless the caller set it. Waiting changes no number a test checks.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    os.environ.setdefault("MLAGENTS_LIKE_SPIN_WAIT_MS", "0")

# node id prefix -> group. Kept here rather than as xdist_group marks: pytest 9.2's structured
# node ids silently drop the marks' grouping in pytest-xdist 3.8 (pytest-xdist issue 1386).
XDIST_GROUPS = {
    # the private Slurm cluster (tests/slurm/conftest.py's session fixtures) starts once
    "tests/slurm/": "slurm",
    # the Unity Editor's fixed port 5004 (test_llapi_example too, where it has no network namespace)
    "tests/integration/test_learn_cli.py::test_editor_mode_listens_on_5004_and_trains_the_player_that_connects": "port_5004",
    "tests/integration/test_hostile_simulators.py::test_editor_mode_port_in_use_gives_advice_that_works": "port_5004",
    "tests/interop/test_llapi_example.py::": "port_5004",
    # module fixtures that train or record once for all their tests
    "tests/interop/test_mlagents_learn.py::": "mlagents_learn_run",
    "tests/unit/test_demonstrations.py::test_gail_rewards_expert_steps_above_random_ones_after_training": "ball3d_demos",
}


def xdist_group(nodeid: str) -> str | None:
    return next((group for prefix, group in XDIST_GROUPS.items() if nodeid.startswith(prefix)), None)


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist, absent without it
def pytest_xdist_make_scheduler(config, log):
    """--dist loadgroup with the groups of XDIST_GROUPS: every other test is a unit of its own,
    sent to the next free worker; larger units go first (pytest-xdist's loadscope order)."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return xdist_group(nodeid) or nodeid

    return GroupScheduling(config, log)


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def pytest_configure(config):
    config.addinivalue_line("markers", "may_skip_in_ci: a skip of this test is accepted under CI too")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if (report.skipped and not hasattr(report, "wasxfail") and in_ci()
            and item.get_closest_marker("may_skip_in_ci") is None):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        reason = reason.removeprefix("Skipped: ")
        report.outcome = "failed"
        report.longrepr = f"skipped under CI, where every test must run: {reason}"
