"""The PPO update buffer: experiences waiting for the next update.

It keeps one growing list of arrays per field and concatenates them only when an update starts, so
appending a trajectory costs no copy.
"""
from __future__ import annotations

import numpy as np


class UpdateBuffer:
    """Experiences waiting for the next PPO update: field name -> list of [T, ...] arrays."""

    def __init__(self) -> None:
        self._fields: dict[str, list[np.ndarray]] = {}
        self._length = 0

    def __len__(self) -> int:
        return self._length

    def append(self, fields: dict[str, np.ndarray]) -> None:
        """Add one trajectory's arrays; every array shares the same leading length T."""
        lengths = {name: len(array) for name, array in fields.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"fields of one trajectory disagree on length: {lengths}")
        if self._fields and set(fields) != set(self._fields):
            raise ValueError(f"fields {sorted(fields)} differ from buffered fields {sorted(self._fields)}")
        for name, array in fields.items():
            self._fields.setdefault(name, []).append(array)
        self._length += next(iter(lengths.values()), 0)

    def rewrite(self, name: str, fn) -> None:
        """Replace every buffered array of field ``name`` by ``fn(array)`` (same leading length;
        POCA pads its teammate columns when a wider group arrives)."""
        arrays = self._fields.get(name)
        if arrays is not None:
            arrays[:] = [fn(array) for array in arrays]

    @property
    def field_names(self) -> list[str]:
        return list(self._fields)

    def concatenated(self) -> dict[str, np.ndarray]:
        """All buffered experiences, field name -> array [len(self), ...]."""
        return {name: np.concatenate(arrays, axis=0) for name, arrays in self._fields.items()}

    def clear(self) -> None:
        self._fields = {}
        self._length = 0
