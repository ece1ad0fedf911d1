"""``gonio jobs``: inspect and act on a job store (``--db``, ``--data-dir``), or on a running
daemon's jobs through its API (``--daemon URL``, :mod:`gonio.cli.daemon_jobs`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from gonio.cli import UsageError
from gonio.cli.daemon_client import add_daemon_options


def register(subparsers: Any) -> None:
    j = subparsers.add_parser(
        "jobs", help="list, show or abort jobs in a job store, or rebuild a job's result file",
        description="list: the jobs; show ID: one job as the API's GET /api/v1/jobs/ID has it "
        "(--json: as JSON); abort ID: end one left "
        "unfinished (e.g. a foreground scan interrupted by Ctrl-C); rebuild ID: write a "
        "completed job's result file again from the readings the store holds (when the file "
        "is missing or damaged), with the calibration the job was finished with; a job that "
        "failed while it was being finished (a full disk, an error in reconstruction or the "
        "result writing) or was aborted then, with every reading stored, is finished again "
        "and completed so. "
        "With --daemon URL the jobs are a running daemon's, acted on through its API: list, "
        "show, abort (a running job too), cancel ID (take a queued job out of the queue), "
        "reorder ID --position N and/or --priority P (N=0: next), wait ID [-o FILE] (follow "
        "the job with a progress bar until it ends, saying while it is queued what it waits "
        "for and when it may start, then fetch its result to FILE and print "
        "the summary 'gonio scan' prints; e.g. a scan queued with 'gonio scan --daemon URL "
        "--no-wait', or one whose terminal was closed), pause ID and resume ID (at the end of "
        "the angle under way), remove ID (a queued or finished job and its readings), halt "
        "(the emergency halt: the running job stops at once, the queue is held) and release "
        "(queued jobs start again).")
    j.add_argument("action", nargs="?",
                   choices=["list", "show", "abort", "rebuild", "cancel", "reorder", "wait",
                            "pause", "resume", "remove", "halt", "release"],
                   default="list")
    j.add_argument("job_id", nargs="?", type=int)
    j.add_argument("--daemon", default=None, metavar="URL",
                   help="act through the running daemon at URL (it owns its job store), e.g. "
                        "http://127.0.0.1:8600; cancel, reorder and wait need it")
    add_daemon_options(j)
    j.add_argument("--position", type=int, default=None,
                   help="reorder: the job's new place among the queued jobs (0: next)")
    j.add_argument("--priority", type=int, default=None,
                   help="reorder: the job's new priority (higher runs first)")
    j.add_argument("--accept-uncalibrated", action="store_true",
                   help="reorder: move a scan ahead of a queued calibration all the same, to "
                        "measure in sensor units (the daemon refuses it otherwise)")
    j.add_argument("--db", type=Path, default=None,
                   help="job store (SQLite, DATA_DIR/gonio.sqlite), e.g. the one 'gonio scan' "
                        "prints, or the data directory holding it (required unless "
                        "--data-dir names it; without either the error lists the stores "
                        "found in the default data directories)")
    j.add_argument("--data-dir", type=Path, default=None,
                   help="the data directory ('gonio scan' prints it): its gonio.sqlite is "
                        "the store when --db is not given; the store's result paths are "
                        "relative to it (show: result_file; rebuild: its results/ gets the "
                        "file); default: the folder of --db")
    j.add_argument("-o", "--output", type=Path, default=None,
                   help="wait: write the completed job's result file here (a calibration job's "
                        "calibration beside it, as OUTPUT.calibration.json); without it the "
                        "result stays in the daemon")
    j.add_argument("--overwrite", action="store_true",
                   help="wait: replace an existing -o file (without it, refused before the wait)")
    j.add_argument("--no-progress", action="store_true", help="wait: no progress bar")
    j.add_argument("--json", action="store_true", help="machine-readable output")
    j.set_defaults(func=_jobs)


def _jobs(args: argparse.Namespace) -> int:
    from gonio.store import JobStore

    if args.action != "wait" and (args.output is not None or args.no_progress
                                  or args.overwrite):
        raise UsageError("-o, --overwrite and --no-progress go with wait (gonio jobs --daemon "
                         "URL wait ID -o FILE)")
    if args.daemon is not None:
        from gonio.cli.daemon_jobs import jobs_through_daemon

        return jobs_through_daemon(args)
    if args.action == "wait":
        raise UsageError(
            "jobs wait follows a job a daemon runs: give its address, e.g. 'gonio jobs --daemon "
            f"http://127.0.0.1:8600 wait {args.job_id if args.job_id is not None else 'ID'} "
            "-o FILE' (a job of a foreground 'gonio scan' is followed by that scan; run the same "
            "command again to resume one it left)")
    if args.action in ("cancel", "reorder", "pause", "resume", "remove", "halt", "release"):
        raise UsageError(
            f"jobs {args.action} acts on a daemon's queue: give its address, e.g. 'gonio jobs "
            f"--daemon http://127.0.0.1:8600 {args.action}"
            + ("" if args.action in ("halt", "release")
               else f" {args.job_id if args.job_id is not None else 'ID'}")
            + (" --position 0'" if args.action == "reorder" else "'")
            + " (the key in $GONIO_API_KEY or --api-key)")
    if args.db is None and args.data_dir is not None:
        # The data directory 'gonio scan' prints, given as --data-dir (as 'gonio scan' takes
        # it): its store, as there ('gonio jobs list --data-dir DIR' was refused, "--db is
        # required").
        from gonio.paths import STORE_NAME

        args.db = args.data_dir
        if not (args.data_dir / STORE_NAME).is_file():
            raise UsageError(f"--data-dir {args.data_dir} holds no job store ({STORE_NAME}): "
                             "give the data directory 'gonio scan' or 'gonio serve' printed, "
                             "or --db STORE")
    if args.db is None:
        raise UsageError(_no_store_text())
    if args.db.is_dir():
        # The data directory that gonio scan and gonio serve print, given for its store.
        from gonio.daemon import STORE_FILE

        if not (args.db / STORE_FILE).is_file():
            raise UsageError(f"{args.db} is a folder without a job store ({STORE_FILE}); "
                             "--db takes the store, DATA_DIR/gonio.sqlite")
        args.db = args.db / STORE_FILE
    if not args.db.is_file():
        raise UsageError(f"job store {args.db} does not exist")
    if args.action == "list" and args.job_id is not None:
        # 'gonio jobs list 3' listed every job without a word about the 3.
        raise UsageError(f"list takes no job id; 'gonio jobs show {args.job_id} --db "
                         f"{args.db}' shows job {args.job_id}")
    if args.action == "abort":
        return _abort_job(args)
    store = JobStore(args.db, durable=False)
    if args.action == "rebuild":
        return _rebuild(args, store)
    if args.action == "show":
        return _show_job(args, store)
    rows = store.list_jobs()
    waiting = _queue_wait(store, args.db, rows)
    if args.json:
        # The API's names (GET /api/v1/jobs, 'gonio jobs --daemon URL list --json') for what
        # a store holds: "done"/"total" here broke a script moved from one to the other.
        print(json.dumps([{"id": r.id, "state": r.state.value, "kind": r.kind,
                           "specimen": r.specimen, "priority": r.priority,
                           "created": r.created, "started": r.started, "finished": r.finished,
                           "done_angles": r.done_angles, "total_angles": r.total_angles,
                           # The names before 2026-11-29, kept for scripts written then.
                           "done": r.done_angles, "total": r.total_angles,
                           "reason": r.reason,
                           "waiting": waiting if r.state.value == "queued" else None}
                          for r in rows]))
        return 0
    print(f"{'id':>4}  {'state':<14} {'kind':<11} {'angles':>9}  {'created':<19}  specimen")
    for r in rows:
        created = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(r.created))
        why = waiting if r.state.value == "queued" else r.reason
        print(f"{r.id:>4}  {r.state.value:<14} {r.kind:<11} "
              f"{r.done_angles:>4}/{r.total_angles:<4}  {created}  {r.specimen}"
              + (f"  ({why})" if why else ""))
    note = _interrupted_note(args.db, rows)
    if note is not None:
        print(note)
    return 0


def _no_store_text() -> str:
    """What ``gonio jobs`` without ``--db`` says: where it looked, what it found, what to
    pass."""
    from gonio.paths import default_stores, store_places

    found = default_stores()
    how = ("pass --db DATA_DIR/gonio.sqlite (or the data directory), the data directory "
           "'gonio scan' or 'gonio serve' prints at start")
    if not found:
        return (f"which job store? --db is required, and none was found in the default places "
                f"({', '.join(store_places())}); {how} (a daemon with a data_dir in its "
                "config keeps its store there)")
    listed = "; ".join(f"--db {p}" for p in found)
    return (f"which job store? --db is required; the default places hold: {listed}. Pass one "
            "of them, or --db DATA_DIR/gonio.sqlite for another data directory")


def _show_job(args: argparse.Namespace, store: Any) -> int:
    """``gonio jobs show ID``: the job as ``GET /api/v1/jobs/{id}`` has it
    (:meth:`gonio.service_models.JobDetail.from_row`, the one assembly of a job's status),
    from the store: its queue position and why it waits, the angles an adaptive plan may
    measure, the finishing estimate of an active job. The engine's live ETA is the daemon's
    alone (null here); plus ``result_file``, the result's path on this machine."""
    from gonio.jobstates import ACTIVE_STATES
    from gonio.plans.dryrun import dry_run
    from gonio.plans.models import PlanError, parse_stored_plan
    from gonio.rigdescription import RigDescription
    from gonio.service_models import JobDetail
    from gonio.store import NotFound
    from gonio.timeleft import QueuedRun, finishing_estimate, most_channels, start_estimates

    if args.job_id is None:
        raise UsageError("jobs show needs a job id, e.g. 'gonio jobs show 3 --db jobs.sqlite'")
    try:
        row = store.get_job(args.job_id)
    except NotFound as exc:
        raise UsageError(str(exc)) from None
    # The store's lock, probed once: whether a daemon answers for the job, and whether an
    # active job is interrupted (it was probed a second time for the note).
    holder = _store_holder(args.db)
    live = _daemon_detail(holder, row.id)
    if live is not None:
        # A daemon runs this store: its answer has what only it knows (the live ETA, the
        # activity, the basis build), from the same JobDetail.from_row.
        return _print_detail(args, row, live, False)
    queued = row.state.value == "queued"
    max_angles = None
    if row.kind == "adaptive":
        try:
            max_angles = dry_run(parse_stored_plan(row.plan),
                                 RigDescription.model_validate(row.rig)).max_angles
        except (PlanError, ValueError):
            max_angles = None  # a plan or rig the code no longer reads: done/total only
    active = row.state in ACTIVE_STATES
    # Why a queued job waits needs the active jobs only, not the whole list again (every
    # job's plan and rig decoded, this one's a second time).
    waiting = (_queue_wait(store, args.db, [row, *store.list_jobs(ACTIVE_STATES)])
               if queued else None)
    # A queue that waits gives no start, in the daemon's words; when it runs, the estimate
    # rests on the running job's live time left, the daemon's alone (null here).
    start = (start_estimates(None, False, waiting, [QueuedRun(row.id, None)])[0]
             if waiting is not None else None)
    detail = JobDetail.from_row(
        row, max_angles, waiting,
        queue_position=store.queue_position(row.id) if queued else None,
        finishing=(finishing_estimate(store.list_jobs(["completed"]),
                                      most_channels(row.rig))
                   if active and row.kind != "calibration" else None), start=start)
    # A paused job waits for the user whether or not a process holds the store.
    interrupted = holder is None and row.state.value in ("running", "suspended",
                                                         "reconstructing")
    return _print_detail(args, row, detail.model_dump(mode="json"), interrupted)


def _print_detail(args: argparse.Namespace, row: Any, d: dict[str, Any],
                  interrupted: bool) -> int:
    """Print a job's detail ``d`` (as JSON with --json), with ``result_file``, and when
    ``interrupted`` (an active job no process runs) the note saying so."""
    if row.result_path:
        # The store's path is relative to the data directory (docs/engine.md).
        data_dir = args.data_dir if args.data_dir is not None else args.db.resolve().parent
        d["result_file"] = str((data_dir / row.result_path).resolve())
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    for line in detail_lines(d):
        print(line)
    if interrupted:
        print(_interrupted_text(args.db, [row]))
    return 0


def _store_holder(db: Path) -> dict[str, Any] | None:
    """The record of the process that holds the store ``db``'s lock (a daemon, a ``gonio
    scan``; possibly empty when unreadable), or None when none does. A store whose lock
    cannot be probed (no write access to its folder) counts as held: nothing can be said of
    who runs it, so nothing is called interrupted."""
    from gonio.locks import LockBusy, claim_store

    try:
        claim_store(db).release()
        return None
    except LockBusy as exc:
        return dict(exc.holder)
    except OSError:
        return {}


def _daemon_detail(holder: dict[str, Any] | None, job_id: int) -> dict[str, Any] | None:
    """``GET /api/v1/jobs/{job_id}`` of the daemon that runs jobs from the store whose lock
    ``holder`` holds (the address it records, :func:`gonio.locks.advertise_url`); None when
    no daemon holds the store (or a ``gonio scan`` does) or it does not answer."""
    from gonio.cli.daemon_client import DaemonClient

    url = (holder or {}).get("url")
    if not isinstance(url, str) or not url:
        return None
    try:
        with DaemonClient(url, timeout_s=10.0) as client:
            got = client.request("GET", f"/api/v1/jobs/{job_id}")
    except (UsageError, OSError) as exc:
        print(f"note: the daemon at {url} did not answer ({exc}); the job as stored:",
              file=sys.stderr)
        return None
    return got if isinstance(got, dict) else None


def detail_lines(d: dict[str, Any]) -> list[str]:
    """A job's detail (``GET /api/v1/jobs/{id}``'s fields) as lines for a terminal."""
    def when(t: float | None) -> str:
        return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(t)) if t else "-"

    angles = f"{d['done_angles']}/{d['total_angles']} angles"
    if d.get("max_angles") is not None:
        angles += f" (at most {d['max_angles']})"
    lines = [f"job {d['id']}: {d['kind']} '{d['specimen']}', {d['state']}, {angles}, "
             f"priority {d['priority']}",
             f"  created {when(d['created'])}, started {when(d['started'])}, "
             f"finished {when(d['finished'])}"]
    if d.get("queue_position") is not None:
        lines.append(f"  queue position: {d['queue_position']} (0 = next)")
    if d.get("waiting"):
        lines.append(f"  waiting: {d['waiting']}")
    if d.get("start_refusal"):
        lines.append(f"  {d['start_refusal']}")
    if d.get("reason"):
        lines.append(f"  reason: {d['reason']}")
    if d.get("activity"):
        lines.append(f"  activity: {d['activity']}")
    if d.get("eta_s") is not None:
        lines.append(f"  measuring left: {d['eta_s']:.0f} s")
    if d.get("reconstruction_s") is not None:
        lines.append(f"  finishing: about {d['reconstruction_s']:.0f} s "
                     f"({d['reconstruction_estimate']})")
    if d.get("basis_build_s") is not None:
        lines.append(f"  basis build first: about {d['basis_build_s']:.0f} s")
    if d.get("time_left_s") is not None:
        lines.append(f"  time left in all: about {d['time_left_s']:.0f} s")
    if d.get("result_file"):
        lines.append(f"  result: {d['result_file']}")
    lines.extend(_result_lines(d))
    lines.append("  (--json: every field, as GET /api/v1/jobs/ID)")
    return lines


def _result_lines(d: dict[str, Any]) -> list[str]:
    """What a completed scan measured, as ``gonio scan`` said it at the end: its samples and
    headline error (``predicted_log_rmse``, marked when outside physical bounds), the
    calibration and the result's warnings. Only ``--json`` had them."""
    from gonio.cli.scan_report import result_headline, scan_summary

    summary = d.get("result")
    if d.get("state") != "completed" or d.get("kind") == "calibration" or not summary:
        return []
    lines = [f"  measured: {result_headline(summary)}"]
    # The end-of-scan summary's other lines (calibration, local prior, arc, warnings), but
    # the paragraph on what the error means: the scan said it, and the page and --json do.
    meaning = {f"  {key}:" for key in ("predicted_log_rmse", "predicted_error")}
    for line, _warning in scan_summary(d["id"], summary, None, "")[1:]:
        if not any(line.startswith(m) for m in meaning):
            lines.append(line if line.startswith("  ") else f"  {line}")
    return lines


def _queue_wait(store: Any, db: Path, rows: list[Any]) -> str | None:
    """Why the store's queued jobs do not start (:func:`gonio.jobstates.queue_wait`, as the
    API's ``waiting`` and the lab page say it): its stored queue hold, the maintenance lock of
    its data directory, or a paused or suspended job."""
    from gonio.jobstates import ACTIVE_STATES, QUEUE_HOLD, queue_wait
    from gonio.maintenance import LOCK_FILE_NAME, MaintenanceLock

    if not any(r.state.value == "queued" for r in rows):
        return None
    hold = store.hold(QUEUE_HOLD)
    maintenance = MaintenanceLock(db.resolve().parent / LOCK_FILE_NAME).reason()
    said = queue_wait(((r.id, r.state) for r in rows if r.state in ACTIVE_STATES),
                      hold[0] if hold is not None else None, maintenance)
    if said is not None or _store_holder(db) is not None:
        return said
    # Nothing runs jobs from the store (a daemon stopped or killed): the queued ones showed
    # no reason at all, as if they were about to start.
    return ("no daemon runs this store now: queued jobs start when a daemon ('gonio serve') "
            "runs it again (after the jobs it takes up again)")


def _interrupted_note(db: Path, rows: list[Any]) -> str | None:
    """What the list's 'running' (or suspended, reconstructing) means when no process runs
    jobs from the store: the job was interrupted (a daemon stopped, SIGTERM or kill -9; a
    gonio scan killed) and waits for the next one. When a daemon runs the store and jobs are
    queued: where to ask it when they start (the store alone cannot say: the time left of the
    job under way is the daemon's). None when there is nothing to say."""
    from gonio.locks import LockBusy, claim_store

    active = [r for r in rows if r.state.value in ("running", "suspended", "reconstructing")]
    queued = any(r.state.value == "queued" for r in rows)
    if not active and not queued:
        return None
    try:
        claim_store(db).release()
    except LockBusy as exc:
        # A daemon or a gonio scan runs them: the states are live.
        url = exc.holder.get("url") if isinstance(exc.holder, dict) else None
        if not queued or not isinstance(url, str) or not url:
            return None
        url = url.rstrip("/")
        return (f"note: the daemon at {url} runs this store; 'gonio jobs --daemon {url} list' "
                "adds when each queued job may start")
    except OSError:
        return None  # cannot tell (no write access to the store's directory)
    return _interrupted_text(db, active) if active else None


def _interrupted_text(db: Path, active: list[Any]) -> str:
    """The note on ``active`` jobs (running, suspended, reconstructing) that no process runs
    from the store ``db``: they were interrupted, and what happens to them next."""
    ids = ", ".join(str(r.id) for r in active)
    return (f"note: no daemon or gonio scan runs jobs from this store now, so nothing goes on "
            f"with job(s) {ids} above: they were interrupted (a stopped or killed process). "
            "The next 'gonio serve' on this data directory takes them up again (measuring "
            "from the checkpoint, or reconstructing from the stored readings; a gonio scan's "
            f"job: the same command again); 'gonio jobs abort ID --db {db}' ends one instead")


def _rebuild(args: argparse.Namespace, store: Any) -> int:
    """``gonio jobs rebuild ID``: :func:`gonio.finishing.rebuild_result`, reported."""
    from gonio.basis_supply import BasisSupply
    from gonio.finishing import completes_unfinished, rebuild_result
    from gonio.store import NotFound

    if args.job_id is None:
        raise UsageError("jobs rebuild needs a job id, e.g. 'gonio jobs rebuild 3 --db "
                         "DATA/gonio.sqlite'")
    data_dir = args.data_dir if args.data_dir is not None else args.db.resolve().parent
    try:
        before = store.get_job(args.job_id).state
    except NotFound as exc:
        raise UsageError(str(exc)) from None
    if before.value in ("completed", "failed", "aborted"):
        # Only these may be rebuilt (rebuild_result refuses the others, saying why): the line
        # said "rebuilding" before the refusal of a paused job.
        print(f"rebuilding job {args.job_id}'s result from the job store's readings",
              file=sys.stderr)
    old = store.get_job(args.job_id).summary or {}
    lock = None
    if before.value != "completed" and completes_unfinished(store, args.job_id):
        # Completing a failed or aborted job changes its state (and a calibration job's, the
        # calibration in effect): not under a daemon or scan that runs this store.
        from gonio.locks import LockBusy, claim_store

        try:
            lock = claim_store(args.db)
        except LockBusy as exc:
            article = "an" if before.value[:1] in "aeiou" else "a"
            raise UsageError(f"{exc}; {article} {before.value} job is rebuilt only in a job "
                             "store no daemon or scan runs: stop it, rebuild, then start it "
                             "again") from None
    try:
        summary = rebuild_result(store, data_dir, args.job_id, BasisSupply())
    finally:
        if lock is not None:
            lock.release()
    after = store.get_job(args.job_id).state
    print(f"job {args.job_id}: wrote {data_dir / summary['result_path']} from "
          f"{summary['readings']} stored readings"
          + (" (calibrated, 1/sr)" if summary.get("calibrated") else " (sensor units)")
          + (f"; it was {before.value} and is {after.value} now" if after != before else ""))
    line = design_comparison_line(summary)
    if line is not None:
        print(line)
    if (line := rebuild_change_line(old, summary)) is not None:
        print(line)
    return 0


def rebuild_change_line(old: dict[str, Any], new: dict[str, Any]) -> str | None:
    """What ``gonio jobs rebuild`` says when the rebuilt result is not the one the job was
    finished with: the readings and calibration are the same, but the default basis is built
    from today's library, so a table imported since can become the fit's local prior
    (docs/library.md) and move the numbers. None when the prior is the same (or the job had
    no summary to compare with)."""
    if not old or old.get("local_prior") == new.get("local_prior"):
        return None
    was, now = old.get("local_prior"), new.get("local_prior")
    prior = (f"it now leans on {now!r} where no pair looks" if now is not None
             else "it no longer leans on a local prior")
    before = f"; it leaned on {was!r}" if was is not None and now is not None else (
        f" (it leaned on {was!r})" if was is not None else "")
    old_err, new_err = old.get("predicted_log_rmse"), new.get("predicted_log_rmse")
    err = (f"; predicted_log_rmse {old_err:.4f} -> {new_err:.4f}"
           if isinstance(old_err, int | float) and isinstance(new_err, int | float) else "")
    return (f"note: not the result the job was finished with: the basis is built from today's "
            f"library (gonio library list), and {prior}{before}{err}")


def design_comparison_line(summary: dict[str, Any]) -> str | None:
    """What ``gonio jobs rebuild`` says of a rebuilt result's design comparison: why it is not
    available (a job finished by an older gonio whose rig config is lost), the gap when there
    is one, or None (no gap, or no ``[design]`` on the rig)."""
    why = summary.get("design_comparison") or summary.get("design_gap")
    return f"design comparison: {why}" if why else None


def _abort_job(args: argparse.Namespace) -> int:
    """``gonio jobs abort ID --db DB``: end an unfinished job in a store nobody runs now."""
    from gonio.jobstates import IllegalTransition, JobState
    from gonio.locks import LockBusy, claim_store
    from gonio.store import JobStore, NotFound

    if args.job_id is None:
        raise UsageError("jobs abort needs a job id, e.g. 'gonio jobs abort 3 --db jobs.sqlite'")
    try:
        # A daemon or a gonio scan running jobs from this store would not see the change:
        # act through it instead (its API, or Ctrl-C).
        lock = claim_store(args.db)
    except LockBusy as exc:
        url = exc.holder.get("url") if isinstance(exc.holder, dict) else None
        through = (f" (through it: 'gonio jobs --daemon {str(url).rstrip('/')} abort "
                   f"{args.job_id}')" if url else "")
        raise UsageError(f"{exc}{through}") from None
    from gonio.finishing import rebuild_hint

    with lock:
        store = JobStore(args.db)
        try:
            before = store.get_job(args.job_id).state
            row = store.set_state(args.job_id, JobState.ABORTED, reason="aborted by request "
                                  "(gonio jobs abort)")
            # A job left being finished (its daemon or scan died then) has every reading:
            # its result can still be made, which the abort must not hide.
            hint = (rebuild_hint(store, row.id, args.data_dir)
                    if before is JobState.RECONSTRUCTING else None)
        except NotFound as exc:
            raise UsageError(str(exc)) from None
        except IllegalTransition:
            state = store.get_job(args.job_id).state.value
            raise UsageError(f"job {args.job_id} is {state}: only an unfinished job can be "
                             "aborted") from None
        finally:
            store.close()
    print(f"job {row.id} aborted ({row.done_angles} of {row.total_angles} angles had been "
          "measured; its readings stay in the store)")
    if hint is not None:
        print(f"it was being finished: {hint}")
    return 0
