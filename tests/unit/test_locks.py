"""gonio.locks: exclusive ownership by flock, naming the holder, never blocked by stale files."""

from __future__ import annotations

import fcntl
import json
import os
import stat
from pathlib import Path

import pytest

from gonio.locks import (
    FileLock,
    LockBusy,
    claim_endpoints,
    claim_store,
    endpoint_key,
    endpoint_lock,
)


def _foreign_holder(path: Path, record: dict[str, object]) -> int:
    """Hold ``path`` the way another process would: its own open file and flock."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.write(fd, json.dumps(record).encode())
    return fd


def test_a_held_lock_is_refused_naming_the_holder(tmp_path: Path) -> None:
    path = tmp_path / "gonio.sqlite.lock"
    fd = _foreign_holder(path, {"pid": 4242, "host": "labpc", "program": "gonio serve",
                                "since": 0.0})
    try:
        with pytest.raises(LockBusy) as info:
            claim_store(tmp_path / "gonio.sqlite", "data directory /x")
        msg = str(info.value)
        assert "data directory /x is in use by gonio serve (pid 4242 on labpc, since " \
               "1970-01-01 00:00:00 UTC)" in msg
        assert info.value.holder["pid"] == 4242
    finally:
        os.close(fd)  # the holder goes away...
    lock = claim_store(tmp_path / "gonio.sqlite")  # ...and the lock is free at once
    try:
        record = json.loads(path.read_text())
        assert record["pid"] == os.getpid()
    finally:
        lock.release()
    assert path.read_text() == ""  # released: the file no longer names this process


def test_a_stale_lock_file_does_not_block(tmp_path: Path) -> None:
    # A lock file left by a process that died (kill -9): it names a holder, but nobody holds
    # the flock, so it must not matter.
    path = tmp_path / "db.sqlite.lock"
    path.write_text(json.dumps({"pid": 999999, "host": "gone", "program": "gonio scan"}))
    lock = claim_store(tmp_path / "db.sqlite")
    assert lock.held
    lock.release()
    assert not lock.held


def test_locks_are_reentrant_within_a_process(tmp_path: Path) -> None:
    a = FileLock(tmp_path / "x.lock", "x").acquire()
    b = FileLock(tmp_path / "x.lock", "x").acquire()  # the same process: counted, not refused
    a.release()
    fd = os.open(tmp_path / "x.lock", os.O_RDONLY)
    try:
        with pytest.raises(BlockingIOError):  # still held for b
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        b.release()
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # now free
    finally:
        os.close(fd)


def test_endpoint_keys_name_one_device_once(tmp_path: Path) -> None:
    target = tmp_path / "ttyUSB0"
    target.write_text("")
    link = tmp_path / "gonio-zaber"
    link.symlink_to(target)
    assert endpoint_key(str(link)) == endpoint_key(str(target))
    assert endpoint_key("socket://10.0.0.5:55550") == endpoint_key("tcp://10.0.0.5:55550")
    assert endpoint_key("tcp://10.0.0.5:502") != endpoint_key("tcp://10.0.0.5:503")
    assert "/" not in endpoint_key("/dev/pts/7")


def test_a_pty_is_one_endpoint_under_every_name_and_is_refused_through_another(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two jobs must not open one serial device through two names: a real pty, named by its
    /dev/pts path, a symlink to it, /dev/fd/N and a second device node of it (mknod, as a
    container's own /dev or a hand-made node has), shares one lock; another pty does not."""
    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path / "locks"))
    (tmp_path / "locks").mkdir()
    master, slave = os.openpty()
    other_master, other_slave = os.openpty()
    try:
        name = os.ttyname(slave)
        link = tmp_path / "gonio-stage"
        link.symlink_to(name)
        names = [str(link), f"/dev/fd/{slave}"]
        node = tmp_path / "ttyStage"
        try:
            os.mknod(node, stat.S_IFCHR | 0o600, os.stat(name).st_rdev)
            names.append(str(node))
        except PermissionError:
            pass  # no CAP_MKNOD here: the other names still are checked
        assert {endpoint_key(n) for n in names} == {endpoint_key(name)}, names
        assert endpoint_key(os.ttyname(other_slave)) != endpoint_key(name)
        for alias in names:
            held = claim_endpoints([alias])  # this process, through one name...
            try:
                fd = os.open(endpoint_lock(name).path, os.O_RDONLY)
                try:  # ...is what another process meets through the device's own name
                    with pytest.raises(BlockingIOError):
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                finally:
                    os.close(fd)
            finally:
                held.release()
        fd = _foreign_holder(tmp_path / "locks" / f"gonio-{endpoint_key(name)}.lock",
                             {"pid": 4242, "host": "labpc", "program": "gonio serve"})
        try:
            for alias in names:
                with pytest.raises(LockBusy, match=f"{alias} is in use by gonio serve"):
                    claim_endpoints([alias])
        finally:
            os.close(fd)
    finally:
        for fd in (master, slave, other_master, other_slave):
            os.close(fd)


@pytest.mark.parametrize("spelling", ["tcp://localhost:1502", "socket://LOCALHOST:1502",
                                      "tcp://127.0.0.1:1502", "tcp://127.0.1.1:1502",
                                      "tcp://[::1]:1502"])
def test_every_loopback_spelling_is_one_endpoint(spelling: str) -> None:
    # RFC 5735 / RFC 4291: 127.0.0.0/8 and ::1 are this host; "localhost" names it (RFC 6761).
    assert endpoint_key(spelling) == endpoint_key("tcp://127.0.0.1:1502")
    assert endpoint_key(spelling) != endpoint_key("tcp://127.0.0.1:1503")
    assert endpoint_key(spelling) != endpoint_key("tcp://10.0.0.5:1502")


def test_a_rig_claimed_as_localhost_is_refused_as_127_0_0_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path))
    held = tmp_path / f"gonio-{endpoint_key('tcp://localhost:1502')}.lock"
    fd = _foreign_holder(held, {"pid": 7, "host": "h", "program": "gonio serve", "since": 0})
    try:
        with pytest.raises(LockBusy, match=r"tcp://127.0.0.1:1502 is in use by gonio serve"):
            claim_endpoints(["tcp://127.0.0.1:1502"])
    finally:
        os.close(fd)


def test_claiming_a_rig_is_all_or_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path))
    busy = tmp_path / f"gonio-{endpoint_key('tcp://127.0.0.1:1502')}.lock"
    fd = _foreign_holder(busy, {"pid": 7, "host": "h", "program": "gonio scan", "since": 0})
    try:
        with pytest.raises(LockBusy, match=r"tcp://127.0.0.1:1502 is in use by gonio scan"):
            claim_endpoints(["/dev/pts/99", "tcp://127.0.0.1:1502"])
        # The first endpoint was given back when the second was refused: another process
        # (played by a foreign flock) can take it.
        first = tmp_path / f"gonio-{endpoint_key('/dev/pts/99')}.lock"
        fd2 = _foreign_holder(first, {})
        os.close(fd2)
    finally:
        os.close(fd)


def test_the_lock_directory_is_shared_unless_overridden(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gonio.locks import lock_dir

    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path))
    assert lock_dir() == tmp_path
    monkeypatch.delenv("GONIO_LOCK_DIR")
    run_lock = Path("/run/lock")
    if run_lock.is_dir() and os.access(run_lock, os.W_OK):
        assert lock_dir() == run_lock  # what every user's gonio agrees on
