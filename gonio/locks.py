"""One owner at a time: OS locks on a data directory's job store and on a rig's device endpoints.

Each lock is ``flock(2)`` on a small lock file, held for as long as the owning process keeps it
(usually its whole life). The kernel drops the lock when the process ends, however it ends
(``kill -9`` and power loss included), so a lock file left behind by a dead process never blocks
anyone: only a live holder does. The file's content names the holder (pid, host, program, since
when) so a refusal can say who to ask; the content is informative, the ``flock`` is the truth.

Two kinds of lock:

* the **job store** of a data directory (``<store>.lock`` beside the SQLite file): the daemon
  and ``gonio scan`` take it, so two programs never run jobs from one store;
* every **device endpoint** of a rig (a serial port, a ``socket://`` URL, a Modbus TCP
  ``host:port``): lock files named after the endpoint in a lock directory shared by every user
  of the machine (``$GONIO_LOCK_DIR``, else ``/run/lock``, else the temporary directory). The
  daemon takes them all at start-up; the stage and Modbus drivers take theirs when they connect,
  so ``gonio stage`` or ``gonio scan`` on a rig the daemon owns is refused, naming the daemon.

Within one process a lock is re-entrant (counted): the daemon's rig claim and its drivers' own
claims on the same endpoints do not conflict. ``flock`` is advisory: it keeps out programs that
ask for it (every gonio program, and pyserial with ``exclusive=True``), not others.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import ipaddress
import json
import os
import re
import socket
import stat
import sys
import tempfile
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = [
    "LOCK_DIR_ENV",
    "FileLock",
    "LockBusy",
    "claim_endpoints",
    "claim_store",
    "endpoint_lock",
    "lock_dir",
]

LOCK_DIR_ENV = "GONIO_LOCK_DIR"
"""Environment variable naming the directory for device-endpoint lock files."""

_SHARED_LOCK_DIR = Path("/run/lock")


class LockBusy(RuntimeError):
    """Another process holds the lock; the message names it and says what to do.

    Attributes
    ----------
    what : str
        What is locked, in words ("data directory /var/lib/gonio", "/dev/ttyUSB0").
    holder : dict
        The holder's record (``pid``, ``host``, ``program``, ``since``), possibly empty when the
        lock file cannot be read.
    """

    def __init__(self, what: str, holder: dict[str, Any], advice: str) -> None:
        self.what = what
        self.holder = holder
        # A daemon records the address it serves (:func:`advertise_url`): the advice names it
        # instead of a placeholder, so the command it suggests works as printed.
        url = holder.get("url")
        if isinstance(url, str) and url:
            advice = advice.replace("--daemon URL", f"--daemon {url.rstrip('/')}")
        super().__init__(f"{what} is in use by {describe_holder(holder)}; {advice}")


def describe_holder(holder: dict[str, Any]) -> str:
    """``"gonio serve (pid 4242 on labpc, since 2026-11-23 01:02:03 UTC)"``, or a fallback."""
    if not holder:
        return "another process (its lock file names no holder)"
    since = holder.get("since")
    when = (time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(float(since)))
            if isinstance(since, int | float) else "unknown time")
    url = holder.get("url")
    at = f", serving {url}" if isinstance(url, str) and url else ""
    return (f"{holder.get('program', 'a program')} (pid {holder.get('pid', '?')} on "
            f"{holder.get('host', '?')}, since {when}{at})")


def lock_dir() -> Path:
    """Where device-endpoint lock files live: one directory every user of the machine shares.

    ``$GONIO_LOCK_DIR`` if set; else ``/run/lock`` (the FHS place for device locks, world
    writable) when it is writable; else the temporary directory. Programs must agree on it to
    see each other: a systemd unit with ``PrivateTmp=yes`` must use ``/run/lock`` (and list it
    in ``ReadWritePaths=``).
    """
    env = os.environ.get(LOCK_DIR_ENV)
    if env:
        return Path(env)
    if _SHARED_LOCK_DIR.is_dir() and os.access(_SHARED_LOCK_DIR, os.W_OK | os.X_OK):
        return _SHARED_LOCK_DIR
    return Path(tempfile.gettempdir())


def canonical_host(host: str) -> str:
    """One name per network host, so two spellings of one device server share a lock.

    Every loopback spelling (``localhost``, ``127.0.0.1``, ``127.0.1.1``, ``::1``) becomes
    ``loopback``; an IP address its compressed form; a host name the sorted first address it
    resolves to (the drivers resolve the same name when they connect), or the name in lower case
    when it does not resolve.
    """
    name = host.strip().strip("[]").lower()
    if name == "localhost" or name.endswith(".localhost"):
        return "loopback"
    try:
        address = ipaddress.ip_address(name)
    except ValueError:
        try:
            infos = socket.getaddrinfo(name, None, proto=socket.IPPROTO_TCP)
        except (OSError, UnicodeError):
            return name
        addresses = sorted({str(info[4][0]) for info in infos})
        if not addresses:
            return name
        address = ipaddress.ip_address(addresses[0].split("%")[0])
    if address.is_loopback:
        return "loopback"
    return address.compressed


def endpoint_key(endpoint: str) -> str:
    """A file-name-safe key for a device endpoint; two names of one device share it.

    A path that is a device node is keyed by the device itself (character or block, major and
    minor number: its ``st_rdev``), not by a name: ``/dev/gonio-zaber`` (a udev symlink),
    ``/dev/serial/by-id/...``, ``/dev/fd/N``, a second node made with ``mknod`` (a container's
    own ``/dev``) and ``/dev/ttyUSB0`` are one device. Another path (a device not plugged in
    yet, a file) is keyed by its real path (symlinks resolved). ``socket://host:port`` and a
    Modbus ``tcp://host:port`` are the same TCP endpoint, and so are ``tcp://localhost:502``
    and ``tcp://127.0.0.1:502`` (:func:`canonical_host`).
    """
    text = endpoint.strip()
    m = re.match(r"^(?:socket|tcp|rfc2217)://(\[[^]]+\]|[^/?#:]*)(?::(\d+))?", text)
    if m:
        text = f"tcp-{canonical_host(m.group(1))}-{m.group(2) or ''}"
    elif text.startswith("/"):
        text = os.path.realpath(text)
        device = _device_identity(text)
        if device is not None:
            return device
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-") or "endpoint"


def _device_identity(path: str) -> str | None:
    """``chr-MAJOR-MINOR`` (or ``blk-...``) of the device node at ``path``; None when it is
    not one or cannot be looked at."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    if stat.S_ISCHR(st.st_mode):
        kind = "chr"
    elif stat.S_ISBLK(st.st_mode):
        kind = "blk"
    else:
        return None
    return f"{kind}-{os.major(st.st_rdev)}-{os.minor(st.st_rdev)}"


RIG_ADVICE = ("one program drives a rig at a time; stop that process, or act through its API "
              "(gonio stage/scan --daemon URL)")


def endpoint_lock(endpoint: str) -> FileLock:
    """The (not yet acquired) lock of one device endpoint."""
    return FileLock(lock_dir() / f"gonio-{endpoint_key(endpoint)}.lock", endpoint, RIG_ADVICE)


# --------------------------------------------------------------------------- the lock
_HELD: dict[str, tuple[int, int]] = {}
"""Locks this process holds: real path -> (fd, count). Re-entrant within the process."""
_HELD_GUARD = threading.Lock()
_URL: str | None = None
"""The address this process serves its API on, once it listens (:func:`advertise_url`)."""


def advertise_url(url: str) -> None:
    """Record ``url`` (this daemon's API address) in every lock this process holds and takes
    from now on, so a program refused by one of them is told the real address to act through
    (``gonio stage --daemon URL``), not a default port."""
    global _URL
    _URL = url
    with _HELD_GUARD:
        for fd, _count in _HELD.values():
            record = _read_holder(fd)
            if record.get("pid") != os.getpid():
                continue  # opened read-only: not ours to rewrite
            record["url"] = url
            with contextlib.suppress(OSError):
                data = json.dumps(record).encode("utf-8")
                os.ftruncate(fd, 0)
                os.pwrite(fd, data, 0)


def _program() -> str:
    argv = [os.path.basename(sys.argv[0]) if sys.argv else "python", *sys.argv[1:3]]
    return " ".join(a for a in argv if a) or "python"


def _read_holder(fd: int) -> dict[str, Any]:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = os.read(fd, 4096)
        holder = json.loads(data.decode("utf-8")) if data.strip() else {}
    except (OSError, ValueError):
        return {}
    return holder if isinstance(holder, dict) else {}


class FileLock:
    """An exclusive ``flock`` on ``path`` for this process, naming its holder in the file.

    Parameters
    ----------
    path : Path
        The lock file (created if missing, never deleted: deleting a lock file while another
        process waits on it would let two processes "hold" two different files).
    what : str
        What the lock protects, in words, for messages.
    advice : str
        What to tell someone who finds it held.
    """

    def __init__(self, path: Path, what: str,
                 advice: str = "stop that process first, or act through it") -> None:
        self.path = Path(path)
        self.what = what
        self.advice = advice
        self._key: str | None = None

    @property
    def held(self) -> bool:
        return self._key is not None

    def _open(self) -> tuple[int, bool]:
        """(fd, writable). Opens an existing file without O_CREAT first: in a sticky world-
        writable directory (``/run/lock``) the kernel refuses O_CREAT on another user's file."""
        for flags in (os.O_RDWR, os.O_RDONLY):
            try:
                return os.open(self.path, flags | os.O_CLOEXEC), flags == os.O_RDWR
            except FileNotFoundError:
                break
            except PermissionError:
                continue
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
        except FileExistsError:  # another process created it meanwhile
            return os.open(self.path, os.O_RDONLY | os.O_CLOEXEC), False
        with contextlib.suppress(OSError):
            os.fchmod(fd, 0o644)  # readable by every user despite a restrictive umask
        return fd, True

    def acquire(self) -> FileLock:
        """Take the lock (without waiting); returns self.

        Raises
        ------
        LockBusy
            Another process holds it; the message names that process.
        OSError
            The lock file cannot be created (e.g. no write access to its directory).
        """
        if self._key is not None:
            return self
        key = os.path.realpath(self.path)
        with _HELD_GUARD:
            if key in _HELD:
                fd, count = _HELD[key]
                _HELD[key] = (fd, count + 1)
                self._key = key
                return self
            fd, writable = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = _read_holder(fd)
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise LockBusy(self.what, holder, self.advice) from None
                raise
            if writable:
                record = {"pid": os.getpid(), "host": socket.gethostname(),
                          "program": _program(), "since": time.time(), "what": self.what}
                if _URL is not None:
                    record["url"] = _URL
                with contextlib.suppress(OSError):
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, json.dumps(record).encode("utf-8"), 0)
            _HELD[key] = (fd, 1)
            self._key = key
        return self

    def release(self) -> None:
        """Give the lock up (the last holder in this process unlocks the file); idempotent."""
        key, self._key = self._key, None
        if key is None:
            return
        with _HELD_GUARD:
            fd, count = _HELD.get(key, (-1, 0))
            if count > 1:
                _HELD[key] = (fd, count - 1)
                return
            _HELD.pop(key, None)
        if fd >= 0:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)  # a stale record must not name a process that let go
            with contextlib.suppress(OSError):
                os.close(fd)  # closing the last descriptor drops the flock

    def holder(self) -> dict[str, Any]:
        """The record in the lock file (who holds or last held it); {} when unreadable."""
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC)
        except OSError:
            return {}
        try:
            return _read_holder(fd)
        finally:
            os.close(fd)

    def __enter__(self) -> FileLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


class LockSet:
    """Several locks taken together: all or none. Release with :meth:`release`."""

    def __init__(self, locks: Iterable[FileLock]) -> None:
        self.locks = list(locks)

    def acquire(self) -> LockSet:
        done: list[FileLock] = []
        try:
            for lock in self.locks:
                done.append(lock.acquire())
        except BaseException:
            for lock in reversed(done):
                lock.release()
            raise
        return self

    def release(self) -> None:
        for lock in reversed(self.locks):
            lock.release()

    def __enter__(self) -> LockSet:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


STORE_ELSEWHERE = "another data directory (--data-dir) or job store (--db)"
"""Where a ``gonio scan`` or ``gonio jobs`` refused a busy store can go instead."""

DATA_DIR_ELSEWHERE = (
    "another data directory (--data-dir, or [paths] data_dir in the daemon config)")
"""Where a daemon refused a busy data directory can go instead (``gonio serve`` has no
``--db``: its store is always the data directory's)."""


def claim_store(store_path: str | os.PathLike[str], what: str | None = None,
                elsewhere: str = STORE_ELSEWHERE) -> FileLock:
    """Take the job store's lock (``<store>.lock``) for this process; returns it (held).

    Parameters
    ----------
    store_path : the SQLite file of the job store
    what : how to name it in a refusal (default: "job store <path>")
    elsewhere : the refusal's advice on where this process can keep its jobs instead, in the
        caller's own options (:data:`STORE_ELSEWHERE`, :data:`DATA_DIR_ELSEWHERE`)

    Raises
    ------
    LockBusy
        Another process (a daemon, a ``gonio scan``) runs jobs from this store.
    """
    path = Path(store_path).resolve()
    return FileLock(
        path.with_name(path.name + ".lock"), what or f"job store {path}",
        advice="two programs must not run jobs from one store; stop that process, use its "
               f"API, or give this one {elsewhere}",
    ).acquire()


def claim_endpoints(endpoints: Iterable[str]) -> LockSet:
    """Take the locks of a rig's device endpoints, all or none; returns them (held).

    Raises
    ------
    LockBusy
        Another process owns one of them (the message names which and who).
    """
    # One lock per endpoint, in a stable order.
    return LockSet(endpoint_lock(ep) for ep in dict.fromkeys(endpoints)).acquire()
