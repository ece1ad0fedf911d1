"""The maintenance lock: while it is set, nothing new starts on the rig, whoever asks.

A technician working on the rig sets it (through the API, or by creating the lock file
``MAINTENANCE`` in the daemon's data directory from a shell). The worker then starts no job and
resumes none (:attr:`gonio.worker.Worker.gate`), and the API refuses every change with 423
(:mod:`gonio.api.maintenance`). The state lives in that file, so it survives a crash or restart
of the daemon (the file is written atomically and flushed to disk) and the shell and the API
agree on it.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

LOCK_FILE_NAME = "MAINTENANCE"


@dataclass(frozen=True)
class LockState:
    """Whether the lock is set, why, by whom (key name) and since when (Unix time, seconds)."""

    locked: bool
    reason: str = ""
    by: str | None = None
    since: float | None = None


class MaintenanceLock:
    """File-backed maintenance lock.

    Parameters
    ----------
    path : Path
        The lock file. It exists exactly while the lock is set; its content (JSON with
        ``reason``, ``by``, ``since``) is informative and may be empty or hand-written text.
    """

    def __init__(self, path: Path) -> None:
        self.path = path

    def state(self) -> LockState:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return LockState(False)
        except OSError as exc:
            # An unreadable lock file still means "locked": failing closed is the safe side.
            return LockState(True, reason=f"lock file {self.path} is unreadable: {exc}")
        try:
            data = json.loads(text) if text.strip() else {}
        except json.JSONDecodeError:
            data = {"reason": text.strip()}
        if not isinstance(data, dict):
            data = {"reason": str(data)}
        since = data.get("since")
        return LockState(
            True,
            reason=str(data.get("reason", "")),
            by=str(data["by"]) if data.get("by") is not None else None,
            since=float(since) if isinstance(since, int | float) else self.path.stat().st_mtime,
        )

    def lock(self, reason: str, by: str | None) -> LockState:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(json.dumps({"reason": reason, "by": by, "since": time.time()}))
            f.flush()
            os.fsync(f.fileno())  # the lock must outlive a power cut, not just a crash
        tmp.replace(self.path)  # atomic: a concurrent reader sees the old or the new lock
        _sync_dir(self.path.parent)
        return self.state()

    def unlock(self) -> LockState:
        self.path.unlink(missing_ok=True)
        _sync_dir(self.path.parent)
        return self.state()

    def reason(self) -> str | None:
        """Why nothing may start (for :attr:`gonio.worker.Worker.gate`), or None if unlocked."""
        st = self.state()
        if not st.locked:
            return None
        return "maintenance lock" + (f": {st.reason}" if st.reason else "")


def _sync_dir(path: Path) -> None:
    """Flush a directory entry change (rename, unlink) to disk where the OS allows it."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
