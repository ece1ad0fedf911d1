"""The job store's events to their subscribers: stored first, then each one woken.

Every event is committed to the store (:meth:`gonio.store.JobStore.append_event`) before anyone
is told, by whichever thread commits it (the API's, the engine loop's, a finishing thread).
:meth:`EventHub.subscribe` then re-reads the store from the last event it delivered, so a
subscriber that was slow or woken once for a burst loses nothing.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import Any

from gonio.service_models import Event
from gonio.store import EventRow, JobStore

_BATCH = 500
"""Events read from the store per wake-up of a subscriber."""


class EventHub:
    """Publish and subscribe over one job store's events.

    Parameters
    ----------
    store : JobStore
        Where events are committed; the hub listens to it from construction until
        :meth:`close`.
    """

    def __init__(self, store: JobStore) -> None:
        self.store = store
        self._loop: asyncio.AbstractEventLoop | None = None
        self._cond: asyncio.Condition | None = None
        self._version = 0
        store.add_listener(self._on_event)

    def start(self) -> None:
        """Wake subscribers on the running loop (the API's) from now on, from any thread."""
        self._loop = asyncio.get_running_loop()
        self._cond = asyncio.Condition()

    def close(self) -> None:
        """Stop listening to the store."""
        self.store.remove_listener(self._on_event)

    @property
    def seq(self) -> int:
        """Sequence number of the latest event."""
        return self.store.last_seq()

    def record(self, type_: str, data: dict[str, Any], job_id: int | None = None) -> Event:
        """Store an event (e.g. the maintenance lock) and tell every subscriber."""
        return Event.from_row(self.store.append_event(job_id, type_, data))

    def add_listener(self, fn: Callable[[Event], None]) -> Callable[[EventRow], None]:
        """Call ``fn(event)`` right after each event is stored, in the committing thread.

        Runs before the code that caused the event continues (e.g. before the worker takes the
        next job), so keep ``fn`` short. Returns the handle for :meth:`remove_listener`.
        """
        def listener(ev: EventRow) -> None:
            fn(Event.from_row(ev))

        self.store.add_listener(listener)
        return listener

    def remove_listener(self, handle: Callable[[EventRow], None]) -> None:
        self.store.remove_listener(handle)

    def _on_event(self, ev: EventRow) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            loop.create_task(self._bump())
        else:
            asyncio.run_coroutine_threadsafe(self._bump(), loop)

    async def _bump(self) -> None:
        assert self._cond is not None
        async with self._cond:
            self._version += 1
            self._cond.notify_all()

    async def subscribe(self, since_seq: int = 0, job_id: int | None = None
                        ) -> AsyncIterator[Event]:
        """Stored events after ``since_seq``, then live ones as they happen; none is lost.

        Every event is committed to the store before subscribers are woken, and each wake-up
        re-reads the store from the last delivered ``seq``, so a burst is never dropped.
        """
        if self._cond is None:
            self._cond = asyncio.Condition()
        last = since_seq
        while True:
            version = self._version
            batch = self.store.events_after(last, _BATCH, job_id=job_id)
            for ev in batch:
                last = ev.seq
                yield Event.from_row(ev)
            if batch:
                continue
            async with self._cond:
                await self._cond.wait_for(lambda v=version: self._version != v)  # type: ignore[misc]
