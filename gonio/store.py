"""Durable job store: SQLite (stdlib ``sqlite3``) in WAL mode.

Three kinds of record (schema in ``docs/engine.md``):

* ``jobs``: one row per job: state, priority and queue position, timestamps, the plan and the
  rig snapshot as JSON, progress, the reason of a failure, the result path and summary.
* ``steps`` / ``readings`` / ``darks``: the planned stage angles of a job and every reading
  taken at them. A stage angle is a checkpoint: its readings, its ``done`` mark, the job's
  progress and a ``checkpoint`` event commit in one transaction (:meth:`JobStore.commit_angle`),
  so after a crash an angle is either wholly stored or not at all. ``UNIQUE(job_id,
  angle_index, light, sensor)`` makes a repeated angle unable to duplicate readings.
* ``events``: an append-only log with a monotonic ``seq``; the API replays it to clients.
* ``holds``: decisions that must outlive the process, e.g. the queue hold of an emergency halt
  or of a job that stops the queue on failure (:meth:`JobStore.set_hold`).

Every state change goes through :func:`gonio.jobstates.check_transition`.

Opening a store file checks it (``PRAGMA quick_check``): a damaged file is refused with a
:class:`StoreError` naming it and saying what to do, before anything reads or writes it. Result
paths are stored relative to the data directory (``results/job-<id>.h5``); stores written by
older versions, which stored them as given (absolute, or relative to the daemon's working
directory), are rewritten on the first open by a gonio that does so, which then marks the store
(``meta`` key ``result_paths``) so later opens skip the pass over every finished job (half a
second at 5,000 jobs); :meth:`JobStore.set_result` stores paths in the same form.

Thread-safety and concurrency: writes go through one connection guarded by a lock (SQLite has
one writer at a time anyway). Reads never take that lock: each thread reads through its own
connection, which WAL lets run concurrently with the writer and with each other, so a status
request never waits behind a checkpoint's commit (or its fsync). Other processes (``gonio jobs``
while the daemon runs) read the same way. A ``":memory:"`` store has no WAL and no second
connection can see it, so there reads share the writer's connection under the lock.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any, cast

from gonio.jobstates import ACTIVE_STATES, JobState, check_action, check_transition

SCHEMA_VERSION = 2
RESULT_PATHS_MARK = "relative"
"""``meta`` value of key ``result_paths`` once a store's result paths were made relative to its
data directory (:meth:`JobStore._migrate_result_paths`)."""
#: The statements that bring a store of schema ``k`` to ``k + 1``, run in one transaction when
#: an older store is opened (the tables of a new store are created at the latest version).
_MIGRATIONS: dict[int, tuple[str, ...]] = {
    # 1 -> 2: the sensor range of each reading (auto-ranging); older readings were all taken
    # in the nominal range.
    1: ("ALTER TABLE readings ADD COLUMN range_index INTEGER NOT NULL DEFAULT 0",
        "ALTER TABLE readings ADD COLUMN range_scale REAL NOT NULL DEFAULT 1.0"),
}
# How long a connection waits on a lock held by another writer, and how long opening a new
# store keeps retrying while concurrent openers create it.
_BUSY_TIMEOUT_MS = 5000
_OPEN_RETRY_S = 30.0

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS jobs (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    state         TEXT NOT NULL,
    kind          TEXT NOT NULL,
    specimen      TEXT NOT NULL,
    priority      INTEGER NOT NULL DEFAULT 0,
    position      REAL NOT NULL DEFAULT 0,
    created       REAL NOT NULL,
    started       REAL,
    finished      REAL,
    plan          TEXT NOT NULL,
    rig           TEXT NOT NULL,
    reason        TEXT,
    result_path   TEXT,
    summary       TEXT,
    done_angles   INTEGER NOT NULL DEFAULT 0,
    total_angles  INTEGER NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS jobs_queue ON jobs (state, priority, position);
CREATE TABLE IF NOT EXISTS steps (
    job_id        INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
    angle_index   INTEGER NOT NULL,
    round         INTEGER NOT NULL,
    specimen_deg  REAL NOT NULL,
    position_deg  REAL NOT NULL,
    done          INTEGER NOT NULL DEFAULT 0,
    actual_deg    REAL,
    PRIMARY KEY (job_id, angle_index)
);
CREATE TABLE IF NOT EXISTS readings (
    job_id        INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
    angle_index   INTEGER NOT NULL,
    commanded_deg REAL NOT NULL,
    actual_deg    REAL NOT NULL,
    light         TEXT NOT NULL,
    sensor        TEXT NOT NULL,
    raw           TEXT NOT NULL,
    dark          TEXT NOT NULL,
    exposure_s    REAL NOT NULL,
    averages      INTEGER NOT NULL,
    saturated     INTEGER NOT NULL,
    t_read        REAL NOT NULL,
    t_commit      REAL NOT NULL,
    range_index   INTEGER NOT NULL DEFAULT 0,
    range_scale   REAL NOT NULL DEFAULT 1.0,
    UNIQUE (job_id, angle_index, light, sensor)
);
CREATE TABLE IF NOT EXISTS darks (
    job_id        INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,
    angle_index   INTEGER NOT NULL,
    sensor        TEXT NOT NULL,
    values_json   TEXT NOT NULL,
    t_read        REAL NOT NULL,
    UNIQUE (job_id, angle_index, sensor)
);
-- What finishing took beyond the readings (the rig config's provenance, a simulated
-- specimen's recipe), so a rebuilt result holds what the original did. A table of its own,
-- created on open: stores without it read as before, and older gonio versions ignore it.
CREATE TABLE IF NOT EXISTS finishing (
    job_id        INTEGER PRIMARY KEY REFERENCES jobs(id) ON DELETE CASCADE,
    inputs        TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS holds (
    name          TEXT PRIMARY KEY,
    reason        TEXT NOT NULL,
    since         REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS events (
    seq           INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id        INTEGER,
    type          TEXT NOT NULL,
    time          REAL NOT NULL,
    data          TEXT NOT NULL
);
"""


class NotFound(LookupError):
    """No job with that id."""


class StoreError(ValueError):
    """The store file is not usable (wrong schema, not a gonio store)."""


@dataclass(frozen=True)
class JobRow:
    """One job as stored."""

    id: int
    state: JobState
    kind: str
    specimen: str
    priority: int
    position: float
    created: float
    started: float | None
    finished: float | None
    plan: dict[str, Any]
    rig: dict[str, Any]
    reason: str | None
    result_path: str | None
    summary: dict[str, Any] | None
    done_angles: int
    total_angles: int


@dataclass(frozen=True)
class StepRow:
    angle_index: int
    round: int
    specimen_deg: float
    position_deg: float
    done: bool
    actual_deg: float | None


@dataclass(frozen=True)
class ReadingRow:
    """One (angle, light, sensor) reading; ``raw`` and ``dark`` are per-channel values.

    ``range_index`` is the sensor range it was taken in (0: nominal) and ``range_scale`` that
    range's sensitivity relative to range 0; ``dark`` was read in the same range, so
    ``(raw - dark) / range_scale`` is in range-0 units (:func:`gonio.calibration.counts`).
    """

    angle_index: int
    commanded_deg: float
    actual_deg: float
    light: str
    sensor: str
    raw: tuple[float, ...]
    dark: tuple[float, ...]
    exposure_s: float
    averages: int
    saturated: bool
    t_read: float
    range_index: int = 0
    range_scale: float = 1.0


@dataclass(frozen=True)
class EventRow:
    seq: int
    job_id: int | None
    type: str
    time: float
    data: dict[str, Any]


EventListener = Callable[[EventRow], None]


#: Where --db should point instead of a file that is not a job store: reading jobs wants an
#: existing store, starting one a new file (the old hint gave only the latter).
_STORE_HINT = ("point --db at a gonio job store (DATA_DIR/gonio.sqlite, the one 'gonio scan' "
               "and the daemon print), or at a new file to start one")


class JobStore:
    """The SQLite job store at ``path`` (created on first use).

    Parameters
    ----------
    path : path of the database file, or ``":memory:"`` for a throw-away store
    durable : bool
        True: ``synchronous=FULL`` (each checkpoint survives a power cut). False:
        ``synchronous=NORMAL`` (survives a process crash, the case the engine promises).
    """

    def __init__(self, path: str | Path, durable: bool = True):
        self.path = str(path)
        if self.path != ":memory:":
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._listeners: list[EventListener] = []
        self._shared_reads = self.path == ":memory:"
        # Reader connections by thread; the thread object tells when one can be closed.
        self._readers: dict[int, tuple[threading.Thread, sqlite3.Connection]] = {}
        self._readers_lock = threading.Lock()
        self._local = threading.local()
        self._closed = False
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        row = self._initialise(durable)
        if row is None:
            # Two processes may create the same new store at once: the first insert wins and
            # the other must then read (and check) the version the first one wrote.
            self._db.execute(
                "INSERT OR IGNORE INTO meta (key, value) VALUES ('schema', ?)",
                (str(SCHEMA_VERSION),),
            )
            row = self._db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
        if int(row[0]) < SCHEMA_VERSION:
            row = (self._migrate(int(row[0])),)
        if int(row[0]) != SCHEMA_VERSION:
            raise StoreError(
                f"{self.path} has store schema {row[0]}, this gonio reads {SCHEMA_VERSION}; "
                "use a matching gonio version or a new database file"
            )
        if self.path != ":memory:":
            self._migrate_result_paths()

    def _check_integrity(self) -> None:
        """``PRAGMA quick_check`` (every page's structure, not every index entry: linear in
        the file's size); a damaged file is refused before anything trusts it."""
        try:
            rows = self._db.execute("PRAGMA quick_check(5)").fetchall()
        except sqlite3.OperationalError:
            raise  # locked by a concurrent opener: _initialise retries
        except sqlite3.DatabaseError as exc:
            rows = [(str(exc),)]
        problems = [str(r[0]) for r in rows if str(r[0]) != "ok"]
        if problems:
            self._db.close()
            raise StoreError(
                f"job store {self.path} is damaged (SQLite integrity check: "
                f"{'; '.join(problems)[:300]}). Nothing was written to it. Stop everything "
                "that uses it, copy it aside, then restore it from a backup or recover what it "
                f"holds into a new file (sqlite3 {self.path} .recover | sqlite3 recovered.sqlite) "
                "and start on that"
            )

    def _migrate_result_paths(self) -> None:
        """Rewrite result paths of older stores relative to the data directory (see the module
        doc); a no-op once done."""
        with self._lock:
            done = self._db.execute(
                "SELECT value FROM meta WHERE key = 'result_paths'").fetchone()
            if done is not None and done[0] == RESULT_PATHS_MARK:
                return
            rows = self._db.execute(
                "SELECT id, result_path, summary FROM jobs WHERE result_path IS NOT NULL"
            ).fetchall()
        changes: list[tuple[str, str | None, int]] = []
        for job_id, path, summary in rows:
            new_path = relative_result_path(job_id, path)
            new_summary = summary
            if summary:
                d = json.loads(summary)
                if isinstance(d, dict):
                    new_summary = json.dumps(_relative_summary(job_id, d))
            if new_path != path or new_summary != summary:
                changes.append((new_path, new_summary, job_id))
        if changes:
            with self._tx() as c:
                c.executemany("UPDATE jobs SET result_path = ?, summary = ? WHERE id = ?",
                              changes)
        # Everything this gonio writes is already relative (set_result), so the pass is needed
        # once per store; an older gonio writing to it afterwards writes paths its readers
        # resolved before this pass existed. A store this process may not write to (or one
        # busy past the timeout) keeps no mark and is looked through again at the next open,
        # as before.
        try:
            with self._tx() as c:
                c.execute("INSERT OR REPLACE INTO meta (key, value) VALUES ('result_paths', ?)",
                          (RESULT_PATHS_MARK,))
        except sqlite3.OperationalError:
            pass

    def _migrate(self, version: int) -> int:
        """Bring a store of schema ``version`` up to :data:`SCHEMA_VERSION`; returns the new
        version. One transaction, re-reading the version inside it, so two processes opening
        an old store at once migrate it once; nothing stored is lost."""
        with self._tx() as c:
            version = int(c.execute("SELECT value FROM meta WHERE key='schema'").fetchone()[0])
            while version < SCHEMA_VERSION and version in _MIGRATIONS:
                for statement in _MIGRATIONS[version]:
                    c.execute(statement)
                version += 1
                c.execute("UPDATE meta SET value = ? WHERE key = 'schema'", (str(version),))
        return version

    def _initialise(self, durable: bool) -> tuple[Any, ...] | None:
        """Set the connection up and create the schema; return the stored schema-version row.

        Concurrent openers of one new file can get SQLITE_BUSY from the switch to WAL or from
        the schema script without the busy handler being consulted (SQLite returns it at once
        where waiting could deadlock), so a *locked* database is retried for a while; any other
        database error means the file is not a gonio store.
        """
        deadline = time.monotonic() + _OPEN_RETRY_S
        delay = 0.01
        while True:
            try:
                # busy_timeout first: the WAL switch and the schema script need it too.
                self._db.execute(f"PRAGMA busy_timeout={_BUSY_TIMEOUT_MS}")
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute(f"PRAGMA synchronous={'FULL' if durable else 'NORMAL'}")
                self._db.execute("PRAGMA foreign_keys=ON")
                self._check_integrity()
                self._db.executescript(_SCHEMA)
                row = self._db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
                self._job_cols = tuple(
                    d[0] for d in self._db.execute("SELECT * FROM jobs LIMIT 0").description
                )
                return cast("tuple[Any, ...] | None", row)
            except sqlite3.OperationalError as exc:
                busy = "locked" in str(exc) or "busy" in str(exc)
                if busy and time.monotonic() < deadline:
                    time.sleep(delay)
                    delay = min(delay * 2, 0.5)
                    continue
                self._db.close()
                raise StoreError(
                    f"{self.path} is not a usable gonio job store ({exc}); "
                    f"{_STORE_HINT}"
                ) from None
            except sqlite3.DatabaseError as exc:
                self._db.close()
                raise StoreError(
                    f"{self.path} is not a usable gonio job store ({exc}); "
                    f"{_STORE_HINT}"
                ) from None

    # ------------------------------------------------------------------ plumbing
    @contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        """One write transaction (``BEGIN IMMEDIATE`` so writers never deadlock on upgrade)."""
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    @contextmanager
    def _read(self) -> Iterator[sqlite3.Connection]:
        """A connection for reading from this thread, without the writer's lock (see module doc).

        Autocommit mode: every statement sees the latest committed state, including this
        thread's own writes through the writer connection.
        """
        if self._shared_reads:
            with self._lock:
                yield self._db
            return
        conn: sqlite3.Connection | None = getattr(self._local, "conn", None)
        if conn is None:
            conn = self._open_reader()
        yield conn

    def _open_reader(self) -> sqlite3.Connection:
        if self._closed:
            raise sqlite3.ProgrammingError("the job store is closed")
        # check_same_thread=False only so close() can close it from another thread; it is used
        # by its own thread alone.
        conn = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        conn.execute(f"PRAGMA busy_timeout={_BUSY_TIMEOUT_MS}")
        conn.execute("PRAGMA query_only=ON")
        me = threading.current_thread()
        with self._readers_lock:
            # Threads come and go (thread pools resize): close what dead threads left behind.
            for ident, (thread, old) in list(self._readers.items()):
                if not thread.is_alive():
                    old.close()
                    del self._readers[ident]
            self._readers[me.ident or 0] = (me, conn)
        self._local.conn = conn
        return conn

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._db.close()
        with self._readers_lock:
            for _thread, conn in self._readers.values():
                conn.close()
            self._readers.clear()

    def add_listener(self, fn: EventListener) -> None:
        """Call ``fn(event)`` after every committed event (from the committing thread)."""
        self._listeners.append(fn)

    def remove_listener(self, fn: EventListener) -> None:
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _notify(self, events: Iterable[EventRow]) -> None:
        for ev in events:
            for fn in list(self._listeners):
                fn(ev)

    @staticmethod
    def _insert_event(
        c: sqlite3.Connection, job_id: int | None, type_: str, data: dict[str, Any]
    ) -> EventRow:
        t = time.time()
        cur = c.execute(
            "INSERT INTO events (job_id, type, time, data) VALUES (?, ?, ?, ?)",
            (job_id, type_, t, json.dumps(data)),
        )
        assert cur.lastrowid is not None
        return EventRow(cur.lastrowid, job_id, type_, t, data)

    # ------------------------------------------------------------------ jobs
    def create_job(
        self,
        *,
        kind: str,
        specimen: str,
        plan: dict[str, Any],
        rig: dict[str, Any],
        priority: int = 0,
        total_angles: int = 0,
        created: dict[str, Any] | None = None,
    ) -> JobRow:
        """Store a new queued job (FIFO within its priority) and a ``created`` event.

        ``total_angles``: the stage angles its plan measures first, when known at submission
        (a queued job then reads "0 of 8", not "0 of 0"); the engine sets it again when it
        plans them, and adaptive rounds add to it. ``created``: more of what the submission
        decided, kept in the ``created`` event's data (e.g. ``uncalibrated_accepted``)."""
        with self._tx() as c:
            pos = c.execute("SELECT COALESCE(MAX(position), 0) + 1 FROM jobs").fetchone()[0]
            cur = c.execute(
                "INSERT INTO jobs (state, kind, specimen, priority, position, created, plan, rig,"
                " total_angles) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (JobState.QUEUED.value, kind, specimen, priority, pos, time.time(),
                 json.dumps(plan), json.dumps(rig), total_angles),
            )
            job_id = int(cur.lastrowid or 0)
            ev = self._insert_event(
                c, job_id, "created",
                {**(created or {}), "state": "queued", "kind": kind, "priority": priority},
            )
        self._notify([ev])
        return self.get_job(job_id)

    def get_job(self, job_id: int) -> JobRow:
        with self._read() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            raise NotFound(f"no job with id {job_id}")
        return self._job_from(row)

    def _job_from(self, row: Sequence[Any]) -> JobRow:
        return _job_row(dict(zip(self._job_cols, row, strict=True)))

    def list_jobs(self, states: Iterable[str] | None = None) -> list[JobRow]:
        """Jobs in queue order for queued ones, newest last otherwise (by id)."""
        q = "SELECT * FROM jobs"
        args: list[Any] = []
        if states is not None:
            st = [JobState(s).value for s in states]
            q += f" WHERE state IN ({', '.join('?' * len(st))})"
            args = st
        q += " ORDER BY id"
        with self._read() as db:
            rows = [self._job_from(r) for r in db.execute(q, args).fetchall()]
        # The queued jobs keep the places they hold by id, taken in the order the worker takes
        # them (:meth:`queue`): a job moved up (reorder) is listed ahead of those it passed.
        slots = [k for k, r in enumerate(rows) if r.state is JobState.QUEUED]
        queued = sorted((rows[k] for k in slots), key=lambda r: (-r.priority, r.position, r.id))
        for k, r in zip(slots, queued, strict=True):
            rows[k] = r
        return rows

    def queue(self) -> list[JobRow]:
        """Queued jobs in the order the worker takes them: priority (high first), then position."""
        with self._read() as db:
            rows = db.execute(
                "SELECT * FROM jobs WHERE state = 'queued' ORDER BY priority DESC, position, id"
            ).fetchall()
        return [self._job_from(r) for r in rows]

    def queue_position(self, job_id: int) -> int | None:
        """0 for the job the worker takes next; None unless the job is queued.

        Counted in SQL, so a status request does not decode every queued job's plan.
        """
        with self._read() as db:
            row = db.execute(
                "SELECT state, priority, position FROM jobs WHERE id = ?", (job_id,)
            ).fetchone()
            if row is None or row[0] != JobState.QUEUED.value:
                return None
            ahead = db.execute(
                "SELECT COUNT(*) FROM jobs WHERE state = 'queued' AND (priority > ? OR "
                "(priority = ? AND (position < ? OR (position = ? AND id < ?))))",
                (row[1], row[1], row[2], row[2], job_id),
            ).fetchone()[0]
        return int(ahead)

    def set_state(
        self,
        job_id: int,
        new_state: str,
        *,
        reason: str | None = None,
        data: dict[str, Any] | None = None,
    ) -> JobRow:
        """Move a job to ``new_state`` if the transition table allows it; log a ``state`` event.

        Raises
        ------
        NotFound, gonio.jobstates.IllegalTransition
        """
        with self._tx() as c:
            row = c.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                raise NotFound(f"no job with id {job_id}")
            old = row[0]
            nxt = check_transition(old, new_state, job_id)
            now = time.time()
            sets = ["state = ?"]
            args: list[Any] = [nxt.value]
            if nxt is JobState.RUNNING:
                sets.append("started = COALESCE(started, ?)")
                args.append(now)
            if nxt in (JobState.COMPLETED, JobState.FAILED, JobState.ABORTED, JobState.HALTED):
                sets.append("finished = ?")
                args.append(now)
            if reason is not None or nxt is JobState.RUNNING:
                # Running again means the earlier suspension or pause reason no longer applies.
                sets.append("reason = ?")
                args.append(reason)
            c.execute(f"UPDATE jobs SET {', '.join(sets)} WHERE id = ?", (*args, job_id))
            payload = {"from": old, "state": nxt.value, **({"reason": reason} if reason else {})}
            ev = self._insert_event(c, job_id, "state", {**payload, **(data or {})})
        self._notify([ev])
        return self.get_job(job_id)

    def set_failure_reason(self, job_id: int, reason: str, data: dict[str, Any]) -> None:
        """Replace the reason of a ``failed`` job, with a ``rebuild_failed`` event (``reason``
        and ``data``): ``gonio jobs rebuild`` finished it again and that failed too. Not a
        state change (the job stays failed), so it is not in the transition table.

        Raises
        ------
        NotFound
            No failed job with this id.
        """
        with self._tx() as c:
            cur = c.execute("UPDATE jobs SET reason = ? WHERE id = ? AND state = 'failed'",
                            (reason, job_id))
            if cur.rowcount != 1:
                raise NotFound(f"no failed job with id {job_id}")
            ev = self._insert_event(c, job_id, "rebuild_failed", {**data, "reason": reason})
        self._notify([ev])

    def set_result(self, job_id: int, result_path: str | None, summary: dict[str, Any]) -> None:
        """Store job ``job_id``'s result path and summary, paths in the data directory's own
        relative form (:func:`relative_result_path`), as every open expects them."""
        path = None if result_path is None else relative_result_path(job_id, result_path)
        with self._tx() as c:
            c.execute(
                "UPDATE jobs SET result_path = ?, summary = ? WHERE id = ?",
                (path, json.dumps(_relative_summary(job_id, summary)), job_id),
            )

    def set_finishing_inputs(self, job_id: int, inputs: dict[str, Any]) -> None:
        """Keep what finishing job ``job_id`` took beyond its readings (JSON-serialisable:
        the provenance it added, a simulated specimen's recipe), for ``gonio jobs rebuild``."""
        with self._tx() as c:
            c.execute("INSERT OR REPLACE INTO finishing (job_id, inputs) VALUES (?, ?)",
                      (job_id, json.dumps(inputs)))

    def finishing_inputs(self, job_id: int) -> dict[str, Any] | None:
        """What :meth:`set_finishing_inputs` kept for job ``job_id``; None when nothing was
        (a job finished by a gonio from before it, or not finished)."""
        with self._read() as c:
            row = c.execute("SELECT inputs FROM finishing WHERE job_id = ?",
                            (job_id,)).fetchone()
        return None if row is None else cast("dict[str, Any]", json.loads(row[0]))

    def reorder(self, job_id: int, *, priority: int | None = None,
                position: int | None = None,
                check: Callable[[list[tuple[int, str]], list[tuple[int, str]]], None] | None
                = None) -> JobRow:
        """Change a queued job's priority and/or move it to index ``position`` of the queue.

        The queue is ordered by priority, then position; a job moved to an index takes the
        priority of the job it lands next to, so the stored order and the requested order agree.
        ``check(before, after)``, given the queue's ``(id, kind)`` in order before and after the
        change, may refuse it by raising: nothing is changed then.
        """
        queue_sql = ("SELECT id, kind FROM jobs WHERE state = 'queued' "
                     "ORDER BY priority DESC, position, id")
        with self._tx() as c:
            row = c.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                raise NotFound(f"no job with id {job_id}")
            check_action("reorder", row[0], job_id)
            before = [(r[0], r[1]) for r in c.execute(queue_sql)]
            if priority is not None:
                c.execute("UPDATE jobs SET priority = ? WHERE id = ?", (priority, job_id))
            if position is not None:
                order = [
                    (r[0], r[1])
                    for r in c.execute(
                        "SELECT id, priority FROM jobs WHERE state = 'queued' AND id != ? "
                        "ORDER BY priority DESC, position, id",
                        (job_id,),
                    )
                ]
                k = max(0, min(position, len(order)))
                if order:
                    neighbour = order[k][1] if k < len(order) else order[-1][1]
                    if priority is None:
                        c.execute(
                            "UPDATE jobs SET priority = ? WHERE id = ?", (neighbour, job_id)
                        )
                ids = [i for i, _ in order]
                ids.insert(k, job_id)
                c.executemany(
                    "UPDATE jobs SET position = ? WHERE id = ?",
                    [(float(i + 1), jid) for i, jid in enumerate(ids)],
                )
            if check is not None:
                check(before, [(r[0], r[1]) for r in c.execute(queue_sql)])
            ev = self._insert_event(
                c, job_id, "reordered", {"priority": priority, "position": position}
            )
        self._notify([ev])
        return self.get_job(job_id)

    def delete_job(self, job_id: int) -> None:
        """Remove a job and its readings (state checks are the caller's)."""
        with self._tx() as c:
            cur = c.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
            if cur.rowcount == 0:
                raise NotFound(f"no job with id {job_id}")
            ev = self._insert_event(c, job_id, "removed", {})
        self._notify([ev])

    def active_jobs(self) -> list[JobRow]:
        """Jobs in a state that owns the rig (running, paused, suspended, reconstructing)."""
        return self.list_jobs(s.value for s in ACTIVE_STATES)

    def reconcile(self, can_resume: Callable[[JobRow], str | None]) -> list[tuple[int, str]]:
        """Startup reconciliation of jobs the previous process left active.

        ``can_resume(job)`` returns None when the job can resume from its last checkpoint (it
        keeps its state and gets a ``recovered`` event; the worker resumes it first), or the
        reason it cannot (the job is marked failed with that reason). Never leaves a job stuck.

        Returns
        -------
        list of (job id, "resumed" | "failed")
        """
        out: list[tuple[int, str]] = []
        for job in self.active_jobs():
            why = can_resume(job)
            if why is None:
                self.append_event(job.id, "recovered", {
                    "state": job.state.value, "done_angles": job.done_angles})
                out.append((job.id, "resumed"))
            else:
                self.set_state(job.id, JobState.FAILED, reason=why)
                out.append((job.id, "failed"))
        return out

    # ------------------------------------------------------------------ steps and readings
    def add_steps(self, job_id: int, steps: Sequence[tuple[int, int, float, float]]) -> None:
        """Plan stage angles ``(angle_index, round, specimen_deg, position_deg)`` for a job."""
        with self._tx() as c:
            c.executemany(
                "INSERT INTO steps (job_id, angle_index, round, specimen_deg, position_deg) "
                "VALUES (?, ?, ?, ?, ?)",
                [(job_id, *s) for s in steps],
            )
            total = c.execute(
                "SELECT COUNT(*) FROM steps WHERE job_id = ?", (job_id,)
            ).fetchone()[0]
            c.execute("UPDATE jobs SET total_angles = ? WHERE id = ?", (total, job_id))
            ev = self._insert_event(c, job_id, "planned", {
                "round": steps[0][1] if steps else None, "new_angles": len(steps),
                "total_angles": total})
        self._notify([ev])

    def steps(self, job_id: int) -> list[StepRow]:
        with self._read() as db:
            rows = db.execute(
                "SELECT angle_index, round, specimen_deg, position_deg, done, actual_deg "
                "FROM steps WHERE job_id = ? ORDER BY angle_index",
                (job_id,),
            ).fetchall()
        return [StepRow(r[0], r[1], r[2], r[3], bool(r[4]), r[5]) for r in rows]

    def add_darks(self, job_id: int, angle_index: int,
                  darks: dict[str, tuple[float, ...]]) -> None:
        """Store dark readings (sensor -> per-channel values) taken at ``angle_index``."""
        t = time.time()
        with self._tx() as c:
            c.executemany(
                "INSERT OR REPLACE INTO darks (job_id, angle_index, sensor, values_json, t_read) "
                "VALUES (?, ?, ?, ?, ?)",
                [(job_id, angle_index, s, json.dumps(list(v)), t) for s, v in darks.items()],
            )

    def darks(self, job_id: int) -> dict[int, dict[str, tuple[float, ...]]]:
        """Stored darks: ``{angle_index: {sensor: values}}``."""
        out: dict[int, dict[str, tuple[float, ...]]] = {}
        with self._read() as db:
            for a, s, v in db.execute(
                "SELECT angle_index, sensor, values_json FROM darks WHERE job_id = ?", (job_id,)
            ):
                out.setdefault(a, {})[s] = tuple(json.loads(v))
        return out

    def commit_angle(
        self,
        job_id: int,
        angle_index: int,
        actual_deg: float,
        readings: Sequence[ReadingRow],
        event_data: dict[str, Any] | None = None,
    ) -> EventRow:
        """Checkpoint one stage angle: readings, step done, progress and event, atomically.

        Raises
        ------
        sqlite3.IntegrityError
            If readings of this angle were already committed (the engine never repeats a
            committed angle; the constraint makes a bug loud instead of duplicating data).
        """
        t = time.time()
        with self._tx() as c:
            c.executemany(
                "INSERT INTO readings (job_id, angle_index, commanded_deg, actual_deg, light, "
                "sensor, raw, dark, exposure_s, averages, saturated, t_read, t_commit, "
                "range_index, range_scale) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                [
                    (job_id, r.angle_index, r.commanded_deg, r.actual_deg, r.light, r.sensor,
                     json.dumps(list(r.raw)), json.dumps(list(r.dark)), r.exposure_s,
                     r.averages, int(r.saturated), r.t_read, t, r.range_index, r.range_scale)
                    for r in readings
                ],
            )
            c.execute(
                "UPDATE steps SET done = 1, actual_deg = ? WHERE job_id = ? AND angle_index = ?",
                (actual_deg, job_id, angle_index),
            )
            done = c.execute(
                "SELECT COUNT(*) FROM steps WHERE job_id = ? AND done = 1", (job_id,)
            ).fetchone()[0]
            total = c.execute(
                "SELECT COUNT(*) FROM steps WHERE job_id = ?", (job_id,)
            ).fetchone()[0]
            c.execute(
                "UPDATE jobs SET done_angles = ?, total_angles = ? WHERE id = ?",
                (done, total, job_id),
            )
            ev = self._insert_event(c, job_id, "progress", {
                "angle_index": angle_index, "done": done, "total": total,
                "actual_deg": actual_deg, **(event_data or {})})
        self._notify([ev])
        return ev

    def readings(self, job_id: int) -> list[ReadingRow]:
        with self._read() as db:
            rows = db.execute(
                "SELECT angle_index, commanded_deg, actual_deg, light, sensor, raw, dark, "
                "exposure_s, averages, saturated, t_read, range_index, range_scale FROM readings "
                "WHERE job_id = ? ORDER BY angle_index, light, sensor",
                (job_id,),
            ).fetchall()
        return [
            ReadingRow(r[0], r[1], r[2], r[3], r[4], tuple(json.loads(r[5])),
                       tuple(json.loads(r[6])), r[7], r[8], bool(r[9]), r[10], int(r[11]),
                       float(r[12]))
            for r in rows
        ]

    def reading_count(self, job_id: int) -> int:
        with self._read() as db:
            return int(db.execute(
                "SELECT COUNT(*) FROM readings WHERE job_id = ?", (job_id,)).fetchone()[0])

    # ------------------------------------------------------------------ holds
    def set_hold(self, name: str, reason: str, event: str | None = None,
                 data: dict[str, Any] | None = None) -> None:
        """Store hold ``name`` (replacing one of that name) and, in the same transaction, an
        ``event``: a hold survives any crash exactly when its event does."""
        with self._tx() as c:
            c.execute("INSERT OR REPLACE INTO holds (name, reason, since) VALUES (?, ?, ?)",
                      (name, reason, time.time()))
            ev = self._insert_event(c, None, event, data or {}) if event else None
        if ev is not None:
            self._notify([ev])

    def clear_hold(self, name: str, event: str | None = None,
                   data: dict[str, Any] | None = None) -> None:
        """Remove hold ``name`` (if set) and store ``event`` in the same transaction."""
        with self._tx() as c:
            c.execute("DELETE FROM holds WHERE name = ?", (name,))
            ev = self._insert_event(c, None, event, data or {}) if event else None
        if ev is not None:
            self._notify([ev])

    def hold(self, name: str) -> tuple[str, float] | None:
        """``(reason, since)`` of hold ``name`` (Unix time, seconds), or None."""
        with self._read() as db:
            row = db.execute("SELECT reason, since FROM holds WHERE name = ?", (name,)).fetchone()
        return None if row is None else (str(row[0]), float(row[1]))

    # ------------------------------------------------------------------ events
    def append_event(self, job_id: int | None, type_: str, data: dict[str, Any]) -> EventRow:
        with self._tx() as c:
            ev = self._insert_event(c, job_id, type_, data)
        self._notify([ev])
        return ev

    def has_event(self, job_id: int, type_: str) -> bool:
        """Whether the job has at least one event of this type (e.g. a warning recorded
        before a restart)."""
        with self._read() as db:
            row = db.execute("SELECT 1 FROM events WHERE job_id = ? AND type = ? LIMIT 1",
                             (job_id, type_)).fetchone()
        return row is not None

    def last_event(self, job_id: int, type_: str) -> EventRow | None:
        """The job's latest event of this type (e.g. the arc its scan chose), or None."""
        with self._read() as db:
            r = db.execute("SELECT seq, job_id, type, time, data FROM events WHERE job_id = ? "
                           "AND type = ? ORDER BY seq DESC LIMIT 1", (job_id, type_)).fetchone()
        return None if r is None else EventRow(r[0], r[1], r[2], r[3], json.loads(r[4]))

    def events_after(self, seq: int, limit: int = 1000, job_id: int | None = None
                     ) -> list[EventRow]:
        q = "SELECT seq, job_id, type, time, data FROM events WHERE seq > ?"
        args: list[Any] = [seq]
        if job_id is not None:
            q += " AND job_id = ?"
            args.append(job_id)
        q += " ORDER BY seq LIMIT ?"
        args.append(limit)
        with self._read() as db:
            rows = db.execute(q, args).fetchall()
        return [EventRow(r[0], r[1], r[2], r[3], json.loads(r[4])) for r in rows]

    def last_seq(self) -> int:
        with self._read() as db:
            return int(db.execute("SELECT COALESCE(MAX(seq), 0) FROM events").fetchone()[0])


def relative_result_path(job_id: int, path: str) -> str:
    """A stored result path as the data directory's own relative path.

    Finishing writes job N's result to ``results/job-N.h5`` in the data directory, and only
    there, so a path ending in those two parts is that file, whatever absolute or
    working-directory-relative prefix an older gonio stored it with. Other paths are kept.
    """
    parts = PurePath(path).parts
    own = ("results", f"job-{job_id}.h5")
    return "/".join(own) if tuple(parts[-2:]) == own else path


def relative_calibration_path(path: str) -> str:
    """A stored calibration path as the data directory's own (``calibration.json``)."""
    return "calibration.json" if PurePath(path).name == "calibration.json" else path


def _relative_summary(job_id: int, summary: dict[str, Any]) -> dict[str, Any]:
    """``summary`` with its ``result_path`` and ``calibration_path`` (when strings) in the
    data directory's relative form; other keys as they are."""
    out = dict(summary)
    if isinstance(out.get("result_path"), str):
        out["result_path"] = relative_result_path(job_id, out["result_path"])
    if isinstance(out.get("calibration_path"), str):
        out["calibration_path"] = relative_calibration_path(out["calibration_path"])
    return out


def _job_row(d: dict[str, Any]) -> JobRow:
    return JobRow(
        id=d["id"],
        state=JobState(d["state"]),
        kind=d["kind"],
        specimen=d["specimen"],
        priority=d["priority"],
        position=d["position"],
        created=d["created"],
        started=d["started"],
        finished=d["finished"],
        plan=json.loads(d["plan"]),
        rig=json.loads(d["rig"]),
        reason=d["reason"],
        result_path=d["result_path"],
        summary=json.loads(d["summary"]) if d["summary"] else None,
        done_angles=d["done_angles"],
        total_angles=d["total_angles"],
    )
