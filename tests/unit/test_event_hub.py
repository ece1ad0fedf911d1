"""Events from the job store to their subscribers (gonio.event_hub), on a real SQLite store."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path

from gonio.event_hub import EventHub
from gonio.service_models import Event
from gonio.store import JobStore


def test_recorded_events_are_stored_and_reach_listeners_in_the_committing_thread(
        tmp_path: Path) -> None:
    store = JobStore(tmp_path / "jobs.sqlite")
    hub = EventHub(store)
    seen: list[tuple[Event, str]] = []
    handle = hub.add_listener(lambda ev: seen.append((ev, threading.current_thread().name)))

    def commit() -> None:
        hub.record("maintenance", {"held_by": "alice"})

    t = threading.Thread(target=commit, name="committer")
    t.start()
    t.join()
    (ev, thread), = seen
    assert (ev.type, ev.data, ev.job_id) == ("maintenance", {"held_by": "alice"}, None)
    assert thread == "committer"
    assert hub.seq == ev.seq
    assert [e.type for e in store.events_after(0)] == ["maintenance"]  # stored, not only told
    hub.remove_listener(handle)
    hub.record("maintenance", {"held_by": None})
    assert len(seen) == 1
    hub.close()


def test_a_subscriber_gets_the_backlog_then_live_events_none_lost_or_repeated(
        tmp_path: Path) -> None:
    store = JobStore(tmp_path / "jobs.sqlite")
    hub = EventHub(store)
    # More than one store read's worth (500) before the subscriber starts.
    for i in range(505):
        store.append_event(None, "tick", {"i": i})
    first = store.last_seq()

    async def go() -> list[int]:
        hub.start()
        got: list[int] = []

        async def consume() -> None:
            async for ev in hub.subscribe(since_seq=3):
                got.append(ev.data["i"])
                if len(got) == 502 + 5:
                    return

        task = asyncio.create_task(consume())
        while len(got) < 502:
            await asyncio.sleep(0.01)

        def burst() -> None:  # live events committed by another thread, as the engine does
            for i in range(505, 510):
                hub.record("tick", {"i": i})

        await asyncio.to_thread(burst)
        await asyncio.wait_for(task, timeout=60)
        return got

    got = asyncio.run(go())
    assert got == list(range(3, 510))
    assert hub.seq == first + 5
    hub.close()


def test_a_subscriber_for_one_job_sees_only_that_job(tmp_path: Path) -> None:
    store = JobStore(tmp_path / "jobs.sqlite")
    hub = EventHub(store)
    a = store.create_job(kind="uniform", specimen="a", plan={}, rig={})
    b = store.create_job(kind="uniform", specimen="b", plan={}, rig={})
    store.append_event(b.id, "note", {})
    store.append_event(a.id, "note", {})

    async def go() -> list[tuple[int | None, str]]:
        out: list[tuple[int | None, str]] = []
        async for ev in hub.subscribe(0, job_id=a.id):
            out.append((ev.job_id, ev.type))
            if len(out) == 2:
                return out
        return out

    assert asyncio.run(asyncio.wait_for(go(), timeout=30)) == [(a.id, "created"),
                                                                 (a.id, "note")]
    hub.close()
