"""A driver's claim on its endpoint: the cross-process lock of :mod:`gonio.locks`, and the
in-process lock that serialises transactions on one bus.

The file lock is taken in ``connect()`` and given back in ``close()``, so a second program
opening the same serial port, ``socket://`` URL or Modbus TCP endpoint is refused with
:class:`gonio.hal.DeviceInUse` naming the owner, instead of interleaving its packets with the
owner's (which is how a daemon's scan ended up with wrong readings and a manual stage move with
a "mechanical obstruction").
"""

from __future__ import annotations

import threading

from gonio.hal import DeviceInUse
from gonio.locks import FileLock, LockBusy, endpoint_lock


def claim(device: str, endpoint: str) -> FileLock:
    """The held lock of ``endpoint`` for ``device``.

    Raises
    ------
    DeviceInUse
        Another process owns the endpoint.
    """
    try:
        return endpoint_lock(endpoint).acquire()
    except LockBusy as exc:
        raise DeviceInUse(device, str(exc)) from None
    except OSError as exc:
        # No lock directory we can write: say so rather than run unprotected silently.
        raise DeviceInUse(
            device, f"cannot take the lock of {endpoint} ({exc}); set GONIO_LOCK_DIR to a "
            "directory every gonio program on this machine can write"
        ) from None


_BUS_LOCKS: dict[str, threading.Lock] = {}
_BUS_LOCKS_GUARD = threading.Lock()


def bus_lock(endpoint: str) -> threading.Lock:
    """The one thread lock of ``endpoint`` (a serial port or URL) in this process.

    Every driver instance on the same bus (several servos on one U2D2, several axes of one
    Zaber chain) shares it, so their request/reply transactions never interleave; a driver
    holds it for one whole transaction.
    """
    with _BUS_LOCKS_GUARD:
        return _BUS_LOCKS.setdefault(endpoint, threading.Lock())
