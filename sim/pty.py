"""Raw-mode pseudo-terminal transport for serial-device simulators.

The simulator holds the master side; a driver opens the slave path (``/dev/pts/N``) exactly as
it would open ``/dev/ttyUSB0``. The slave is put in raw mode (no echo, no CR/LF translation, no
line buffering, no signals): a cooked terminal would echo binary Dynamixel packets back to the
SDK and turn Zaber's ``\\r`` into ``\\n``. A reader thread hands every chunk of bytes to a
handler and writes back whatever the handler returns.

POSIX only (Linux, macOS), like the pseudo-terminals themselves.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty
from collections.abc import Callable

Handler = Callable[[bytes], bytes]
"""Takes received bytes, returns the bytes to send back (possibly empty)."""


class PtyTransport:
    """A pseudo-terminal whose slave path a serial driver can open.

    Parameters
    ----------
    handler : callable
        Called from the reader thread with each received chunk; its return value is written
        back to the driver.
    name : str
        Thread name, for debugging.
    """

    def __init__(self, handler: Handler, name: str = "gonio-sim-pty") -> None:
        self._handler = handler
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        # Keep the slave open ourselves: when the driver closes and reopens the port, the
        # master must not see a hang-up (EIO) in between.
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._write_lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.05)
            except (OSError, ValueError):
                return  # closed under us
            if not ready:
                continue
            try:
                data = os.read(self._master, 4096)
            except OSError:
                continue  # transient hang-up while the driver reopens the port
            if not data:
                continue
            reply = self._handler(data)
            if reply:
                self.write(reply)

    def write(self, data: bytes) -> None:
        """Send bytes to the driver (thread-safe)."""
        with self._write_lock:
            view = memoryview(data)
            while view:
                n = os.write(self._master, view)
                view = view[n:]

    def close(self) -> None:
        """Stop the reader thread and release the terminal; safe to call twice."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
