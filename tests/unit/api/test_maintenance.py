"""The maintenance lock at the HTTP layer: 423 with who, why and how to release it, nothing
while unlocked. The whole daemon under the lock: tests/system/api/test_guards.py."""

from __future__ import annotations

import asyncio
from pathlib import Path
from types import SimpleNamespace

import pytest
from fastapi import HTTPException
from starlette.requests import Request

from gonio.api.maintenance import LOCK_FILE_NAME, MaintenanceLock, refuse_while_locked


def _request(lock: MaintenanceLock) -> Request:
    app = SimpleNamespace(state=SimpleNamespace(maintenance=lock))
    return Request({"type": "http", "app": app, "headers": []})


def test_nothing_is_refused_while_unlocked(tmp_path: Path) -> None:
    asyncio.run(refuse_while_locked(_request(MaintenanceLock(tmp_path / LOCK_FILE_NAME))))


@pytest.mark.parametrize(("reason", "by", "says"), [
    ("lamp swap", "ana", "the rig is locked for maintenance by ana: lamp swap; changes are "
                        "refused until the lock is released"),
    ("", None, "the rig is locked for maintenance; changes are refused"),
])
def test_a_change_under_the_lock_is_423_saying_who_why_and_how(
        tmp_path: Path, reason: str, by: str | None, says: str) -> None:
    lock = MaintenanceLock(tmp_path / LOCK_FILE_NAME)
    lock.lock(reason, by)
    with pytest.raises(HTTPException) as exc:
        asyncio.run(refuse_while_locked(_request(lock)))
    assert exc.value.status_code == 423
    assert str(exc.value.detail).startswith(says)
    assert "DELETE /api/v1/maintenance" in exc.value.detail
    # The file by its path (it said "in the daemon's data directory", which the user had to
    # find out first).
    assert f"remove the lock file {tmp_path / LOCK_FILE_NAME})" in exc.value.detail
