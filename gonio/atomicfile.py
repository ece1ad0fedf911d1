"""Files written whole or not at all: a temporary file beside the target, then a rename.

A reader (the daemon serving a result, a renderer opening an export, the next start reading
``calibration.json``) sees either the old file or the new one, never a torn one; a write that
fails (a full disk) leaves no temporary file behind to hold the space.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path


def write_atomically(path: str | os.PathLike[str], data: bytes | str, *,
                     sync_dir: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically and durably.

    Parameters
    ----------
    path : the file to write (its folder must exist)
    data : the whole content; ``str`` is written as UTF-8
    sync_dir : also flush the folder, so the rename itself survives a power cut (for state
        files the next start reads, such as the calibration in effect)

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OSError
        The file could not be written (``errno.ENOSPC`` on a full disk); ``path`` is as it was
        and no temporary file is left. Its ``filename`` is ``path``, not the temporary's.
    """
    out = Path(path)
    # One temporary name per writer: two writers of the same file never share one.
    tmp = out.with_name(f"{out.name}.{uuid.uuid4().hex[:12]}.part")
    payload = data.encode("utf-8") if isinstance(data, str) else data
    try:
        with open(tmp, "wb") as fh:
            fh.write(payload)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, out)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and exc.filename in (str(tmp), tmp):
            # The caller named ``out``; an error naming the temporary ("x.gltf.3f2a9c.part:
            # Permission denied") names a file nobody asked for.
            exc.filename, exc.filename2 = str(out), None
        raise
    if sync_dir:
        with contextlib.suppress(OSError):  # not every file system lets a folder be synced
            fd = os.open(out.parent, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    return out
