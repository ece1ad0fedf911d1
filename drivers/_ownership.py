"""A driver's claim on its endpoint: the process-wide lock of :mod:`gonio.locks`.

Taken in ``connect()`` and given back in ``close()``, so a second program opening the same
serial port, ``socket://`` URL or Modbus TCP endpoint is refused with
:class:`gonio.hal.DeviceInUse` naming the owner, instead of interleaving its packets with the
owner's (which is how a daemon's scan ended up with wrong readings and a manual stage move with
a "mechanical obstruction").
"""

from __future__ import annotations

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
