"""Skips that CI must not accept.

A test skips when this machine lacks what it needs: the interop venv (.venv-interop), a second
CPU, Linux's fork or affinity masks. Every skip is listed with its reason at the end of a run
(``-ra`` in pyproject.toml's addopts). Under CI (``CI`` set, as ``CI=true bash .ci/run`` does) such
a skip is a failure with the same reason, so a CI run that silently skipped the interop or fork
tests cannot pass. A test whose skip depends on something outside the project's control on any
machine (the Unity Editor's fixed port 5004 held by another program) says so with
``@pytest.mark.may_skip_in_ci`` and stays a skip.
"""
from __future__ import annotations

import os

import pytest


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
