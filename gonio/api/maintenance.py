"""The maintenance lock: while it is set, every change through the API is refused with 423.

A technician working on the rig sets it (through the API, or by creating the lock file in the
daemon's data directory from a shell) so no client starts a scan under their hands. The state
lives in that file, so it survives a daemon restart and the shell and the API agree on it.
Reads, the event stream and releasing the lock itself stay available.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from fastapi import HTTPException, Request, status

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
        tmp.write_text(
            json.dumps({"reason": reason, "by": by, "since": time.time()}), encoding="utf-8"
        )
        tmp.replace(self.path)  # atomic: a concurrent reader sees the old or the new lock
        return self.state()

    def unlock(self) -> LockState:
        self.path.unlink(missing_ok=True)
        return self.state()


async def refuse_while_locked(request: Request) -> None:
    """FastAPI dependency for mutating endpoints: 423 Locked while maintenance is on."""
    lock: MaintenanceLock = request.app.state.maintenance
    st = lock.state()
    if st.locked:
        who = f" by {st.by}" if st.by else ""
        why = f": {st.reason}" if st.reason else ""
        raise HTTPException(
            status.HTTP_423_LOCKED,
            f"the rig is locked for maintenance{who}{why}; changes are refused until the lock "
            "is released (DELETE /api/v1/maintenance, or remove the lock file "
            f"{LOCK_FILE_NAME} in the daemon's data directory)",
        )
