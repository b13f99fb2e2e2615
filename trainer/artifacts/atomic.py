"""Write a file so that readers (and a crash at any moment) see the old content or the new, never half.

The content goes to a temp file in the target's folder, is flushed and fsynced, then renamed over
the target with os.replace (atomic on POSIX and Windows); the folder is fsynced so the rename
survives a power cut where the platform allows. On any failure the temp file is removed and an
existing target is left untouched.

The file gets the mode any ``open(path, "w")`` would give it, 0o666 less the process umask (mkstemp
alone makes it 0o600), so results are shared or private as the user's umask says and never more
open than that (docs/reliability.md).
"""
from __future__ import annotations

import errno
import os
import shutil
import tempfile
from typing import IO, Callable

from trainer import crash_points
from trainer.errors import ResultsWriteError

# what a folder the user cannot write, or a full disk, raises: the run stops with one message
WRITE_ERRNOS = frozenset(getattr(errno, name) for name in
                         ("EACCES", "EPERM", "EROFS", "ENOSPC", "EFBIG", "EDQUOT", "ENOTDIR") if hasattr(errno, name))


def results_write_error(path: str | os.PathLike[str], error: OSError) -> ResultsWriteError:
    """The one message for an ``OSError`` of ``WRITE_ERRNOS`` while writing ``path``."""
    name = errno.errorcode.get(error.errno or 0, "")
    reason = f"{error.strerror or error}" + (f" [{name}]" if name else "")
    hints = {errno.ENOSPC: "free some disk space", errno.EFBIG: "raise the file size limit (ulimit -f)"}
    hint = hints.get(error.errno or 0, f"make {os.path.dirname(os.path.abspath(path))} writable")
    return ResultsWriteError(
        f"cannot write {os.fspath(path)}: {reason}. {hint[0].upper() + hint[1:]}, then continue with --resume "
        f"(checkpoints written before are intact), or choose another --results-dir."
    )


def _read_umask() -> int:
    """The process umask, read without changing it where Linux allows (/proc), else set and reset
    once, at import, before any thread of ours creates files."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO], None], binary: bool = True) -> None:
    """Call ``write(file)`` on a temp file beside ``path``, then rename it onto ``path``."""
    path = os.fspath(path)
    try:
        _atomic_write(path, write, binary)
    except OSError as error:
        if error.errno in WRITE_ERRNOS:
            raise results_write_error(path, error) from error
        raise


def _atomic_write(path: str, write: Callable[[IO], None], binary: bool) -> None:
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    handle, tmp_path = tempfile.mkstemp(prefix=f".{os.path.basename(path)}-", suffix=".tmp", dir=folder)
    try:
        if hasattr(os, "fchmod"):
            os.fchmod(handle, 0o666 & ~_UMASK)
        with os.fdopen(handle, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8"})) as tmp:
            write(tmp)
            tmp.flush()
            os.fsync(tmp.fileno())
        crash_points.reached("atomic.replace")
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
