"""checkpoint.pt files: atomic saves and safe (weights_only) loads.

A checkpoint holds only tensors, numbers, strings, dicts and lists, so it loads with
``torch.load(weights_only=True)``, which refuses any pickle that would run code.
"""
from __future__ import annotations

import os
from typing import Any

import torch

from trainer.artifacts.atomic import atomic_write
from trainer.errors import UserError

_RECOVERY_HINT = "use --force to start over, or a different --run-id"


def save_checkpoint(path: str | os.PathLike[str], state: dict[str, Any]) -> None:
    """torch.save ``state`` to a temp file beside ``path``, fsync it, then os.replace onto ``path``.

    A failure at any point leaves an existing file at ``path`` untouched.
    """
    atomic_write(path, lambda f: torch.save(state, f))




def load_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Load a checkpoint onto the CPU, refusing anything but plain tensors and containers."""
    if not os.path.isfile(path):
        raise UserError(f"checkpoint {os.fspath(path)!r} does not exist; {_RECOVERY_HINT}")
    try:
        state = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as error:  # any failure to unpickle means the file cannot be used
        raise UserError(
            f"checkpoint {os.fspath(path)!r} is corrupt or not a trainer checkpoint "
            f"({type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}); {_RECOVERY_HINT}"
        ) from error
    if not isinstance(state, dict):
        raise UserError(
            f"checkpoint {os.fspath(path)!r} does not hold a dict of state dicts; {_RECOVERY_HINT}"
        )
    return state
