"""unity_stub_env: a headless simulator that talks to a trainer exactly like a Unity player
built with ML-Agents (communication API 1.5.0). See ``unity_stub_env.cli`` for the executable.

``TASKS`` and ``make_task`` (``unity_stub_env.tasks``) are loaded on first use: importing the
tasks imports MuJoCo (~0.3 s), which the trainer must not pay when it only checks a task name
before launching the stub.

This module is the stub's public API for other packages (the trainer uses nothing else):
``TASK_NAMES``, ``MIRROR_TASK``, ``spin_wait_args``, ``transport_args`` and ``write_player_launcher`` (cheap), ``TASKS`` and
``make_task`` (loaded on first use), and the HMM tools the trainer's ``hmm`` sampler uses: ``Hmm``,
``HmmError``, ``parse_corpus``, ``train_hmm`` (``unity_stub_env.hmm``, loaded on first use).

On a Linux machine without a display, importing the package sets ``MUJOCO_GL=egl`` unless it is
set (``unity_stub_env.render.gl``): MuJoCo reads it once, and its default (GLFW) needs a display."""
from __future__ import annotations

from unity_stub_env.render.gl import headless_default

headless_default()  # before anything imports MuJoCo: it reads MUJOCO_GL once, at import

from unity_stub_env.launcher import spin_wait_args, transport_args, write_player_launcher
from unity_stub_env.task_names import MIRROR_TASK, TASK_NAMES

__all__ = ["MIRROR_TASK", "TASK_NAMES", "TASKS", "make_task", "spin_wait_args", "transport_args", "write_player_launcher",
           "Hmm", "HmmError", "parse_corpus", "train_hmm"]
_LAZY = ("TASKS", "make_task")
_LAZY_HMM = {"Hmm": "Hmm", "HmmError": "HmmError", "parse_corpus": "parse_corpus", "train_hmm": "train"}


def __getattr__(name: str):
    if name in _LAZY:
        from unity_stub_env import tasks

        return getattr(tasks, name)
    if name in _LAZY_HMM:
        from unity_stub_env import hmm

        return getattr(hmm, _LAZY_HMM[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
