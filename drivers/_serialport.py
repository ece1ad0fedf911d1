"""A serial port that cannot be opened, said in words.

pyserial's own message repeats the errno: a vanished ``/dev/ttyUSB0`` is
``[Errno 2] could not open port /dev/ttyUSB0: [Errno 2] No such file or directory:
'/dev/ttyUSB0'``, and the drivers put that inside their own sentence, so a lab read the port
three times and the errno twice in one fault. :func:`open_failure` says once what happened,
from the error number; each driver adds what to check.
"""

from __future__ import annotations

import errno
import os


def open_failure(port: str, exc: BaseException) -> str:
    """Why ``port`` could not be opened, in words, naming the port once.

    Parameters
    ----------
    port
        The port or URL as the rig config gives it.
    exc
        What opening it raised (pyserial's ``SerialException`` is an ``OSError`` carrying the
        error number; a URL pyserial cannot read raises ``ValueError``).

    Returns
    -------
    str
        ``"serial port '/dev/ttyUSB0' does not exist (nothing is plugged in under that
        name)"``, and the like for a port without
        permission or busy; other errors by their system text, without ``[Errno N]``.
    """
    code = getattr(exc, "errno", None)
    where = f"serial port {port!r}"
    if code == errno.ENOENT:
        return f"{where} does not exist (nothing is plugged in under that name)"
    if code in (errno.EACCES, errno.EPERM):
        return (f"no permission to open {where} (the user running gonio needs the group "
                "dialout, or the udev rules of docs/install.md)")
    if code == errno.EBUSY:
        return f"{where} is busy (another driver or program has it open)"
    if code in (errno.ENXIO, errno.ENODEV, errno.EIO):
        return (f"{where} has no device behind it any more ({os.strerror(code).lower()}: the "
                "adapter was unplugged or reset)")
    if isinstance(code, int):
        return f"cannot open {where}: {os.strerror(code).lower()}"
    return f"cannot open {port!r}: {exc}"


def lock_refused(port: str) -> str:
    """The message of a port another program holds (an exclusive lock refused)."""
    return (f"serial port {port!r} is held by another program (it could not be locked for "
            "exclusive use); close it (a terminal program, another gonio) and retry")
