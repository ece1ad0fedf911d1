"""Server-sent events: the service's event log as a ``text/event-stream``.

Each event is one SSE message whose ``id`` is the event's ``seq`` and whose ``data`` is the
event as JSON (``{"seq", "type", "job_id", "time", "data"}``). There is no ``event:`` field, so
a plain ``EventSource.onmessage`` sees every event; the type is inside the JSON.

Resync: a client that reconnects sends the last ``seq`` it saw as ``Last-Event-ID`` (browsers'
``EventSource`` does this by itself) or as ``?since=``; the stream then replays every stored
event after it before going live, so nothing is lost across a dropped connection. A comment
line every ``heartbeat_s`` keeps proxies and NAT tables from closing an idle stream and lets
the server notice a client that went away.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from typing import Any

HEARTBEAT_S = 15.0
RETRY_MS = 2000


class StreamCloser:
    """Ends every open event stream at once, so a daemon shutdown does not wait for them.

    An event stream never ends by itself; without this, uvicorn's graceful shutdown waits its
    whole timeout for them and then cancels them mid-response. :meth:`close` may be called
    from any thread or a signal handler.
    """

    def __init__(self) -> None:
        self._event: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.closed = False

    def event(self) -> asyncio.Event:
        """The event streams wait on (call from the serving loop)."""
        if self._event is None:
            self._event = asyncio.Event()
            self._loop = asyncio.get_running_loop()
        if self.closed:
            self._event.set()
        return self._event

    def close(self) -> None:
        """End all streams now and refuse to keep new ones open."""
        self.closed = True
        loop, event = self._loop, self._event
        if loop is not None and event is not None and not loop.is_closed():
            # RuntimeError: the loop closed meanwhile, so nothing is left to wake.
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(event.set)


def format_event(event: Any) -> bytes:
    """One SSE message for a service event (anything with seq, type, job_id, data)."""
    payload = {
        "seq": int(event.seq),
        "type": str(event.type),
        "job_id": event.job_id,
        "time": getattr(event, "time", None),
        "data": event.data,
    }
    # json.dumps escapes newlines, so the data stays on one ``data:`` line as SSE requires.
    return f"id: {payload['seq']}\ndata: {json.dumps(payload, default=str)}\n\n".encode()


async def sse_stream(
    events: AsyncIterator[Any], heartbeat_s: float = HEARTBEAT_S,
    closing: asyncio.Event | None = None,
) -> AsyncIterator[bytes]:
    """Encode ``events`` as SSE, interleaving keep-alive comments while nothing happens.

    The next event is awaited in one task that survives heartbeats: cancelling a pending
    ``__anext__`` on every timeout would close the underlying generator. When ``closing`` is
    set (daemon shutdown) the stream ends normally; clients reconnect with ``Last-Event-ID``.
    """
    yield f"retry: {RETRY_MS}\n\n".encode()
    pending: asyncio.Task[Any] | None = None
    closed: asyncio.Task[Any] | None = (
        asyncio.ensure_future(closing.wait()) if closing is not None else None
    )
    try:
        while True:
            if pending is None:
                pending = asyncio.ensure_future(events.__anext__())
            waiting = {pending} if closed is None else {pending, closed}
            done, _ = await asyncio.wait(waiting, timeout=heartbeat_s,
                                         return_when=asyncio.FIRST_COMPLETED)
            if closed is not None and closed in done:
                return
            if not done:
                yield b": keep-alive\n\n"
                continue
            try:
                event = pending.result()
            except StopAsyncIteration:
                return
            finally:
                pending = None
            yield format_event(event)
    finally:
        if closed is not None:
            closed.cancel()
        if pending is not None:
            pending.cancel()
            with contextlib.suppress(asyncio.CancelledError, StopAsyncIteration):
                await pending
        aclose = getattr(events, "aclose", None)
        if aclose is not None:
            with contextlib.suppress(Exception):
                await aclose()
