"""Installed as sitecustomize.py into .venv-interop on Python 3.12 and newer only.

ML-Agents 1.1.0 was written for Python 3.10 and numpy 1.23.5. Past Python 3.11 numpy 1.23.5 has no
wheel, so the interop venv runs a current numpy, and two things ML-Agents uses are gone. This file
puts back exactly those two, with the meaning they had on Python 3.11 / numpy 1.23.5, and nothing
else (docs/python-versions.md "The interop peer on Python 3.12 and 3.13"):

* ``numpy.float``: an alias of the builtin ``float`` (deprecated in numpy 1.20, removed in 1.24).
  ML-Agents evaluates it in an annotation of ``mlagents/trainers/buffer.py`` at import time.
* ``importlib.metadata.entry_points()`` called without arguments returns a dict of group name ->
  entry points, as on Python 3.10/3.11 (3.12 returns one flat ``EntryPoints``). ML-Agents' plugin
  registry (``mlagents/plugins/trainer_type.py``, ``stats_writer.py``) does ``group in
  entry_points()`` and ``entry_points()[group]``. Calls with arguments are passed through unchanged.
"""
import importlib.metadata as _metadata

try:
    import numpy as _np
except ImportError:  # while pip is still filling the venv
    _np = None
if _np is not None and "float" not in _np.__dict__:
    _np.float = float

_entry_points = _metadata.entry_points


class _GroupedEntryPoints(dict):
    """Python 3.11's no-argument ``entry_points()``: a dict by group that also has ``select``."""

    def __init__(self, flat):
        super().__init__((group, flat.select(group=group)) for group in sorted(flat.groups))
        self._flat = flat

    def select(self, **params):
        return self._flat.select(**params)


def entry_points(**params):
    if params:
        return _entry_points(**params)
    return _GroupedEntryPoints(_entry_points())


_metadata.entry_points = entry_points
