"""Jobs on a running daemon from the command line: ``gonio scan --daemon URL`` queues one and
follows it, ``gonio jobs --daemon URL ACTION`` lists, shows, aborts, cancels, reorders or waits
for them, all through the daemon's REST API (:class:`gonio.cli.daemon_client.DaemonClient`).

Following a job and fetching its result is one function, :func:`follow_and_fetch`, for both
``gonio scan --daemon`` and ``gonio jobs --daemon URL wait ID``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from gonio.cli import UsageError
from gonio.cli.daemon_client import (
    DaemonClient,
    DaemonRefused,
    DaemonUnreachable,
)
from gonio.cli.scan_report import (
    FINAL_STATES,
    HOLDING_STATES,
    appeared_text,
    calibration_copy_path,
    check_output_path,
    dry_run_summary,
    print_scan_summary,
    queued_line,
    resumed_line,
    start_text,
    suspended_line,
    write_output,
)


def scan_through_daemon(args: argparse.Namespace, plan: Any) -> int:
    """Queue ``plan`` on a daemon, follow it to its end, fetch its result file
    (:func:`follow_and_fetch`); with ``--no-wait``, return once it is queued, printing the
    ``gonio jobs --daemon URL wait ID -o FILE`` that does the rest.

    The daemon owns the rig, its job store and its calibration: the job runs in its queue like
    any other (visible on the lab page), with the calibration in effect there. Ctrl-C stops
    following, not the job.
    """
    for flag, given in (("--db", args.db), ("--data-dir", args.data_dir),
                        ("--calibration", args.calibration)):
        if given is not None:
            raise UsageError(
                f"{flag} does not apply with --daemon: the daemon keeps its own data directory "
                "and job store and applies its own calibration (calibrate it with "
                "--white-reference ALBEDO)")
    body = {"plan": plan.model_dump(mode="json")}
    with DaemonClient(args.daemon, args.api_key) as client:
        if args.dry_run:
            from gonio.plans.dryrun import DryRun

            answer = client.request("POST", "/api/v1/jobs/dry-run", json=body)
            rig = client.request("GET", "/api/v1/rig")
            print(json.dumps(answer, indent=2) if args.json else dry_run_summary(
                DryRun.model_validate(answer), plan, str(rig.get("name", "rig"))))
            return 0
        if args.json and not args.no_wait:
            raise UsageError("--json goes with --dry-run or --no-wait (a followed scan prints "
                             "its summary; 'gonio jobs --daemon URL show ID --json' gives the "
                             "job as JSON)")
        # The plan's warnings (the daemon records them in the job's events, which this command
        # does not follow), said before it is queued; a daemon without them sends none.
        checked = client.request("POST", "/api/v1/jobs/dry-run", json=body)
        for warning in checked.get("warnings", []) if isinstance(checked, dict) else []:
            print(f"warning: {warning}", file=sys.stderr)
        try:
            job = client.request("POST", "/api/v1/jobs", json=body, params={
                "accept_uncalibrated": "true"} if args.accept_uncalibrated else None)
        except DaemonRefused as exc:
            if exc.status == 409 and "accept_uncalibrated" in str(exc):
                raise UsageError(f"{exc} (here: --accept-uncalibrated)") from None
            raise
        job_id = int(job["id"])
        if args.no_wait and args.json:
            # A script queueing jobs gets the daemon's answer (the job's row: its id, state,
            # queue place), not a sentence to parse for the id.
            print(json.dumps(job))
            return 0
        if args.no_wait:
            out = args.output or Path(_suggested_output(job_id, job.get("specimen")))
            print(f"job {job_id} queued on {client.url}; follow it and fetch its result "
                  f"with:\n  {wait_command(client.url, job_id, out)}")
            return 0
        print(f"job {job_id} queued on {client.url}", file=sys.stderr)
        # What the daemon said of the job, kept for a message if it goes away: its queueing
        # answer at first, then every poll's.
        return follow_and_fetch(client, job_id, args.output, no_progress=args.no_progress,
                                overwrite=args.overwrite, seen=dict(job), queued_here=True)


def _suggested_output(job_id: int, specimen: Any) -> str:
    """The result file ``gonio scan --daemon --no-wait`` without ``-o`` suggests: the
    specimen's name when it makes a plain file name, else the job's."""
    import re

    from gonio.export.metadata import UNNAMED

    name = str(specimen or "")
    if name and name != UNNAMED and re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", name):
        return f"{name}.h5"
    return f"job-{job_id}.h5"


def wait_command(url: str, job_id: int, out: Path | None) -> str:
    """The command that follows daemon job ``job_id`` and fetches its result to ``out``
    (``gonio jobs --daemon URL wait ID -o FILE``; without ``-o`` when ``out`` is None), with
    ``out`` absolute, so it works from another terminal's folder too. It names no API key
    (reads need none unless the daemon says so; the key stays out of shell history), and
    ``--overwrite`` when ``out`` exists (the command would be refused without it)."""
    import shlex

    cmd = f"gonio jobs --daemon {shlex.quote(url)} wait {job_id}"
    if out is None:
        return cmd
    # A file there already (the user said --overwrite) would refuse the command otherwise.
    again = " --overwrite" if Path(out).is_file() else ""
    return f"{cmd} -o {shlex.quote(str(Path(out).absolute()))}{again}"


def follow_and_fetch(client: DaemonClient, job_id: int, out: Path | None, *, no_progress: bool,
                     overwrite: bool = False,
                     seen: dict[str, Any] | None = None, queued_here: bool = False) -> int:
    """Follow daemon job ``job_id`` to its end with a progress bar, fetch its result to
    ``out`` and print the summary ``gonio scan`` prints; the exit status.

    One path for ``gonio scan --daemon`` (after it queued the job) and ``gonio jobs --daemon
    URL wait ID``, so a scan followed from the terminal that queued it and one picked up again
    later end alike. Ctrl-C and a daemon that stops answering stop the following, not the job:
    both print the ``gonio jobs --daemon URL wait ID -o FILE`` that takes it up again.

    Parameters
    ----------
    client : the daemon's client
    job_id : the job to follow
    out : where its result file goes (``-o``, checked writable by the caller); None: not
        fetched, the summary says where the daemon keeps it
    no_progress : no progress bar
    overwrite : ``--overwrite``: a file that appeared at ``out`` while the job ran (and its
        calibration copy's) is replaced; without it, refused (:func:`write_output`)
    seen : what the daemon last said of the job (its queueing answer); None when nothing yet
    queued_here : the command queued the job (running it again queues a second scan)

    Returns
    -------
    int
        0 completed (and fetched, with ``out``); 1 ended otherwise, or the daemon stopped
        answering; 130 Ctrl-C.

    Raises
    ------
    DaemonUnreachable
        The daemon never answered (a wrong address, or it is down) while nothing of the job
        had been seen.
    DaemonRefused
        It refused (no such job, a key needed).
    """
    again = wait_command(client.url, job_id, out)
    last: dict[str, Any] = dict(seen or {})
    try:
        row = _follow(client, job_id, disabled=no_progress, seen=last)
        if row["state"] != "completed":
            print(f"job {job_id} {row['state']}: {row.get('reason')}", file=sys.stderr)
            return 1
        if out is not None:
            _fetch_result(client, job_id, out, overwrite=overwrite)
        if row.get("kind") == "calibration":
            _calibration_fetched(client, job_id, out, overwrite=overwrite)
            return 0
    except DaemonUnreachable as exc:
        if not last:
            raise
        print(lost_daemon_message(client.url, job_id, last, str(exc), again, queued_here),
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if last.get("state") == "completed" and out is not None:
            # Stopped while its result was fetched: the job is done, nothing goes on.
            print(f"stopped fetching; job {job_id} is completed and the daemon keeps its "
                  f"result: fetch it with {again}", file=sys.stderr)
            return 130
        then = ("follow it and fetch its result with" if out is not None
                else "follow it again with")
        then = (f"Do not run this command again, which would queue a second scan; {then}"
                if queued_here else then.capitalize())
        print(f"stopped following; job {job_id} goes on in the daemon. {then}: {again}",
              file=sys.stderr)
        return 130
    where = f"the daemon keeps it: {client.url}/api/v1/jobs/{job_id}/result"
    print_scan_summary(job_id, row.get("result") or {}, out,
                       where if out is not None else f"not fetched ({where}; "
                       f"'{wait_command(client.url, job_id, None)} -o FILE' fetches it)")
    return 0


def _fetch_result(client: DaemonClient, job_id: int, out: Path, *,
                  overwrite: bool = False) -> None:
    """Write completed job ``job_id``'s result file, as the daemon serves it, to ``out``
    (:func:`write_output`: whole or not at all, so a fetch cut short leaves no truncated file
    under that name; a file that appeared there since the start's check is replaced only with
    ``overwrite``); when that fails, say that the daemon keeps it and how to fetch it
    elsewhere."""
    result = client.request("GET", f"/api/v1/jobs/{job_id}/result")
    try:
        write_output(out, result.content, overwrite=overwrite)
    except FileExistsError:
        # The command names --overwrite: the file is there now.
        raise UsageError(appeared_text(out, job_id, "the daemon keeps the result: fetch it "
                                       "with " + wait_command(client.url, job_id, out)
                                       + ", or to another -o")) from None
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise UsageError(f"job {job_id} completed, but its result could not be written to "
                         f"{out} ({why}); the daemon keeps it: fetch it elsewhere with "
                         f"'{wait_command(client.url, job_id, None)} -o FILE'") from None


def _calibration_fetched(client: DaemonClient, job_id: int, out: Path | None, *,
                         overwrite: bool = False) -> None:
    """Print what completed calibration job ``job_id`` left, and with ``out`` (its fetched
    result) write that job's calibration beside it as ``OUT.calibration.json``.

    The copy is the calibration the job made, as its result file records it, not the one the
    daemon applies now: a job waited for after a later calibration would otherwise copy that
    later one under this job's name.
    """
    now = client.request("GET", "/api/v1/calibration")
    source = now.get("source", "") if isinstance(now, dict) else ""
    applies = ("the daemon now applies this calibration to its scans"
               if source.startswith(f"job {job_id}:") else
               f"the daemon applies another calibration now ({source or 'none'})")
    if out is None:
        print(f"job {job_id} completed: {applies}; '{wait_command(client.url, job_id, None)} "
              "-o FILE' fetches its result and a copy of its calibration")
        return
    from gonio.results import read_provenance

    made = read_provenance(out).get("new_calibration")
    if made is None and source.startswith(f"job {job_id}:"):
        made = json.dumps(now)  # a result without its calibration (made before it was kept)
    if made is None:
        print(f"job {job_id} completed: {applies}; its result does not record its calibration, "
              f"so no copy was written beside {out}")
        return
    cal_out = calibration_copy_path(out)
    try:
        write_output(cal_out, json.dumps(json.loads(made), indent=2).encode(),
                     overwrite=overwrite)
    except FileExistsError:
        raise UsageError(appeared_text(cal_out, job_id, f"its result is in {out}, which "
                                       "records the calibration too")) from None
    print(f"job {job_id} completed: {applies}; a copy is in {cal_out}")


def lost_daemon_message(url: str, job_id: int, seen: dict[str, Any], why: str, again: str,
                        queued_here: bool = True) -> str:
    """What ``gonio scan --daemon`` and ``gonio jobs --daemon URL wait`` say when their daemon
    stops answering while they follow a job.

    It said only that the daemon could not be reached, so a user whose daemon was killed
    mid-scan could not tell that the job was kept (and resumes when the daemon restarts) and
    ran the command again, queueing a second scan of the specimen. It then pointed at the
    API's URLs; it names the command that takes the job up again.

    Parameters
    ----------
    url : the daemon's address
    job_id : the job followed
    seen : the job's detail as last answered (empty if none came)
    why : the connection error's message
    again : the command that follows the job and fetches its result (:func:`wait_command`)
    queued_here : the command queued the job (``gonio scan --daemon``): running it again would
        queue a second scan
    """
    when = (f" (last seen {seen['state']}, {seen.get('done_angles', 0)} of "
            f"{seen.get('total_angles') or '?'} angles)" if seen else "")
    then = ("Do not run this command again, which would queue a second scan; once the daemon "
            "answers, follow the job and fetch its result with: " if queued_here else
            "Once the daemon answers, run this command again: ")
    return (f"{why}\n"
            f"  job {job_id}{when} is kept in the daemon's job store: a restarted daemon (gonio "
            f"serve on the same data directory) takes it up again, a scan under way from its last "
            f"checkpoint. {then}{again} (or follow it on the lab page at {url})")


def holding_jobs(client: Any) -> list[dict[str, Any]]:
    """The daemon's jobs that hold the rig (:data:`HOLDING_STATES`), one filtered job list
    per state: what :func:`queued_line` needs, without the whole job list, which a store of
    many thousands of jobs answers slowly (each queued job's start estimate included), every
    half second while a job waits."""
    return [job for state in HOLDING_STATES
            for job in client.request("GET", "/api/v1/jobs", params={"state": state})]


def _follow(client: Any, job_id: int, disabled: bool, poll_s: float = 0.5,
            seen: dict[str, Any] | None = None) -> dict[str, Any]:
    """Poll the job with a progress bar until it ends; returns its last detail (``seen``, when
    given, holds the last detail answered, for a message if the daemon goes away)."""
    from tqdm import tqdm

    # The first answer before the bar: a job the daemon does not have (gonio jobs wait 99)
    # is refused without an empty bar above the refusal.
    row: dict[str, Any] = client.request("GET", f"/api/v1/jobs/{job_id}")
    if row["state"] in FINAL_STATES:
        # Ended already: no bar (it printed a full bar at millions of angles per second,
        # after the summary, for a job that ended long ago).
        if seen is not None:
            seen.update(row)
        return row
    bar = tqdm(total=None, unit="angle", desc=f"job {job_id}", disable=disabled, file=sys.stderr)
    told: str | None = None
    queued_told: tuple[Any, ...] | None = None
    try:
        while True:
            if seen is not None:
                seen.clear()
                seen.update(row)
            bar.total = row.get("total_angles") or None
            bar.n = int(row.get("done_angles") or 0)
            bar.set_description_str(f"job {job_id} {row['state']}")
            bar.refresh()
            reason = row.get("reason") if row["state"] == "suspended" else None
            if reason and reason != told:
                bar.write(suspended_line(job_id, reason, through_daemon=True),
                          file=sys.stderr)
            elif told and row["state"] == "running":
                bar.write(resumed_line(job_id), file=sys.stderr)
            told = reason
            if row["state"] == "queued":
                # Why it waits, said once and again when that changes (the bar sits at 0).
                key, line = queued_line(job_id, row, holding_jobs(client))
                if key != queued_told:
                    bar.write(line, file=sys.stderr)
                queued_told = key
            if row["state"] in FINAL_STATES:
                return row
            time.sleep(poll_s)
            row = client.request("GET", f"/api/v1/jobs/{job_id}")
    finally:
        bar.close()


def _queue_place(args: argparse.Namespace, job: int) -> str | None:
    """Job ``job``'s place in the daemon's queue in words ("next", "3rd"), or None when it is
    not queued or the daemon does not say."""
    with DaemonClient(args.daemon, args.api_key) as client:
        at = client.request("GET", f"/api/v1/jobs/{job}").get("queue_position")
    if not isinstance(at, int):
        return None
    return "next" if at == 0 else ordinal(at + 1)


def ordinal(n: int) -> str:
    """``n`` as an English ordinal: 1st, 2nd, 3rd, 4th, 11th, 12th, 13th, 21st, 112th."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def _say_start_refusals(client: DaemonClient) -> None:
    """Print, after a job left the queue, each queued scan the worker would now refuse when
    it starts (the job list's ``start_refusal``).

    A calibration job cancelled or removed can leave a scan queued behind it to start under
    a calibration at another exposure; the rows said so from then on, but the command that
    caused it said only "cancelled", and the scan failed "not started" overnight.
    """
    try:
        rows = client.request("GET", "/api/v1/jobs")
    except UsageError:  # refused or unreachable (DaemonRefused, DaemonUnreachable)
        return  # the action itself was done; the daemon's rows say the rest
    for row in rows if isinstance(rows, list) else []:
        if isinstance(row, dict) and row.get("start_refusal"):
            print(f"note: job {row['id']} {row['start_refusal']}", file=sys.stderr)


def _queue_action(args: argparse.Namespace) -> int:
    """``gonio jobs --daemon URL halt|release``: the emergency halt (the running job stops at
    once, the queue is held) and its release, as the page's buttons and ``POST
    /api/v1/rig/halt|release``."""
    with DaemonClient(args.daemon, args.api_key) as client:
        answer = client.request("POST", f"/api/v1/rig/{args.action}")
    if args.json:
        print(json.dumps(answer))
    elif args.action == "halt":
        print(f"halted: a job under way stopped where it stood (there may have been none) "
              f"and the queue is held; "
              f"'gonio jobs --daemon {args.daemon} release' lets queued jobs start again")
    else:
        print("released: queued jobs start again")
    return 0


def jobs_through_daemon(args: argparse.Namespace) -> int:
    """``gonio jobs --daemon URL ACTION [ID]``: a running daemon's jobs through its API.

    A lab whose daemon owns the store had the page or curl alone to cancel or reorder a
    queued scan or abort a running one: ``gonio jobs abort`` on that store is refused (two
    programs must not run jobs from one store) and said "use its API" without saying how.
    """
    if args.db is not None or args.data_dir is not None:
        raise UsageError("--db and --data-dir do not apply with --daemon: the daemon keeps its "
                         "own job store")
    if args.action == "rebuild":
        raise UsageError("rebuild works on a job store, not through a daemon: run 'gonio jobs "
                         "rebuild ID --db DATA_DIR' on the daemon's data directory (a "
                         "completed job's, with the daemon running: it serves the rebuilt file; "
                         "a failed job's, with the daemon stopped)")
    if args.action != "reorder" and (args.position is not None or args.priority is not None
                                     or args.accept_uncalibrated):
        raise UsageError("--position, --priority and --accept-uncalibrated go with reorder")
    if args.action in ("halt", "release"):
        if args.job_id is not None:
            raise UsageError(f"{args.action} acts on the whole queue and takes no job id "
                             f"('gonio jobs --daemon {args.daemon} {args.action}')")
        return _queue_action(args)
    if args.action == "list":
        if args.job_id is not None:
            raise UsageError(f"list takes no job id; 'gonio jobs --daemon {args.daemon} show "
                             f"{args.job_id}' shows job {args.job_id}")
    elif args.job_id is None:
        raise UsageError(f"jobs {args.action} needs a job id, e.g. 'gonio jobs --daemon "
                         f"{args.daemon} {args.action} 3'")
    with DaemonClient(args.daemon, args.api_key) as client:
        if args.action == "list":
            rows = client.request("GET", "/api/v1/jobs")
            if args.json:
                print(json.dumps(rows))
                return 0
            print(f"{'id':>4}  {'state':<14} {'kind':<11} {'angles':>9}  specimen")
            for r in rows:
                why = r.get("waiting") or r.get("reason")
                if isinstance(why, dict):
                    why = why.get("reason") or why.get("message")
                said = "; ".join(w for w in (why, start_text(r), r.get("start_refusal")) if w)
                print(f"{r['id']:>4}  {r['state']:<14} {r['kind']:<11} "
                      f"{r['done_angles']:>4}/{r['total_angles']:<4}  {r['specimen']}"
                      + (f"  ({said})" if said else ""))
            return 0
        job = args.job_id
        assert job is not None  # refused above
        if args.action == "wait":
            if args.json:
                raise UsageError(f"wait prints the scan's summary; 'gonio jobs --daemon "
                                 f"{args.daemon} show {job} --json' gives the job as JSON")
            if args.output is not None:
                # Before the wait, not after an hour's scan.
                kind = (None if args.overwrite
                        else client.request("GET", f"/api/v1/jobs/{job}").get("kind"))
                check_output_path(args.output, "nothing was fetched; the daemon keeps the job",
                                  overwrite=args.overwrite, calibration=kind == "calibration",
                                  names_specimen=False)
            return follow_and_fetch(client, job, args.output, no_progress=args.no_progress,
                                    overwrite=args.overwrite)
        if args.action == "show":
            row = client.request("GET", f"/api/v1/jobs/{job}")
            if args.json:
                print(json.dumps(row, indent=2))
                return 0
            from gonio.cli.jobs_command import detail_lines

            # The lines `gonio jobs show` prints from a store, with where the result is.
            if row["state"] == "completed":
                row = {**row, "result_file": (
                    f"{args.daemon.rstrip('/')}/api/v1/jobs/{job}/result (fetch it: "
                    f"{wait_command(client.url, job, None)} -o FILE)")}
            for line in detail_lines(row):
                print(line)
            return 0
        if args.action == "reorder":
            if args.position is None and args.priority is None:
                raise UsageError("reorder needs --position N (0: next) and/or --priority P")
            body = {k: v for k, v in (("position", args.position),
                                      ("priority", args.priority)) if v is not None}
            try:
                row = client.request("POST", f"/api/v1/jobs/{job}/reorder", json=body,
                                     params={"accept_uncalibrated": "true"}
                                     if args.accept_uncalibrated else None)
            except DaemonRefused as exc:
                if exc.status == 409 and "accept_uncalibrated" in str(exc):
                    raise UsageError(f"{exc} (here: --accept-uncalibrated)") from None
                raise
        elif args.action == "remove":
            client.request("DELETE", f"/api/v1/jobs/{job}")
            if args.json:
                # The API answers 204 with no body; a script still gets one JSON object.
                print(json.dumps({"id": job, "removed": True}))
                _say_start_refusals(client)  # on stderr: stdout stays one JSON object
                return 0
            print(f"job {job} removed with its readings (a result file it wrote stays in the "
                  "daemon's data directory)")
            _say_start_refusals(client)
            return 0
        else:
            try:
                row = client.request("POST", f"/api/v1/jobs/{job}/{args.action}")
            except DaemonRefused as exc:
                if exc.status == 409 and args.action == "cancel":
                    raise UsageError(f"{exc}; a running job is stopped with 'gonio jobs "
                                     f"--daemon {args.daemon} abort {job}'") from None
                raise
    if args.json:
        print(json.dumps(row))
        if args.action == "cancel":
            with DaemonClient(args.daemon, args.api_key) as client:
                _say_start_refusals(client)  # on stderr: stdout stays one JSON object
        return 0
    state = row.get("state", "?")
    if args.action == "cancel":
        print(f"job {job} cancelled: taken out of the queue, it will not run (state {state})")
        with DaemonClient(args.daemon, args.api_key) as client:
            _say_start_refusals(client)
    elif args.action == "pause":
        print(f"job {job}: pause asked (state {state}; it stops at the end of the angle under "
              f"way, lights off, and stays paused across a restart of the daemon; asked "
              f"during its last angle, it has nothing left to measure and goes on to finish; "
              f"'gonio jobs --daemon {args.daemon} resume {job}' goes on)")
    elif args.action == "resume":
        print(f"job {job} resumed (state {state})")
    elif args.action == "abort":
        print(f"job {job}: abort asked (state {state}; lights off and the stage stopped, its "
              f"readings stay in the store; 'gonio jobs --daemon {args.daemon} show {job}' "
              "says when it has ended)")
    else:
        # The reorder's answer is the job list's row, which has no place in the queue: asked.
        place = _queue_place(args, job)
        print(f"job {job} reordered: priority {row.get('priority', 0)}, state {state}"
              + (f", {place} in the queue" if place else ""))
    return 0
