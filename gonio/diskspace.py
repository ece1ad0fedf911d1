"""A full disk: recognising it, whatever reported it, and saying what to do.

The daemon writes to one data directory through three libraries that each report a full disk
their own way: Python's file I/O (``OSError`` with ``errno`` ``ENOSPC``, or ``EDQUOT`` when a
quota is reached), h5py (an ``OSError`` carrying HDF5's errno) and SQLite
(``sqlite3.OperationalError`` with the extended code ``SQLITE_FULL``, "database or disk is
full"). :func:`is_disk_full` recognises all of them, so the worker, the service and the API
treat a full disk as one condition: a clear message and a job ``failed`` with "disk full",
never a crashed daemon (docs/engine.md, "A full disk").
"""

from __future__ import annotations

import errno
import shutil
import sqlite3
from pathlib import Path

DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
"""``errno`` values of a write refused for lack of space (a full disk, a user's quota)."""

_SQLITE_FULL = 13
"""SQLite's primary result code for a write refused for lack of space (sqlite3.h)."""

FREE_MARGIN_BYTES = 32 * 1024 * 1024
"""Free space on the data directory's file system above which the worker takes jobs again
after a full disk: a reconstructed result file is about 2 MB, its fits and a few exports
fit several times over."""


class DiskFull(OSError):
    """A write refused for lack of space; the message says what was not written and what to
    do. ``errno`` is ``ENOSPC``, so code that handles ``OSError`` handles this too."""

    def __init__(self, message: str) -> None:
        super().__init__(errno.ENOSPC, message)

    def __str__(self) -> str:
        return str(self.strerror)


def is_disk_full(exc: BaseException | None) -> bool:
    """Whether ``exc`` (or an exception it was raised from) reports a full disk."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, sqlite3.Error):
            code = getattr(exc, "sqlite_errorcode", None)
            if code is not None and code & 0xFF == _SQLITE_FULL:
                return True
        elif isinstance(exc, OSError) and exc.errno in DISK_FULL_ERRNOS:
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def disk_full_message(what: str, where: str | Path) -> str:
    """The one wording of a full disk: ``what`` was not written, free space where."""
    return (f"disk full: {what} could not be written; free space on the file system of "
            f"{where} (nothing already stored was lost)")


def free_bytes(path: str | Path) -> int:
    """Free bytes for this user on the file system holding ``path`` (its nearest existing
    parent when ``path`` does not exist yet); 0 when it cannot be asked."""
    p = Path(path)
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return shutil.disk_usage(p).free
    except OSError:
        return 0


def low_space(path: str | Path) -> str | None:
    """Why jobs cannot run on the data directory ``path`` for lack of space (less than
    :data:`FREE_MARGIN_BYTES` free on its file system), or None."""
    free = free_bytes(path)
    if free >= FREE_MARGIN_BYTES:
        return None
    return (f"disk full: {free // 1024} KiB free on the file system of {path}, a job needs "
            f"{FREE_MARGIN_BYTES // 2**20} MiB; free space (nothing already stored was lost)")
