"""unity-stub-env with its physics timed: ``python timed_stub.py OUT.json <stub args>``.

Wraps ``Academy.advance`` (the decision's ``decision_period`` physics steps, agent resets and
terminal infos) with a clock and writes every call's duration to OUT.json at exit, so
bench/protocol.py can subtract the physics of the very exchanges it timed, measured in the
same run on the same machine state.
"""
from __future__ import annotations

import atexit
import json
import sys
import time

from unity_stub_env import academy, cli

_durations: list[float] = []
_advance = academy.Academy.advance


def _timed_advance(self) -> None:
    started = time.perf_counter()
    _advance(self)
    _durations.append(time.perf_counter() - started)


def _dump(path: str) -> None:
    with open(path, "w") as out:
        json.dump(_durations, out)


if __name__ == "__main__":
    out_path = sys.argv[1]
    academy.Academy.advance = _timed_advance
    atexit.register(_dump, out_path)
    sys.argv = ["unity-stub-env"] + sys.argv[2:]
    sys.exit(cli.main())
