"""The file-backed maintenance lock: set, read, cleared, and failing closed."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from gonio.maintenance import LOCK_FILE_NAME, LockState, MaintenanceLock


def test_unlocked_without_the_file(tmp_path: Path) -> None:
    lock = MaintenanceLock(tmp_path / LOCK_FILE_NAME)
    assert lock.state() == LockState(False)
    assert lock.reason() is None


def test_lock_writes_json_and_unlock_removes_the_file(tmp_path: Path) -> None:
    path = tmp_path / "sub" / LOCK_FILE_NAME  # the data directory may not exist yet
    lock = MaintenanceLock(path)
    before = time.time()
    st = lock.lock("replacing the lamp", "tech")
    assert st.locked and st.reason == "replacing the lamp" and st.by == "tech"
    assert st.since is not None and before - 1 <= st.since <= time.time() + 1
    data = json.loads(path.read_text())
    assert data["reason"] == "replacing the lamp" and data["by"] == "tech"
    assert lock.reason() == "maintenance lock: replacing the lamp"
    assert not path.with_suffix(".tmp").exists()
    assert lock.unlock() == LockState(False)
    assert not path.exists()
    assert lock.unlock() == LockState(False)  # unlocking twice is harmless


def test_a_lock_without_a_reason(tmp_path: Path) -> None:
    lock = MaintenanceLock(tmp_path / LOCK_FILE_NAME)
    lock.lock("", None)
    assert lock.state().by is None
    assert lock.reason() == "maintenance lock"


def test_an_empty_file_from_a_shell_locks_with_its_mtime(tmp_path: Path) -> None:
    path = tmp_path / LOCK_FILE_NAME
    path.touch()
    os.utime(path, (1_000_000.0, 1_000_000.0))
    assert MaintenanceLock(path).state() == LockState(True, "", None, 1_000_000.0)


@pytest.mark.parametrize(("text", "reason"), [
    ("welding the arm\n", "welding the arm"),  # hand-written text is the reason
    ("[1, 2]", "[1, 2]"),  # JSON but not an object
    ('{"reason": "x", "by": 7, "since": "yesterday"}', "x"),
])
def test_hand_written_content_is_read_as_the_reason(tmp_path: Path, text: str,
                                                    reason: str) -> None:
    path = tmp_path / LOCK_FILE_NAME
    path.write_text(text)
    st = MaintenanceLock(path).state()
    assert st.locked and st.reason == reason
    assert st.since == path.stat().st_mtime  # no usable "since": the file's own time


def test_a_non_numeric_since_falls_back_to_the_file_time(tmp_path: Path) -> None:
    path = tmp_path / LOCK_FILE_NAME
    path.write_text('{"reason": "x", "by": 7, "since": "yesterday"}')
    os.utime(path, (2_000_000.0, 2_000_000.0))
    assert MaintenanceLock(path).state() == LockState(True, "x", "7", 2_000_000.0)


def test_an_unreadable_lock_file_fails_closed(tmp_path: Path) -> None:
    path = tmp_path / LOCK_FILE_NAME
    path.mkdir()  # reading a directory raises an OSError other than FileNotFoundError
    st = MaintenanceLock(path).state()
    assert st.locked
    assert "is unreadable" in st.reason and str(path) in st.reason
