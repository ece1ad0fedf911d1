"""The SQLite store: durability, uniqueness, queue order, reconciliation, events."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from gonio.jobstates import IllegalTransition, JobState
from gonio.store import JobStore, NotFound, ReadingRow, StoreError


def _job(store: JobStore, priority: int = 0) -> int:
    return store.create_job(kind="uniform", specimen="s", plan={"kind": "uniform"},
                            rig={"pairs": []}, priority=priority).id


def _reading(k: int, light: str = "L1", sensor: str = "S1") -> ReadingRow:
    return ReadingRow(k, 10.0 * k, 10.0 * k, light, sensor, (1.0, 2.0), (0.1, 0.1), 0.01, 1,
                      False, 0.0)


def test_wal_mode_and_reopen(tmp_path: Path) -> None:
    db = tmp_path / "jobs.sqlite"
    store = JobStore(db)
    jid = _job(store)
    store.add_steps(jid, [(0, 0, 0.0, 0.0), (1, 0, 10.0, 10.0)])
    store.commit_angle(jid, 0, 0.0, [_reading(0), _reading(0, sensor="S2")])
    store.close()
    mode = sqlite3.connect(db).execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"
    again = JobStore(db)
    assert again.get_job(jid).done_angles == 1
    assert again.get_job(jid).total_angles == 2
    assert len(again.readings(jid)) == 2


def test_repeated_angle_never_duplicates() -> None:
    store = JobStore(":memory:")
    jid = _job(store)
    store.add_steps(jid, [(0, 0, 0.0, 0.0)])
    store.commit_angle(jid, 0, 0.0, [_reading(0)])
    with pytest.raises(sqlite3.IntegrityError):
        store.commit_angle(jid, 0, 0.0, [_reading(0)])
    assert store.reading_count(jid) == 1
    # The failed checkpoint rolled back completely: no extra event either.
    assert [e.type for e in store.events_after(0)].count("progress") == 1


def test_queue_order_priority_then_fifo_and_reorder() -> None:
    store = JobStore(":memory:")
    a, b, c = _job(store), _job(store), _job(store, priority=5)
    assert [j.id for j in store.queue()] == [c, a, b]
    store.reorder(b, position=0)
    assert [j.id for j in store.queue()] == [b, c, a]
    store.reorder(a, priority=10)
    assert next(j.id for j in store.queue()) == a
    store.set_state(a, JobState.RUNNING)
    with pytest.raises(IllegalTransition, match="reorder"):
        store.reorder(a, priority=1)
    with pytest.raises(NotFound):
        store.reorder(999, priority=1)


def test_illegal_state_change_is_refused_and_not_logged() -> None:
    store = JobStore(":memory:")
    jid = _job(store)
    n = store.last_seq()
    with pytest.raises(IllegalTransition, match="cannot go from queued to completed"):
        store.set_state(jid, JobState.COMPLETED)
    assert store.last_seq() == n
    assert store.get_job(jid).state is JobState.QUEUED


def test_reconcile_resumes_or_fails() -> None:
    store = JobStore(":memory:")
    a, b, c = _job(store), _job(store), _job(store)
    store.set_state(a, JobState.RUNNING)
    store.set_state(b, JobState.RUNNING)
    store.set_state(b, JobState.SUSPENDED, reason="stage: overload")
    out = store.reconcile(lambda j: None if j.id == a else "rig changed")
    assert out == [(a, "resumed"), (b, "failed")]
    assert store.get_job(a).state is JobState.RUNNING
    assert store.get_job(b).state is JobState.FAILED
    assert store.get_job(b).reason == "rig changed"
    assert store.get_job(c).state is JobState.QUEUED


def test_events_are_monotonic_and_listeners_called() -> None:
    store = JobStore(":memory:")
    seen: list[int] = []
    store.add_listener(lambda ev: seen.append(ev.seq))
    jid = _job(store)
    store.set_state(jid, JobState.RUNNING)
    store.append_event(jid, "note", {"x": 1})
    evs = store.events_after(0)
    assert [e.seq for e in evs] == seen == sorted(seen)
    assert store.events_after(seen[1])[0].data == {"x": 1}


def test_not_a_store(tmp_path: Path) -> None:
    bad = tmp_path / "x.sqlite"
    bad.write_bytes(b"this is not sqlite at all" * 100)
    with pytest.raises(StoreError, match="not a usable gonio job store"):
        JobStore(bad)
