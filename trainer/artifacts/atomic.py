"""Write a file so that readers (and a crash at any moment) see the old content or the new, never half.

The content goes to a temp file in the target's folder, is flushed and fsynced, then renamed over
the target with os.replace (atomic on POSIX and Windows); the folder is fsynced so the rename
survives a power cut where the platform allows. On any failure the temp file is removed and an
existing target is left untouched.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from typing import IO, Callable


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO], None], binary: bool = True) -> None:
    """Call ``write(file)`` on a temp file beside ``path``, then rename it onto ``path``."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    handle, tmp_path = tempfile.mkstemp(prefix=f".{os.path.basename(path)}-", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(handle, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8"})) as tmp:
            write(tmp)
            tmp.flush()
            os.fsync(tmp.fileno())
        os.replace(tmp_path, path)
    except BaseException:
        if os.path.exists(tmp_path):
            os.remove(tmp_path)
        raise
    _fsync_folder(folder)


def atomic_copy(source: str | os.PathLike[str], path: str | os.PathLike[str]) -> None:
    """Copy ``source`` onto ``path`` the same way: readers see the old file or the whole new one."""
    with open(source, "rb") as src:
        atomic_write(path, lambda out: shutil.copyfileobj(src, out))


def _fsync_folder(folder: str) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
