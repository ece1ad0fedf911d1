"""The maintenance lock at the HTTP layer: while it is set, every change is refused with 423.

The lock itself (a file in the daemon's data directory, shared with shells) is
:class:`gonio.maintenance.MaintenanceLock`; the worker honours it too, so nothing new starts on
the rig while it is set. Reads, the event stream, emergency halt and releasing the lock itself
stay available.
"""

from __future__ import annotations

from fastapi import HTTPException, Request, status

from gonio.maintenance import LOCK_FILE_NAME, LockState, MaintenanceLock

__all__ = ["LOCK_FILE_NAME", "LockState", "MaintenanceLock", "refuse_while_locked"]


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
            f"{lock.path})",
        )
