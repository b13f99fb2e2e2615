"""unity_stub_env: a headless simulator that talks to a trainer exactly like a Unity player
built with ML-Agents (communication API 1.5.0). See ``unity_stub_env.cli`` for the executable.

``TASKS`` and ``make_task`` (``unity_stub_env.tasks``) are loaded on first use: importing the
tasks imports MuJoCo (~0.3 s), which the trainer must not pay when it only checks a task name
(``unity_stub_env.task_names``) before launching the stub."""
from __future__ import annotations

__all__ = ["TASKS", "make_task"]


def __getattr__(name: str):
    if name in __all__:
        from unity_stub_env import tasks

        return getattr(tasks, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
