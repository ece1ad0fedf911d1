"""What a scan says, whoever runs it: the summary of a finished scan, the dry run's few
lines, the suspended line, the output check and the states a job ends in. ``gonio scan``
(:mod:`gonio.cli.scan_commands`) and the daemon's jobs (:mod:`gonio.cli.daemon_jobs`) both
print them.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from gonio.arc_wording import arc_summary_line
from gonio.cli import UsageError
from gonio.wording import counted

FINAL_STATES = ("completed", "failed", "aborted", "halted")
"""The states a job does not leave: following it ends there."""


def check_output_path(out: Path, nothing: str = "nothing was measured", *,
                      overwrite: bool = False, calibration: bool = False,
                      names_specimen: bool = True) -> None:
    """Refuse an ``-o`` that cannot be written, or would replace a file, before anything is
    measured.

    The result is copied to ``-o`` when the scan has finished: a folder that cannot be made or
    written found only then cost the lab the whole scan's wait for an error (the result stays
    in the data directory, but the message did not say so). A file is made and removed in the
    folder, so whatever the file system or the permissions refuse is found now. An existing
    file there (yesterday's ``felt.h5``, a command run again from the shell's history) was
    replaced without a word: it is refused unless ``overwrite`` (``--overwrite``) says to.

    Parameters
    ----------
    out : the result file ``-o`` names
    nothing : what the refusal says was left undone (``gonio jobs wait`` measures nothing)
    overwrite : replacing existing files is what the user asked for
    calibration : the job is a calibration, whose calibration file is written beside ``out``
        (:func:`calibration_copy_path`); it is checked too
    names_specimen : ``-o`` names the specimen when ``--specimen`` does not (``gonio scan``;
        not ``gonio jobs wait``): the refusal says how to keep the name

    A file that appears at ``out`` while the scan runs (a second scan given the same ``-o``
    that ended first) is not replaced either: :func:`write_output` refuses it then.
    """
    import os
    import tempfile

    folder = out.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".gonio-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise UsageError(f"-o {out}: cannot write into {folder} ({why}); choose another "
                         f"location for the result ({nothing})") from None
    if out.is_dir():
        raise UsageError(f"-o {out} is a folder; give the result file's name, e.g. "
                         f"{out / 'felt.h5'}")
    # A device, a FIFO or a link to nothing: the result is written beside it and renamed
    # onto it (jobs wait), which would replace /dev/null itself for root, or copied into it
    # (gonio scan), which a FIFO refuses only when the scan has ended. A dry run writes no -o.
    if out.is_symlink() and not out.exists():
        raise UsageError(f"-o {out} is a link to a missing file ({os.readlink(out)}); give "
                         f"the result file's own name ({nothing})")
    if out.exists() and not out.is_file():
        raise UsageError(f"-o {out} is not a regular file (a device or a pipe); give a result "
                         f"file's name, e.g. felt.h5 ({nothing})")
    if overwrite:
        return
    taken = [p for p in ([out, calibration_copy_path(out)] if calibration else [out])
             if p.is_file()]
    if taken:
        names = " and ".join(str(p) for p in taken)
        keep = " (with --specimen NAME to keep the specimen's name)" if names_specimen else ""
        # -o also names the specimen when --specimen does not: another -o alone would start
        # a new job where the same command resumes one.
        raise UsageError(f"{names} already exist{'s' if len(taken) == 1 else ''}; give "
                         f"another -o{keep}, move "
                         f"{'it' if len(taken) == 1 else 'them'} away, or add --overwrite to "
                         f"replace {'it' if len(taken) == 1 else 'them'} ({nothing})")


def write_output(out: Path, data: bytes, *, overwrite: bool) -> None:
    """Write ``data`` to ``out`` whole or not at all (a file beside it, then moved onto it).

    Without ``overwrite`` a file at ``out`` is never replaced, including one that appeared
    after :func:`check_output_path` passed (two scans given the same ``-o``: the one that
    ended second replaced the first one's result without a word). The move is a hard link,
    which the file system refuses when the name is taken, so no other program can slip in
    between the check and the move; where hard links are not supported (FAT, some network
    file systems) the name is checked just before the move instead.

    Raises
    ------
    FileExistsError
        ``out`` exists and ``overwrite`` is false; nothing was written.
    OSError
        The folder or the file cannot be written.
    """
    import contextlib
    import errno
    import os
    import tempfile

    out.parent.mkdir(parents=True, exist_ok=True)
    # A name of its own: two scans ending together with the same -o must not write one part.
    fd, name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent)
    part = Path(name)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        # mkstemp makes it owner-only; a result is as readable as any file made here.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(part, 0o666 & ~umask)
        if overwrite:
            os.replace(part, out)
            return
        try:
            os.link(part, out)
        except FileExistsError:
            raise
        except OSError:
            if out.exists() or out.is_symlink():
                raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(out)) from None
            os.replace(part, out)
    finally:
        with contextlib.suppress(OSError):
            part.unlink(missing_ok=True)


def appeared_text(out: Path, job_id: int, kept: str) -> str:
    """Why a completed job's file was not written to ``out``: the file there appeared while
    the job ran (the start's check found none), and where the job's own copy is (``kept``)."""
    return (f"job {job_id} completed, but {out} appeared while it was measured (another scan "
            f"or program wrote it) and was not replaced; {kept}")


def calibration_copy_path(out: Path) -> Path:
    """Where a calibration job's calibration is copied beside its result ``out``
    (``white.h5``: ``white.calibration.json``)."""
    return out.with_name(out.stem + ".calibration.json")


def scan_summary(job_id: int, summary: dict[str, Any], out: Path | None,
                 kept: str) -> list[tuple[str, bool]]:
    """The end-of-scan summary of completed scan ``job_id``, the same whoever ran it.

    Both ``gonio scan`` and ``gonio scan --daemon`` print it, from the job's stored summary
    alone: the headline (samples, their units, the headline error), where the result is (``out``
    and ``kept``, where the data directory or the daemon keeps its own copy), the calibration
    the values carry, what the headline error means and the result's warnings.

    Parameters
    ----------
    job_id
        The job's id.
    summary
        The job's ``result`` summary (:func:`gonio.finishing.finish_job`).
    out
        The copy written for ``-o``; None when none was (``gonio jobs --daemon URL wait ID``
        without ``-o``).
    kept
        Where the original stays, in words (``kept in PATH``, or the daemon's URL).

    Returns
    -------
    list of (line, to_stderr)
        Lines for standard output, and warnings (``True``) for standard error.
    """
    from gonio.figures import headline_error, local_prior_text

    calibrated = bool(summary.get("calibrated"))
    err = headline_error(summary)
    where = f"wrote {out} ({kept})" if out is not None else kept
    lines: list[tuple[str, bool]] = [
        (f"job {job_id} completed: {result_headline(summary)}; {where}", False)]
    cal = summary.get("calibration")
    source = cal.get("source") if isinstance(cal, dict) else None
    if calibrated:
        lines.append((f"  calibration: {source or 'recorded in the result'}", False))
    else:
        lines.append(("  calibration: none in effect (values are sensor units, not BRDF; "
                      "calibrate with --white-reference ALBEDO)", False))
    if err:
        lines.append((f"  {err['key']}: {err['meaning']}", False))
    if (prior := local_prior_text(summary)) is not None:
        lines.append((f"  {prior}", False))
    lines.extend(_arc_lines(summary))
    for key in ("basis_misfit", "highlight_not_read"):
        if summary.get(key):
            lines.append((f"warning: {summary[key]}", True))
    return lines


def start_text(job: dict[str, Any]) -> str | None:
    """When a queued job (``GET /api/v1/jobs``'s row) is estimated to start, in a few words
    (``starts in about 4.5 min``; ``within`` when the estimate is an upper bound), or None
    for a job not queued or whose start is not known (its ``waiting`` says why)."""
    seconds = job.get("starts_in_s")
    if job.get("state") != "queued" or not isinstance(seconds, int | float):
        return None
    if seconds < 1:
        return "starts next"
    how = "within" if job.get("starts_in_bound") else "in about"
    return f"starts {how} {_duration_text(float(seconds))}"


def result_headline(summary: dict[str, Any]) -> str:
    """A completed scan's result in a few words: its samples, their units and the headline
    error (``80 samples in 1/sr, predicted_log_rmse 0.051``), from the job's stored summary."""
    from gonio.figures import headline_error

    units = "1/sr" if summary.get("calibrated") else "sensor units (uncalibrated)"
    err = headline_error(summary)
    err_text = f"{err['key']} {err['text']}" if err else "no error estimate"
    n = summary.get("n_samples", summary.get("readings"))
    return f"{n} samples in {units}, {err_text}"


def print_scan_summary(job_id: int, summary: dict[str, Any], out: Path | None,
                       kept: str) -> None:
    """Print :func:`scan_summary`: its lines to standard output, its warnings to standard
    error."""
    for line, to_stderr in scan_summary(job_id, summary, out, kept):
        print(line, file=sys.stderr if to_stderr else sys.stdout)


def _arc_lines(summary: dict[str, Any]) -> list[tuple[str, bool]]:
    """The arc scanned (an auto-arc scan's choice, or the plan's) and its test, or a forced
    half turn's warning; the basis the test's verdict chose (``(line, to_stderr)`` pairs)."""
    lines: list[tuple[str, bool]] = []
    if summary.get("arc_asymmetric"):
        lines.append((f"warning: {summary['arc_asymmetric']}", True))
    elif isinstance(summary.get("arc_test_p_value"), int | float):
        lines.append((arc_summary_line(summary), False))
    if summary.get("basis_switch"):
        lines.append((f"  basis: {summary['basis_switch']}", False))
    return lines


def _angles_text(angles: list[float], most: int = 8) -> str:
    shown = [f"{a:g}" for a in angles]
    if len(shown) > most:
        shown = [*shown[: most - 2], "...", shown[-1]]
    return ", ".join(shown) + " deg"


def _duration_text(seconds: float) -> str:
    if seconds < 0.05:
        return "0 s"  # nothing to wait for, or less than a twentieth of a second
    if seconds < 1:
        # A one-angle plan's quarter second read "about 0 s".
        return f"{seconds:.1g} s"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def _part_text(seconds: float) -> str:
    """A part of a duration (moves, settling, exposures) to within a few per cent: a quarter
    of a second's exposures read "0.2 s" at one decimal (round half to even)."""
    if seconds >= 10:
        return f"{seconds:.0f} s"
    return f"{seconds:.1f} s" if seconds >= 1 else f"{seconds:.2g} s"


def dry_run_summary(dr: Any, plan: Any, rig_name: str, *,
                    sim_calibration_s: float | None = None, time_scale: float = 1.0) -> str:
    """A few lines a person reads: angles, readings, duration (``--json`` has everything);
    ``sim_calibration_s``, the calibration ``gonio scan --sim`` runs first, if it does;
    ``time_scale``, the simulated rig's seconds per wall second (``--time-scale``)."""
    n_pairs = len(dr.pairs)
    angles = list(dr.angles_deg)
    ex = plan.exposure
    first = " in the first round" if plan.kind == "adaptive" else ""
    lines = [
        f"dry run of the {plan.kind} plan on rig {rig_name!r}; nothing moves",
        f"  stage angles: {len(angles)}{first} ({_angles_text(angles)})",
        f"  pairs: {n_pairs} ({len(dr.lights)} lights)",
        f"  readings: {dr.readings}{first} ({counted(n_pairs, 'pair')} x "
        f"{counted(len(angles), 'angle')}), "
        f"exposure {ex.exposure_s:g} s x {ex.averages}",
        f"  duration: about {_duration_text(dr.estimated_s)} (moves {_part_text(dr.motion_s)}, "
        f"settling {_part_text(dr.settle_s)}, exposures {_part_text(dr.exposure_s)})",
    ]
    if time_scale != 1.0:
        # The durations are the rig's: a simulated rig at --time-scale moves and exposes
        # faster (or slower), and the number read as wall time. The lamp settling is the
        # engine's own wait, in wall time.
        wall = (dr.motion_s + dr.exposure_s) / time_scale + dr.settle_s
        lines.append(f"  (a real rig's time; the simulated rig at --time-scale {time_scale:g} "
                     f"moves and exposes that much faster: about {_duration_text(wall)} of "
                     "wall time)")
    if sim_calibration_s is not None:
        lines.append(f"  before it, about {_duration_text(sim_calibration_s)}: the simulated "
                     "rig is calibrated on a white reference (no calibration of this rig at "
                     "this exposure is in effect in its data directory; later scans there "
                     "reuse it)")
    finishing = getattr(dr, "finishing_s", None)
    if finishing is not None:
        # The measuring alone read as the job's time; the reconstruction can take longer.
        lines.append(f"  then finishing (reconstruction and export fits): about "
                     f"{_duration_text(finishing)} ({dr.finishing_source})")
    bound = getattr(dr, "max_estimated_s", None)
    if plan.kind == "adaptive":
        where = ("where the expected error falls most" if plan.rule == "posterior"
                 else "where the readings change fastest")
        most = getattr(dr, "max_angles", None)
        lines.append(f"  later rounds add angles {where}; "
                     + (f"at most {counted(most, 'angle')} and {_duration_text(bound)} in all"
                        if bound is not None and most is not None
                        else "no --max-samples, so no bound on the total"))
    for b in getattr(dr, "arc_branches", None) or ():
        arc_deg, angles, secs = b.arc_deg, b.angles, b.estimated_s
        what = ("twofold symmetric: it goes on over half a turn" if arc_deg == 180.0
                else "not twofold symmetric: it goes on over a full turn")
        lines.append(f"  if the first round finds the specimen {what}, at most "
                     f"{counted(angles, 'angle')} ({counted(angles * n_pairs, 'reading')}) and "
                     f"{_duration_text(secs)} in all"
                     + ("; reconstructed with the basis for specimens without twofold "
                        "symmetry" if getattr(b, "basis", "default") == "asymmetric" else ""))
        if getattr(b, "basis_build_s", None) is not None:
            lines.append(f"    then about {_duration_text(b.basis_build_s)} more: that basis is "
                         "not built on this install yet, so the job builds it before "
                         "reconstructing (once; later jobs reuse it)")
    build = getattr(dr, "basis_build_s", None)
    if build is not None:
        lines.append(f"  first, about {_duration_text(build)} more: the reconstruction basis is "
                     "not built on this install yet; the adaptive rule needs it, so the job "
                     "builds it before its first reading (once; later jobs reuse it)")
    if (gap := getattr(dr, "mirror_gap", None)) is not None:
        lines.append(f"  note: {gap}")
    lines += [f"  warning: {w}" for w in getattr(dr, "warnings", [])]
    lines.append("  (--json prints the whole plan: every position in visiting order)")
    return "\n".join(lines)


def suspended_line(job_id: int, reason: str, through_daemon: bool = False) -> str:
    """What a terminal shows when a job suspends: the bar alone said 'suspended' and no why,
    and then nothing while the job waited for the device (a scan that seemed to hang)."""
    then = ("the daemon retries and goes on once it answers (Ctrl-C stops following, not the "
            "job)" if through_daemon else
            "the scan retries and goes on once it answers; Ctrl-C leaves the job paused, and "
            "the same command resumes it")
    return f"job {job_id} suspended: {reason}\n  {then}"


def resumed_line(job_id: int) -> str:
    """What a terminal shows when a suspended job goes on (the device answers again): after
    the suspended line, nothing said the fault had cleared."""
    return f"job {job_id} resumed: the device answers again; measuring goes on"


HOLDING_STATES = ("running", "paused", "suspended", "reconstructing")
"""States in which a job holds the rig (:data:`gonio.jobstates.ACTIVE_STATES`)."""


def queued_line(job_id: int, row: dict[str, Any], jobs: list[dict[str, Any]]
                ) -> tuple[tuple[Any, ...], str]:
    """What a terminal following a queued daemon job says of why it waits: the queue held or
    a paused or suspended job (the API's ``waiting``), the job holding the rig, the queued
    jobs ahead of it (``queue_position``), and when it may start (``starts_in_s``,
    ``starts_in_bound``, ``starts_in_estimate``: the job list's start estimate). ``gonio jobs
    --daemon URL wait`` on a queued job showed a bar at 0 and nothing else.

    Parameters
    ----------
    job_id : the queued job
    row : its detail (``GET /api/v1/jobs/{id}``)
    jobs : the daemon's jobs (``GET /api/v1/jobs``; those holding the rig suffice), for
        the job holding the rig

    Returns
    -------
    key : what the job waits for; the line is said again only when this changes (the time
        left counts down at every poll)
    text : the line
    """
    holders = tuple((int(j["id"]), str(j["state"])) for j in jobs
                    if j.get("state") in HOLDING_STATES and j.get("id") != job_id)
    ahead = row.get("queue_position")
    waiting = row.get("waiting")
    parts: list[str] = []
    if waiting:
        parts.append(str(waiting))  # it names a paused or suspended holder itself
    elif holders:
        parts.append("waits for " + " and ".join(f"job {i} ({s})" for i, s in holders)
                     + " to end")
    if isinstance(ahead, int) and ahead > 0:
        parts.append(f"{counted(ahead, 'queued job')} ahead of it")
    elif not parts:
        # An answer without queue_position (an older daemon) does not say it is next.
        parts.append("next in the queue, the rig is free" if ahead == 0
                     else "the rig is free; its place in the queue is not known")
    seconds, source = row.get("starts_in_s"), row.get("starts_in_estimate")
    start = start_text(row)  # the words gonio jobs --daemon URL list uses
    if start is not None:
        when = start + (f" ({source})" if source else "")
    elif waiting:
        when = "its start is not known until then"  # the estimate's reason is ``waiting``
    else:
        why = str(source or "").removeprefix("not known: ")
        when = "start not known" + (f": {why}" if why else "")
    # The holders say nothing while ``waiting`` does (its text names the cause): a job that
    # ends under a held queue printed the same line again.
    refusal = row.get("start_refusal")  # said at the end: what waiting will come to
    key = (waiting, None if waiting else holders, ahead, isinstance(seconds, int | float),
           None if isinstance(seconds, int | float) or waiting else source, refusal)
    return key, (f"job {job_id} queued: {'; '.join(parts)}; {when}"
                 + (f"; {refusal}" if refusal else ""))
