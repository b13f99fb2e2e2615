"""Hierarchical timers and gauges written to ``run_logs/timers.json`` (docs/outputs.md, "Outputs").

A :class:`TimerTree` is an ordinary object (no module globals), driven by the trainer's one
thread. That keeps ``scope`` lock-free: entering and leaving costs two ``perf_counter`` calls, a dict
lookup and a list push/pop.

    timers = TimerTree()
    with timers.scope("env_step"):
        with timers.scope("communicate"):
            ...
    timers.set_gauge("Ball.Policy.Entropy.mean", 1.41)
    timers.write("results/run/run_logs/timers.json")
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from importlib import metadata as importlib_metadata
from typing import Any, Callable

from protos.versions import COMMUNICATION_VERSION
from trainer.artifacts.atomic import atomic_write

__all__ = ["TimerNode", "GaugeNode", "TimerTree", "TIMER_FORMAT_VERSION", "package_version"]

TIMER_FORMAT_VERSION = "0.1.0"
PACKAGE_NAME = "mlagents-like"

def package_version(dist_name: str = PACKAGE_NAME, module: str | None = None) -> str:
    """Version of an installed distribution (prefers ``module.__version__`` if imported)."""
    loaded = sys.modules.get(module) if module else None
    version = getattr(loaded, "__version__", None)
    if version:
        return str(version)
    try:
        return importlib_metadata.version(dist_name)
    except importlib_metadata.PackageNotFoundError:
        if dist_name == PACKAGE_NAME:  # run from a checkout that pip did not install
            from trainer import __version__

            return __version__
        return "unknown"


class TimerNode:
    """Total seconds and entry count of one code block, plus its children by name."""

    __slots__ = ("children", "total", "count")

    def __init__(self) -> None:
        self.children: dict[str, TimerNode] = {}
        self.total = 0.0
        self.count = 0

    def child(self, name: str) -> TimerNode:
        node = self.children.get(name)
        if node is None:
            node = self.children[name] = TimerNode()
        return node


class GaugeNode:
    """Latest value of a metric with its min, max and number of updates."""

    __slots__ = ("value", "min", "max", "count")

    def __init__(self, value: float) -> None:
        self.value = value
        self.min = value
        self.max = value
        self.count = 1

    def update(self, value: float) -> None:
        self.value = value
        if value < self.min:
            self.min = value
        if value > self.max:
            self.max = value
        self.count += 1

    def as_dict(self) -> dict[str, float]:
        return {"value": self.value, "min": self.min, "max": self.max, "count": self.count}


class _Scope:
    """Context manager for one timed block; created per ``scope()`` call."""

    __slots__ = ("_tree", "_name", "_node", "_start")

    def __init__(self, tree: TimerTree, name: str) -> None:
        self._tree = tree
        self._name = name

    def __enter__(self) -> TimerNode:
        stack = self._tree._stack
        node = stack[-1].child(self._name)
        stack.append(node)
        self._node = node
        self._start = self._tree._clock()
        return node

    def __exit__(self, *exc: object) -> None:
        node = self._node
        node.total += self._tree._clock() - self._start
        node.count += 1
        self._tree._stack.pop()


class TimerTree:
    """Timer tree, gauges and metadata of one run.

    ``clock`` (seconds, monotonic) times scopes and the root total; ``wall_clock`` (unix seconds)
    stamps ``start_time_seconds`` / ``end_time_seconds``. Both are injectable for tests.
    """

    def __init__(
        self,
        clock: Callable[[], float] = time.perf_counter,
        wall_clock: Callable[[], float] = time.time,
        argv: list[str] | None = None,
    ) -> None:
        self._clock = clock
        self._wall_clock = wall_clock
        self.root = TimerNode()
        self._stack: list[TimerNode] = [self.root]
        self._start = clock()
        self.gauges: dict[str, GaugeNode] = {}
        self.metadata: dict[str, str] = self._default_metadata(argv)

    def _default_metadata(self, argv: list[str] | None) -> dict[str, str]:
        ours = package_version()
        return {
            "timer_format_version": TIMER_FORMAT_VERSION,
            "start_time_seconds": str(int(self._wall_clock())),
            "python_version": sys.version,
            "command_line_arguments": " ".join(sys.argv if argv is None else argv),
            "mlagents_version": ours,
            "mlagents_envs_version": ours,
            "mlagents_like_version": ours,
            "communication_protocol_version": COMMUNICATION_VERSION,
            "pytorch_version": package_version("torch", module="torch"),
            "numpy_version": package_version("numpy", module="numpy"),
        }

    # -- timing ---------------------------------------------------------------------------------
    def scope(self, name: str) -> _Scope:
        """``with timers.scope("name"):`` times the block under the currently open scope."""
        return _Scope(self, name)

    # -- gauges and metadata --------------------------------------------------------------------
    def set_gauge(self, name: str, value: float) -> None:
        """Track the latest value and its min/max/count; NaN is ignored."""
        value = float(value)
        if math.isnan(value):
            return
        gauge = self.gauges.get(name)
        if gauge is None:
            self.gauges[name] = GaugeNode(value)
        else:
            gauge.update(value)

    # -- output ---------------------------------------------------------------------------------
    def _node_dict(self, node: TimerNode) -> dict[str, Any]:
        out: dict[str, Any] = {"total": node.total, "count": node.count}
        children = {name: self._node_dict(child) for name, child in node.children.items()}
        child_total = sum(child["total"] for child in children.values())
        out["self"] = max(0.0, node.total - child_total)
        if children:
            out["children"] = children
        return out

    def to_dict(self) -> dict[str, Any]:
        """The timers.json layout: name, gauges, metadata, total, count, self, children.

        The root's total is the time since the tree was created and its count is 1;
        ``end_time_seconds`` is stamped now.
        """
        self.root.total = self._clock() - self._start
        self.root.count = 1
        self.metadata["end_time_seconds"] = str(int(self._wall_clock()))
        out: dict[str, Any] = {
            "name": "root",
            "gauges": {name: gauge.as_dict() for name, gauge in self.gauges.items()},
            "metadata": dict(self.metadata),
        }
        out.update(self._node_dict(self.root))
        return out

    def write(self, path: str | os.PathLike[str]) -> None:
        """Write ``to_dict()`` as indented JSON atomically (temp file + ``os.replace``)."""
        write_json_atomic(path, self.to_dict())


def write_json_atomic(path: str | os.PathLike[str], data: Any) -> None:
    """Dump ``data`` as JSON (indent 4) to a temp file in the target folder, then rename."""
    def dump(f) -> None:
        json.dump(data, f, indent=4)
        f.write("\n")

    atomic_write(path, dump, binary=False)
