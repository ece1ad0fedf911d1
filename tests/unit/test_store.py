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


def test_the_job_list_gives_queued_jobs_in_queue_order_in_their_places() -> None:
    # The list said "queue order for queued ones" and gave them by id: a job moved up (the
    # lab page's up arrow) stayed below the jobs it passed, and the page's next move was
    # counted from that wrong order. Jobs not queued keep their places (by id).
    store = JobStore(":memory:")
    done, a, b, c = _job(store), _job(store), _job(store), _job(store, priority=5)
    store.set_state(done, JobState.RUNNING)
    store.set_state(done, JobState.ABORTED)
    assert [j.id for j in store.list_jobs()] == [done, c, a, b]
    store.reorder(b, position=0)
    assert [j.id for j in store.list_jobs()] == [done, b, c, a]
    assert [j.id for j in store.list_jobs(["queued"])] == [j.id for j in store.queue()]


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


def test_reads_do_not_wait_for_an_open_write(tmp_path: Path) -> None:
    """A status read returns at once while another thread is inside a write transaction.

    White-box on purpose: the writer holds the store's lock across its commit (and fsync); a
    reader that took the same lock would wait here for the full two seconds.
    """
    import threading
    import time

    store = JobStore(tmp_path / "jobs.sqlite")
    jid = _job(store)
    inside, release = threading.Event(), threading.Event()

    def writer() -> None:
        with store._tx() as c:
            c.execute("UPDATE jobs SET specimen = 'changed' WHERE id = ?", (jid,))
            inside.set()
            release.wait(60.0)

    t = threading.Thread(target=writer)
    t.start()
    try:
        assert inside.wait(5)
        t0 = time.perf_counter()
        row = store.get_job(jid)
        events = store.events_after(0)
        elapsed = time.perf_counter() - t0
    finally:
        release.set()
        t.join()
    # Not blocked: had the reads waited for the writer, they would have returned only after
    # its commit (the writer holds its transaction until released, below), and seen it.
    print(f"reads beside an open write transaction took {1000 * elapsed:.1f} ms")
    assert row.specimen == "s"  # the open transaction is not visible
    assert [e.type for e in events] == ["created"]
    assert store.get_job(jid).specimen == "changed"  # and its commit is, on the same thread


def test_reader_connections_of_finished_threads_are_closed(tmp_path: Path) -> None:
    import threading

    store = JobStore(tmp_path / "jobs.sqlite")
    jid = _job(store)
    seen: list[str] = []
    for _ in range(5):
        t = threading.Thread(target=lambda: seen.append(store.get_job(jid).specimen))
        t.start()
        t.join()
    assert seen == ["s"] * 5
    # Each new reader prunes the connections of threads that have ended.
    assert len(store._readers) <= 2
    store.close()
    assert store._readers == {}
    with pytest.raises(sqlite3.ProgrammingError):
        store.get_job(jid)


@pytest.mark.parametrize("path", [":memory:", "file"])
def test_queue_position_matches_queue_order(tmp_path: Path, path: str) -> None:
    store = JobStore(":memory:" if path == ":memory:" else tmp_path / "q.sqlite")
    ids = [_job(store), _job(store), _job(store, priority=3), _job(store), _job(store, 3)]
    store.reorder(ids[3], position=0)
    store.set_state(ids[1], JobState.RUNNING)
    order = [j.id for j in store.queue()]
    assert [store.queue_position(j) for j in order] == list(range(len(order)))
    assert store.queue_position(ids[1]) is None  # running, not queued
    assert store.queue_position(999) is None


def test_many_openers_of_one_new_store_all_succeed(tmp_path: Path) -> None:
    """Two processes (here: connections in threads) creating the same store race on its
    schema row; every opener must succeed and see one schema version."""
    import threading

    path = tmp_path / "race.sqlite"
    n = 8
    barrier = threading.Barrier(n)
    errors: list[BaseException] = []
    stores: list[JobStore] = []

    def open_store() -> None:
        barrier.wait()
        try:
            stores.append(JobStore(path))
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=open_store) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert not errors, errors
    assert len(stores) == n
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT COUNT(*) FROM meta WHERE key='schema'").fetchone() == (1,)
    for s in stores:
        s.close()


# The schema-1 tables a store needs to hold a reading, as gonio wrote them before auto-ranging
# (written out here: the migration must work on what old versions left on disk).
_SCHEMA_1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
INSERT INTO meta (key, value) VALUES ('schema', '1');
CREATE TABLE jobs (
    id INTEGER PRIMARY KEY AUTOINCREMENT, state TEXT NOT NULL, kind TEXT NOT NULL,
    specimen TEXT NOT NULL, priority INTEGER NOT NULL DEFAULT 0,
    position REAL NOT NULL DEFAULT 0, created REAL NOT NULL, started REAL, finished REAL,
    plan TEXT NOT NULL, rig TEXT NOT NULL, reason TEXT, result_path TEXT, summary TEXT,
    done_angles INTEGER NOT NULL DEFAULT 0, total_angles INTEGER NOT NULL DEFAULT 0);
CREATE TABLE readings (
    job_id INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
    angle_index INTEGER NOT NULL, commanded_deg REAL NOT NULL, actual_deg REAL NOT NULL,
    light TEXT NOT NULL, sensor TEXT NOT NULL, raw TEXT NOT NULL, dark TEXT NOT NULL,
    exposure_s REAL NOT NULL, averages INTEGER NOT NULL, saturated INTEGER NOT NULL,
    t_read REAL NOT NULL, t_commit REAL NOT NULL,
    UNIQUE (job_id, angle_index, light, sensor));
INSERT INTO jobs (state, kind, specimen, created, plan, rig)
    VALUES ('completed', 'uniform', 'felt', 1.0, '{}', '{}');
INSERT INTO readings VALUES (1, 0, 0.0, 0.01, 'L1', 'S1', '[1000.0, 2000.0]', '[100.0, 100.0]',
    0.01, 1, 0, 2.0, 3.0);
"""


def test_a_schema_1_store_is_migrated_and_keeps_its_readings(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    with sqlite3.connect(path) as db:
        db.executescript(_SCHEMA_1)
    store = JobStore(path)
    (old,) = store.readings(1)
    # Readings from before auto-ranging were all taken in the nominal range.
    assert old.raw == (1000.0, 2000.0) and old.dark == (100.0, 100.0)
    assert old.range_index == 0 and old.range_scale == 1.0
    assert store.get_job(1).specimen == "felt"
    # New readings carry their range.
    job = _job(store)
    store.add_steps(job, [(0, 0, 0.0, 0.0)])
    ranged = ReadingRow(0, 0.0, 0.0, "L1", "S1", (5.0e5,), (100.0,), 0.01, 1, False, 4.0,
                        range_index=3, range_scale=0.001)
    store.commit_angle(job, 0, 0.0, [ranged])
    assert store.readings(job) == [ranged]
    store.close()
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT value FROM meta WHERE key='schema'").fetchone() == ("2",)
    # Opening it again (already migrated) changes nothing.
    again = JobStore(path)
    assert again.readings(1) == [old] and again.readings(job) == [ranged]
    again.close()


def test_a_store_newer_than_this_gonio_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "new.sqlite"
    JobStore(path).close()
    with sqlite3.connect(path) as db:
        db.execute("UPDATE meta SET value = '99' WHERE key = 'schema'")
    with pytest.raises(StoreError, match="has store schema 99"):
        JobStore(path)


def test_a_damaged_page_is_refused_by_name_and_left_as_it_was(tmp_path: Path) -> None:
    db = tmp_path / "jobs.sqlite"
    store = JobStore(db)
    for _ in range(40):
        job = _job(store)
        store.add_steps(job, [(k, 0, 10.0 * k, 10.0 * k) for k in range(4)])
        for k in range(4):
            store.commit_angle(job, k, 10.0 * k, [_reading(k, "L1", s) for s in ("S1", "S2")])
    store.close()
    with sqlite3.connect(db) as con:
        con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        page = con.execute("PRAGMA page_size").fetchone()[0]
    pages = db.stat().st_size // page
    assert pages > 4
    with open(db, "r+b") as f:
        f.seek(pages // 2 * page)
        f.write(b"\x5a" * page)
    before = db.read_bytes()
    with pytest.raises(StoreError, match=f"job store {db} is damaged") as e:
        JobStore(db)
    assert "restore it from a backup" in str(e.value) and ".recover" in str(e.value)
    assert db.read_bytes() == before


@pytest.mark.parametrize(("stored", "job", "expected"), [
    ("/srv/lab/data/results/job-7.h5", 7, "results/job-7.h5"),  # absolute, moved since
    ("data/results/job-7.h5", 7, "results/job-7.h5"),  # relative to an old working dir
    ("results/job-7.h5", 7, "results/job-7.h5"),  # already as stored now
    ("/srv/lab/data/results/job-8.h5", 7, "/srv/lab/data/results/job-8.h5"),  # not its own
    ("/elsewhere/job-7.h5", 7, "/elsewhere/job-7.h5"),
])
def test_result_paths_become_relative_to_the_data_directory(stored: str, job: int,
                                                            expected: str) -> None:
    from gonio.store import relative_result_path

    assert relative_result_path(job, stored) == expected


def test_an_older_store_is_migrated_when_opened(tmp_path: Path) -> None:
    import json

    db = tmp_path / "jobs.sqlite"
    store = JobStore(db)
    job = _job(store)
    store.close()
    # As an older gonio left it: absolute paths, and no mark that the paths were looked at.
    with sqlite3.connect(db) as con:
        con.execute("UPDATE jobs SET result_path = ?, summary = ? WHERE id = ?",
                    (f"/old/data/results/job-{job}.h5",
                     json.dumps({"result_path": f"/old/data/results/job-{job}.h5",
                                 "calibration_path": "/old/data/calibration.json",
                                 "readings": 3}), job))
        con.execute("DELETE FROM meta WHERE key = 'result_paths'")
    store = JobStore(db)
    row = store.get_job(job)
    assert row.result_path == f"results/job-{job}.h5"
    assert row.summary == {"result_path": f"results/job-{job}.h5",
                           "calibration_path": "calibration.json", "readings": 3}
    store.close()
    with sqlite3.connect(db) as con:  # stored so, not only read so
        assert con.execute("SELECT result_path FROM jobs").fetchone()[0] == row.result_path
        assert json.loads(con.execute("SELECT summary FROM jobs").fetchone()[0]) == row.summary


def test_result_paths_are_stored_relative_and_a_marked_store_is_not_looked_through_again(
        tmp_path: Path) -> None:
    """set_result stores the data directory's relative paths, so once a store is marked
    (every later open) the pass over every finished job is skipped: a path written behind
    gonio's back after the mark stays as it was written, where an unmarked store rewrites it."""
    db = tmp_path / "jobs.sqlite"
    store = JobStore(db)
    job = _job(store)
    store.set_result(job, f"/somewhere/data/results/job-{job}.h5",
                     {"result_path": f"/somewhere/data/results/job-{job}.h5",
                      "calibration_path": "/somewhere/data/calibration.json"})
    row = store.get_job(job)
    assert row.result_path == f"results/job-{job}.h5"
    assert row.summary == {"result_path": f"results/job-{job}.h5",
                           "calibration_path": "calibration.json"}
    store.close()
    raw = f"/behind/its/back/results/job-{job}.h5"
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT value FROM meta WHERE key = 'result_paths'").fetchone() \
            == ("relative",)
        con.execute("UPDATE jobs SET result_path = ? WHERE id = ?", (raw, job))
    store = JobStore(db)
    assert store.get_job(job).result_path == raw  # not looked through: the store was marked
    store.close()
    with sqlite3.connect(db) as con:
        con.execute("DELETE FROM meta WHERE key = 'result_paths'")
    store = JobStore(db)
    assert store.get_job(job).result_path == f"results/job-{job}.h5"  # unmarked: rewritten
    assert store.get_job(job).summary["result_path"] == f"results/job-{job}.h5"
    store.close()
