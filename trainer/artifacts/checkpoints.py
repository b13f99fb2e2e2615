"""checkpoint.pt files: atomic saves, a format version and a checksum, safe (weights_only) loads.

A checkpoint holds only tensors, numbers, strings, dicts and lists, so it loads with
``torch.load(weights_only=True)``, which refuses any pickle that would run code.

Each file is an ordinary ``torch.save`` archive (torch and ML-Agents' tools read it as is) with
one extra entry, ``Format``: ``{"version": FORMAT_VERSION, "sha256": <32 uint8>}``. The digest
covers the content, not the bytes of the archive: every key path, type, dtype, shape and tensor
byte of the rest of the state, in sorted order (``content_digest``). A bit flipped in a tensor,
a truncated file or a file from another program gives a ``CheckpointError`` naming the file.
A file without ``Format`` (written by ML-Agents, or before checksums) loads with a warning; a
newer ``version`` than ours is refused. docs/reliability.md lists what was tried.
"""
from __future__ import annotations

import hashlib
import io
import logging
import os
import pickle
from typing import Any

import torch

from trainer.artifacts.atomic import atomic_write
from trainer.errors import UserError

logger = logging.getLogger("mlagents_like")

_RECOVERY_HINT = "use --force to start over, or a different --run-id"
FORMAT_KEY = "Format"
FORMAT_VERSION = 1


class CheckpointError(UserError):
    """A checkpoint file that is missing, corrupt, truncated, or not one of ours. ``problem`` is
    the message without the advice (--resume names it and goes on to an older checkpoint)."""

    def __init__(self, problem: str) -> None:
        self.problem = problem
        super().__init__(f"{problem}; {_RECOVERY_HINT}")


def content_digest(state: Any) -> bytes:
    """SHA-256 over the content of ``state``: nested dicts (sorted keys), lists, tensors and scalars."""
    digest = hashlib.sha256()

    def feed(path: str, value: Any) -> None:
        if isinstance(value, dict):
            digest.update(f"{path}:dict:{len(value)};".encode())
            for key in sorted(value, key=lambda k: (type(k).__name__, str(k))):
                feed(f"{path}/{key!r}", value[key])
        elif isinstance(value, (list, tuple)):
            digest.update(f"{path}:{type(value).__name__}:{len(value)};".encode())
            for i, item in enumerate(value):
                feed(f"{path}[{i}]", item)
        elif isinstance(value, torch.Tensor):
            t = value.detach().cpu().contiguous()
            digest.update(f"{path}:tensor:{t.dtype}:{tuple(t.shape)};".encode())
            digest.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
        else:
            digest.update(f"{path}:{type(value).__name__}:{value!r};".encode())

    feed("", state)
    return digest.digest()


def save_checkpoint(path: str | os.PathLike[str], state: dict[str, Any]) -> None:
    """torch.save ``state`` plus its ``Format`` entry to a temp file beside ``path``, fsync it,
    then os.replace onto ``path``. A failure at any point leaves an existing file untouched."""
    body = {k: v for k, v in state.items() if k != FORMAT_KEY}
    stamped = dict(body)
    stamped[FORMAT_KEY] = {
        "version": torch.tensor(FORMAT_VERSION, dtype=torch.int64),
        "sha256": torch.tensor(list(content_digest(body)), dtype=torch.uint8),
    }
    # serialized in memory first: a failed write then raises the OSError itself (torch's zip writer
    # would turn it into a RuntimeError), which atomic_write reports as a full disk or a bad folder
    buffer = io.BytesIO()
    torch.save(stamped, buffer)
    atomic_write(path, lambda f: f.write(buffer.getbuffer()))


def load_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Load a checkpoint onto the CPU, refusing anything but plain tensors and containers, and
    verify its checksum. Returns the state without the ``Format`` entry."""
    name = os.fspath(path)
    if not os.path.isfile(name):
        raise CheckpointError(f"checkpoint {name!r} does not exist")
    try:
        state = torch.load(name, weights_only=True, map_location="cpu")
    except Exception as error:  # any failure to unpickle means the file cannot be used
        if isinstance(error, pickle.UnpicklingError):  # torch's text would suggest weights_only=False
            reason = "it holds objects other than tensors and containers, refused unread"
        else:
            reason = str(error).splitlines()[0] if str(error) else ""
        raise CheckpointError(
            f"checkpoint {name!r} is corrupt, truncated or not a trainer checkpoint "
            f"({type(error).__name__}: {reason})"
        ) from error
    if not isinstance(state, dict):
        raise CheckpointError(f"checkpoint {name!r} does not hold a dict of state dicts")
    stamp = state.pop(FORMAT_KEY, None)
    if stamp is None:
        logger.warning("Checkpoint %s has no format version or checksum (written by ML-Agents or an older "
                       "mlagents-like); loading it unverified.", name)
        return state
    try:
        version = int(stamp["version"])
        expected = bytes(stamp["sha256"].tolist())
    except (KeyError, TypeError, ValueError, AttributeError, RuntimeError) as error:
        raise CheckpointError(f"checkpoint {name!r} has a malformed {FORMAT_KEY!r} entry ({error})") from None
    if version > FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {name!r} has format version {version}, newer than this trainer's "
            f"{FORMAT_VERSION}; load it with the mlagents-like version that wrote it instead"
        )
    if content_digest(state) != expected:
        raise CheckpointError(
            f"checkpoint {name!r} fails its checksum: its content was changed or damaged after it was "
            f"written"
        )
    return state


def checkpoint_step(state: dict[str, Any]) -> int:
    """The trainer step a loaded checkpoint was written at (-1 if it does not say)."""
    try:
        return int(state["global_step"]["step"])
    except (KeyError, TypeError, ValueError, RuntimeError):
        return -1
