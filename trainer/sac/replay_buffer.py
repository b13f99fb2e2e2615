"""SAC's replay buffer: a fixed-capacity ring of experiences in numpy, and its file.

Each field (``obs_0``, ``next_obs_0``, ``rewards``, ``done``, ...) is one array [capacity, ...]
allocated at the first ``add``. New rows go at ``cursor`` and wrap around, overwriting the oldest
(ML-Agents instead truncates its list to 80 % of buffer_size when it overflows; both keep the
most recent experiences). Minibatches are drawn uniformly with replacement from a torch generator,
whose state the trainer keeps in its checkpoint.

With network_settings.memory the trainer adds whole sequences (each trajectory padded to a
multiple of ``sequence_length``, its pad rows masked) into a ring whose capacity is a multiple of
it, so every sequence starts at a multiple of ``sequence_length``; ``sample_sequences`` draws
such starts, as the reference samples its sequences.

The file (``save_replay_buffer``) is an .npz archive of plain arrays, written atomically and read
with ``allow_pickle=False``: loading it can never run code.
"""
from __future__ import annotations

import os

import numpy as np
import torch

from trainer.artifacts.atomic import atomic_write

_META = ("__cursor__", "__size__", "__capacity__")


class ReplayBuffer:
    def __init__(self, capacity: int):
        if capacity < 1:
            raise ValueError(f"replay buffer capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.fields: dict[str, np.ndarray] = {}
        self.cursor = 0  # the row the next experience goes to
        self.size = 0  # rows holding experiences (<= capacity)

    def __len__(self) -> int:
        return self.size

    def add(self, fields: dict[str, np.ndarray]) -> None:
        """Append T experiences: every array [T, ...] with the same T. Beyond capacity, the oldest go."""
        lengths = {len(v) for v in fields.values()}
        if len(lengths) != 1:
            raise ValueError(f"fields disagree on length: { {k: len(v) for k, v in fields.items()} }")
        if self.fields and set(fields) != set(self.fields):
            raise ValueError(f"fields {sorted(fields)} differ from the buffer's {sorted(self.fields)}")
        length = lengths.pop()
        if not self.fields:
            self.fields = {k: np.zeros((self.capacity, *np.shape(v)[1:]), dtype=np.asarray(v).dtype)
                           for k, v in fields.items()}
        if length > self.capacity:  # only the newest capacity rows survive
            fields = {k: v[-self.capacity:] for k, v in fields.items()}
            length = self.capacity
        rows = (self.cursor + np.arange(length)) % self.capacity
        for key, value in fields.items():
            self.fields[key][rows] = value
        self.cursor = (self.cursor + length) % self.capacity
        self.size = min(self.size + length, self.capacity)

    def sample_indices(self, batch_size: int, generator: torch.Generator) -> np.ndarray:
        """int64 [batch_size], uniform over the filled rows, with replacement."""
        return torch.randint(0, self.size, (batch_size,), generator=generator).numpy()

    def sample(self, batch_size: int, generator: torch.Generator) -> dict[str, np.ndarray]:
        index = self.sample_indices(batch_size, generator)
        return {key: value[index] for key, value in self.fields.items()}

    def sample_sequences(self, count: int, sequence_length: int, generator: torch.Generator
                         ) -> dict[str, np.ndarray]:
        """``count`` whole sequences of ``sequence_length`` rows (uniform starts at multiples of
        it, with replacement), concatenated: every field [count * sequence_length, ...]."""
        starts = torch.randint(0, self.size // sequence_length, (count,), generator=generator).numpy()
        index = (starts[:, None] * sequence_length + np.arange(sequence_length)).reshape(-1)
        return {key: value[index] for key, value in self.fields.items()}

    def chronological(self) -> dict[str, np.ndarray]:
        """Every stored experience, oldest first."""
        start = self.cursor if self.size == self.capacity else 0
        order = (start + np.arange(self.size)) % self.capacity
        return {key: value[order] for key, value in self.fields.items()}

    # ------------------------------------------------------------------ file
    def save(self, path: str | os.PathLike[str]) -> None:
        """The filled rows, the cursor and the size as an .npz, written atomically."""
        arrays = {key: value[:self.size] for key, value in self.fields.items()}
        arrays["__cursor__"] = np.asarray(self.cursor, dtype=np.int64)
        arrays["__size__"] = np.asarray(self.size, dtype=np.int64)
        arrays["__capacity__"] = np.asarray(self.capacity, dtype=np.int64)
        atomic_write(path, lambda f: np.savez(f, **arrays))

    def load(self, path: str | os.PathLike[str]) -> None:
        """Replace the contents with a saved buffer. The same capacity restores the ring exactly
        (the same rows at the same places, the same cursor); another capacity gets the saved
        experiences oldest first, so it keeps the newest."""
        with np.load(path, allow_pickle=False) as archive:
            cursor, size, capacity = (int(archive[key]) for key in _META)
            saved = {key: archive[key] for key in archive.files if key not in _META}
        self.fields, self.cursor, self.size = {}, 0, 0
        if size == 0 or not saved:
            return
        if capacity == self.capacity:
            self.add(saved)  # rows 0..size-1, where they were
            self.cursor = cursor
            return
        order = (cursor + np.arange(size)) % size  # a wrapped ring's oldest row is at the cursor
        self.add({key: value[order] for key, value in saved.items()})
