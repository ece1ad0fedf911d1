"""The engine's own event loop, in its own thread, so request handling cannot delay a scan.

The REST API runs on uvicorn's event loop. If the worker (and with it the engine and the device
drivers) ran there too, every request handler that is ready to run would sit between a device's
reply and the engine's next command: fifty clients polling without pause stretched a scan by a
third. Here the worker, the engine, the drivers' connections and every device call live on a
second loop in a dedicated thread; the API loop only hands them requests
(:meth:`EngineLoop.call`, :meth:`EngineLoop.run`) and reads what they publish (the store, the
engine's progress).

Objects bound to a loop (drivers' sockets, ``asyncio.Event``, tasks) are created and used on
this loop only; calls from other threads go through ``call_soon_threadsafe`` or
``run_coroutine_threadsafe``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import sys
import threading
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

T = TypeVar("T")

SWITCH_INTERVAL_S = 0.001
"""Python's thread switch interval while an engine loop runs (default 5 ms). The engine's
thread wakes on every device reply and needs the interpreter at once; with the API thread busy
the default interval would add up to 5 ms to each of the ~40 round trips of an angle."""


class EngineLoop:
    """An asyncio loop running in a daemon thread until :meth:`close`."""

    def __init__(self, name: str = "gonio-engine") -> None:
        self.name = name
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._saved_switch: float | None = None

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise RuntimeError("the engine loop is not running; call start() first")
        return self._loop

    @property
    def running(self) -> bool:
        return self._loop is not None and self._thread is not None and self._thread.is_alive()

    def in_loop(self) -> bool:
        """True when called from the engine loop's own thread."""
        return self._thread is not None and threading.current_thread() is self._thread

    def start(self) -> None:
        """Start the thread and its loop; returns once the loop runs."""
        if self.running:
            return
        ready = threading.Event()

        def main() -> None:
            loop = asyncio.new_event_loop()
            asyncio.set_event_loop(loop)
            self._loop = loop
            loop.call_soon(ready.set)
            try:
                loop.run_forever()
            finally:
                _cancel_all(loop)
                with contextlib.suppress(Exception):
                    loop.run_until_complete(loop.shutdown_asyncgens())
                loop.close()

        self._thread = threading.Thread(target=main, name=self.name, daemon=True)
        self._thread.start()
        ready.wait()
        self._saved_switch = sys.getswitchinterval()
        sys.setswitchinterval(min(self._saved_switch, SWITCH_INTERVAL_S))

    def submit(self, coro: Coroutine[Any, Any, T]) -> concurrent.futures.Future[T]:
        """Schedule ``coro`` on the engine loop from any thread."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop)

    async def run(self, coro: Coroutine[Any, Any, T]) -> T:
        """Await ``coro`` run on the engine loop, from another loop (or this one)."""
        if self.in_loop():
            return await coro
        return await asyncio.wrap_future(self.submit(coro))

    def call(self, fn: Callable[..., Any], *args: Any) -> None:
        """Call ``fn(*args)`` on the engine loop soon (from any thread; at once if on it)."""
        if self.in_loop():
            fn(*args)
        else:
            self.loop.call_soon_threadsafe(fn, *args)

    def close(self, timeout_s: float = 30.0) -> None:
        """Stop the loop (cancelling what still runs on it) and join the thread."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        if not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(loop.stop)
        if thread is not threading.current_thread():
            thread.join(timeout_s)
        self._loop = self._thread = None
        if self._saved_switch is not None:
            sys.setswitchinterval(self._saved_switch)
            self._saved_switch = None


def running_in(loop: asyncio.AbstractEventLoop) -> bool:
    """True when the caller runs on ``loop`` (in its thread, inside it): a call from there
    must not wait for the loop through ``run_coroutine_threadsafe``, which would deadlock."""
    try:
        return asyncio.get_running_loop() is loop
    except RuntimeError:
        return False


def _cancel_all(loop: asyncio.AbstractEventLoop) -> None:
    tasks = [t for t in asyncio.all_tasks(loop) if not t.done()]
    for t in tasks:
        t.cancel()
    if tasks:
        with contextlib.suppress(Exception):
            loop.run_until_complete(asyncio.gather(*tasks, return_exceptions=True))
