"""unity_stub_env: a headless simulator that talks to a trainer exactly like a Unity player
built with ML-Agents (communication API 1.5.0). See ``unity_stub_env.cli`` for the executable."""
from __future__ import annotations

from unity_stub_env.tasks import TASKS, make_task

__all__ = ["TASKS", "make_task"]
