"""``gonio scan`` (one job in the foreground) and ``gonio jobs`` (inspect a job store).

``gonio scan`` keeps its job in a data directory with the daemon's layout (``--data-dir``,
default one per rig geometry under the user data folder, :func:`gonio.paths.scan_data_dir`):
the job store ``gonio.sqlite`` (``--db`` overrides), ``results/job-<id>.h5`` and the latest
``calibration.json``. The only file written beside ``-o OUT.h5`` is ``OUT.h5`` itself (and, for
``--white-reference``, ``OUT.calibration.json``). If the store holds an unfinished job with the
same plan on the same rig (the previous run was killed), the scan resumes it from its last
checkpoint instead of starting again.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gonio.cli import UsageError, finite_float, nonnegative_float, positive_float, positive_int
from gonio.cli.daemon_client import (
    DaemonClient,
    DaemonRefused,
    DaemonUnreachable,
    add_daemon_options,
)
from gonio.wording import counted

if TYPE_CHECKING:
    from gonio.basis_supply import BasisSupply


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "scan", help="run one scan in the foreground and write its result file",
        description="Measure a specimen with a uniform or adaptive plan on a real rig "
        "(--rig) or the simulated rig (--sim), reconstruct it and write an HDF5 result.",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--rig", type=Path, help="rig config TOML")
    src.add_argument("--sim", action="store_true", help="start the simulated rig")
    src.add_argument("--daemon", metavar="URL",
                     help="submit the scan to a running daemon (it owns the rig) and wait for "
                          "its result (--no-wait: return once it is queued), e.g. "
                          "http://127.0.0.1:8600")
    add_daemon_options(p)
    p.add_argument("--no-wait", action="store_true",
                   help="with --daemon: queue the scan and return at once, printing its job id "
                        "and the command that follows it and fetches its result ('gonio jobs "
                        "--daemon URL wait ID -o FILE'); -o is then optional")
    p.add_argument("--stage", choices=["dynamixel", "zaber"], default="dynamixel",
                   help="simulated stage kind (with --sim)")
    p.add_argument("--material", default=None,
                   help="simulated material (with --sim): library name, .npz table, or a "
                   "spectral material read by 31-band sensors (metallic-blue-paint, ...: "
                   "docs/colour.md)")
    p.add_argument("--time-scale", type=positive_float, default=1.0,
                   help="simulated seconds per wall second (with --sim)")
    p.add_argument("--seed", type=int, default=0, help="sensor noise seed (with --sim)")
    from gonio.cli.sim_command import add_modbus_port_option

    add_modbus_port_option(p)
    p.add_argument("--rotations", type=positive_int, default=None,
                   help="stage angles r (default 8); with --adaptive the first round's "
                        "(default 4 with the posterior rule, 8 with --rule vf)")
    p.add_argument("--start-deg", type=finite_float, default=0.0, help="first stage angle, degrees")
    p.add_argument("--span", type=float, choices=(180.0, 360.0), default=None, metavar="DEG",
                   help="arc of the uniform stage angles: 180 (default; a twofold-symmetric "
                        "specimen reads the same turned by half a turn, so the angles see twice "
                        "as many distinct azimuths) or 360 (a full turn, for specimens without "
                        "that symmetry; the default with --rule vf)")
    p.add_argument("--arc", choices=["fixed", "auto"], default="fixed",
                   help="fixed (default): --span is the arc; auto: the first round reads the "
                        "half-turn angles and the first one's opposite (two opposites when "
                        "the pairs lie in nearly one plane), tests twofold symmetry "
                        "and continues over half a turn if the specimen has it, else over a "
                        "full turn (docs/science.md 7.4)")
    p.add_argument("--arc-noise", type=positive_float, default=None,
                   help="with --arc auto: the rig's relative noise of one reading, the "
                        "symmetry test's scale (default 0.01)")
    p.add_argument("--adaptive", action="store_true", help="adaptive rotations (math.md 9)")
    p.add_argument("--rule", choices=["posterior", "vf"], default="posterior",
                   help="adaptive refinement rule: posterior (where the joint fit expects the "
                        "error to fall most) or vf (V&F's PCHIP midpoints)")
    p.add_argument("--min-gain", type=positive_float, default=None,
                   help="posterior rule: least drop of the self-estimated log_rmse a new "
                        "stage angle must buy (default 0.00002)")
    p.add_argument("--max-rotations", type=positive_int, default=None,
                   help="with --adaptive: most stage angles in all, the first round's included "
                        "(default 16 with the posterior rule, no cap with --rule vf)")
    p.add_argument("--threshold", type=positive_float, default=0.1,
                   help="vf rule: relative error e")
    p.add_argument("--max-samples", type=positive_int, default=None, help="adaptive sample budget")
    p.add_argument("--exposure", type=positive_float, default=0.01, help="seconds per exposure")
    p.add_argument("--averages", type=positive_int, default=1,
                   help="exposures averaged per reading")
    p.add_argument("--light-settle", type=nonnegative_float, default=0.05,
                   help="seconds after lamp on")
    p.add_argument("--specimen", default=None,
                   help="specimen name, carried into the job, its result and every export "
                        "(default: the output file's name without .h5, e.g. 'felt' for -o "
                        "felt.h5, else 'unnamed'; with --white-reference, the reference's name, "
                        "default 'white reference')")
    p.add_argument("--calibration", type=Path, default=None,
                   help="calibration JSON (from a calibration job) to apply")
    p.add_argument("--accept-uncalibrated", action="store_true",
                   help="run a scan no calibration covers although this rig was calibrated "
                        "(its own data directory holds a calibration): values in sensor units")
    p.add_argument("--white-reference", type=positive_float, default=None, metavar="ALBEDO",
                   help="the stage holds a white reference of this albedo (e.g. 0.99): run a "
                        "calibration job and write OUTPUT.calibration.json for later --calibration")
    p.add_argument("--data-dir", type=Path, default=None,
                   help="job store, results and calibration (default: one folder per rig "
                        "geometry in the user data folder, printed by the scan)")
    p.add_argument("--db", type=Path, default=None,
                   help="job store (SQLite; default DATA_DIR/gonio.sqlite)")
    p.add_argument("--dry-run", action="store_true",
                   help="print the plan's angles, readings and duration; nothing moves")
    p.add_argument("--json", action="store_true", help="with --dry-run: the full plan as JSON")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-export-fits", action="store_true",
                   help="finish without the export fits (several seconds of CPU sooner); "
                   "'gonio export' then fits when it exports")
    # Required but for --daemon URL --no-wait (checked in _scan, which says so).
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="result file (.h5); required, except with --daemon URL --no-wait")
    p.set_defaults(func=_scan)

    j = subparsers.add_parser(
        "jobs", help="list, show or abort jobs in a job store, or rebuild a job's result file",
        description="list: the jobs; show ID: one job as the API's GET /api/v1/jobs/ID has it "
        "(--json: as JSON); abort ID: end one left "
        "unfinished (e.g. a foreground scan interrupted by Ctrl-C); rebuild ID: write a "
        "completed job's result file again from the readings the store holds (when the file "
        "is missing or damaged), with the calibration the job was finished with; a job that "
        "failed because the disk filled while its result was written is completed so. "
        "With --daemon URL the jobs are a running daemon's, acted on through its API: list, "
        "show, abort (a running job too), cancel ID (take a queued job out of the queue), "
        "reorder ID --position N and/or --priority P (N=0: next), wait ID [-o FILE] (follow "
        "the job with a progress bar until it ends, then fetch its result to FILE and print "
        "the summary 'gonio scan' prints; e.g. a scan queued with 'gonio scan --daemon URL "
        "--no-wait', or one whose terminal was closed).")
    j.add_argument("action", nargs="?",
                   choices=["list", "show", "abort", "rebuild", "cancel", "reorder", "wait"],
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
                        "prints, or the data directory holding it (required; without it the "
                        "error lists the stores found in the default data directories)")
    j.add_argument("--data-dir", type=Path, default=None,
                   help="the data directory the store's result paths are relative to (show: "
                        "result_file; rebuild: its results/ gets the file); default: the "
                        "folder of --db")
    j.add_argument("-o", "--output", type=Path, default=None,
                   help="wait: write the completed job's result file here (a calibration job's "
                        "calibration beside it, as OUTPUT.calibration.json); without it the "
                        "result stays in the daemon")
    j.add_argument("--no-progress", action="store_true", help="wait: no progress bar")
    j.add_argument("--json", action="store_true", help="machine-readable output")
    j.set_defaults(func=_jobs)


def _plan(args: argparse.Namespace) -> Any:
    from gonio.plans.models import AdaptivePlan, CalibrationPlan, ExposureSettings, UniformPlan

    ex = ExposureSettings(exposure_s=args.exposure, averages=args.averages,
                          light_settle_s=args.light_settle)
    if args.white_reference is not None:
        if args.adaptive or args.calibration is not None:
            raise UsageError("--white-reference runs a calibration: it takes no --adaptive or "
                             "--calibration")
        if not 0 < args.white_reference <= 1:
            raise UsageError(f"--white-reference is the reference's albedo, in (0, 1]; got "
                             f"{args.white_reference:g}")
        # The job's name too (the job list, the page, the result file's specimen), as the
        # white reference `gonio serve --sim` measures is named (gonio.cli.sim_session).
        name = args.specimen or "white reference"
        return CalibrationPlan(reference_albedo=args.white_reference, specimen=name,
                               reference_name=name, exposure=ex,
                               rotations=args.rotations or 8, start_deg=args.start_deg)
    arc: dict[str, Any] = {}
    if args.arc == "auto":
        if args.span == 360.0:
            raise UsageError("--arc auto chooses the arc itself (half a turn for a "
                             "twofold-symmetric specimen, else a full turn); --span 360 forces "
                             "a full turn: give one of them")
        arc = {"arc": "auto", **({"arc_noise": args.arc_noise} if args.arc_noise else {})}
    elif args.arc_noise is not None:
        raise UsageError("--arc-noise is the scale of the symmetry test of --arc auto; add "
                         "--arc auto or drop --arc-noise")
    if args.adaptive:
        # Only what was given: the plan's defaults depend on the rule.
        given = {k: v for k, v in (("initial_rotations", args.rotations),
                                   ("min_gain", args.min_gain),
                                   ("max_rotations", args.max_rotations),
                                   ("span_deg", args.span)) if v is not None}
        return AdaptivePlan(specimen=_specimen(args), exposure=ex, rule=args.rule,
                            threshold=args.threshold, max_samples=args.max_samples,
                            start_deg=args.start_deg, **given, **arc)
    span = {"span_deg": args.span} if args.span is not None else {}
    return UniformPlan(specimen=_specimen(args), exposure=ex,
                       rotations=args.rotations or 8, start_deg=args.start_deg, **span, **arc)


def _specimen(args: argparse.Namespace) -> str:
    """The specimen's name: ``--specimen``, else the result file's stem (``-o felt.h5``:
    "felt"), else "unnamed", so jobs, results, exports and the page do not all say
    "specimen"."""
    from gonio.export.metadata import UNNAMED

    if args.specimen:
        return str(args.specimen)
    stem = Path(args.output).stem if args.output is not None else ""
    generic = {"", "null", "result", "out", "output", "scan"}
    return stem if stem.lower() not in generic else UNNAMED


def _scan(args: argparse.Namespace) -> int:
    if args.no_wait and not args.daemon:
        raise UsageError("--no-wait goes with --daemon URL: a daemon runs the queued scan after "
                         "this command returns; a scan this command runs itself (--rig, --sim) "
                         "has no one else to run it, so the command waits for it")
    if args.no_wait and args.dry_run:
        raise UsageError("--no-wait queues the scan and returns; --dry-run queues nothing: "
                         "give one of them")
    if args.output is None and not args.no_wait:
        raise UsageError(
            "the result file is required: -o/--output FILE.h5, e.g. -o felt.h5"
            + (" (or --no-wait: queue the scan on the daemon and return; 'gonio jobs --daemon "
               "URL wait ID -o FILE' fetches its result later)" if args.daemon else ""))
    for name in ("exposure", "time_scale"):
        if getattr(args, name) <= 0:
            raise UsageError(f"--{name.replace('_', '-')} must be > 0")
    if args.rig is not None and not args.rig.is_file():
        raise UsageError(f"rig config {args.rig} does not exist")
    plan = _plan(args)
    if args.white_reference is None and not args.specimen and not args.dry_run:
        print(f"note: no --specimen NAME given; the job, its result and its exports call the "
              f"specimen {_specimen(args)!r}", file=sys.stderr)
    if not args.dry_run and args.output is not None:
        _check_output(args.output)
    if args.daemon:
        return _scan_through_daemon(args, plan)
    sim = None
    if args.sim:
        from gonio.cli.sim_command import start_sim_rig_or_say_why
        from gonio.sim.rig import SimRigOptions, start_sim_rig

        sim = start_sim_rig_or_say_why(start_sim_rig, SimRigOptions(
            stage=args.stage, material=args.material, time_scale=args.time_scale,
            seed=args.seed, modbus_port=args.modbus_port))
        config = sim.config
    else:
        from gonio.config import load_rig_config

        config = load_rig_config(args.rig)
    import asyncio

    try:
        return asyncio.run(_run_scan(args, plan, config, sim))
    finally:
        if sim is not None:
            sim.close()


def _check_output(out: Path, nothing: str = "nothing was measured") -> None:
    """Refuse an ``-o`` that cannot be written before anything is measured.

    The result is copied to ``-o`` when the scan has finished: a folder that cannot be made or
    written found only then cost the lab the whole scan's wait for an error (the result stays
    in the data directory, but the message did not say so). A file is made and removed in the
    folder, so whatever the file system or the permissions refuse is found now.

    Parameters
    ----------
    out : the result file ``-o`` names
    nothing : what the refusal says was left undone (``gonio jobs wait`` measures nothing)
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


def _copy_result(src: Path, out: Path, job_id: int) -> None:
    """Copy a completed job's result to ``-o``; when that fails, say where the result is."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, out)
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise UsageError(f"job {job_id} completed, but its result could not be copied to "
                         f"{out} ({why}); it is kept in {src}: copy it from there") from None


async def _run_scan(args: argparse.Namespace, plan: Any, config: Any, sim: Any = None) -> int:
    from gonio.basis_supply import BasisSupply
    from gonio.drivers.factory import build_rig
    from gonio.plans.dryrun import dry_run
    from gonio.rigdescription import RigDescription

    rig = build_rig(config)
    desc = RigDescription.from_rig(rig)
    # The in-process scan reconstructs with the default basis (built on first use), loaded
    # once for this run by whoever needs it first.
    basis = BasisSupply()
    if args.dry_run:
        dr = dry_run(plan, desc, basis_ready=not basis.build_needed(), basis=basis.symmetry(),
                     asymmetric_build_s=(basis.asymmetric_build_s()
                                         if plan.arc_mode() == "auto" else None))
        more = [] if sim is not None else _calibration_warnings(args, plan, config, dr.pairs)
        if more:
            dr = dr.model_copy(update={"warnings": [*dr.warnings, *more]})
        print(dr.model_dump_json(indent=2) if args.json
              else dry_run_summary(dr, plan, config.rig.name))
        return 0
    if args.json:
        raise UsageError("--json goes with --dry-run")
    from gonio.plans.checked import check_plan

    # Refuse a bad plan before connecting to anything; the check goes with the plan from here
    # (the dry run below and the submission do not make it again).
    checked = check_plan(plan, desc)
    from gonio.daemon import STORE_FILE
    from gonio.paths import scan_data_dir

    data_dir = args.data_dir or scan_data_dir(config)
    data_dir.mkdir(parents=True, exist_ok=True)
    db = args.db or data_dir / STORE_FILE
    # Own the data directory, the job store and the rig for the whole run, or refuse naming who
    # does (a daemon on the same data directory or rig, another gonio scan).
    from gonio.locks import LockBusy, claim_endpoints, claim_store

    owned: list[Any] = []
    try:
        owned.append(claim_store(data_dir / STORE_FILE, f"data directory {data_dir}"))
        if Path(db).resolve() != (data_dir / STORE_FILE).resolve():
            owned.append(claim_store(db))
        owned.append(claim_endpoints(config.endpoints()))
    except LockBusy as exc:
        for lock in reversed(owned):
            lock.release()
        raise UsageError(str(exc)) from None
    try:
        return await _run_owned(args, checked, config, sim, rig, db, data_dir, basis)
    finally:
        for lock in reversed(owned):
            lock.release()


async def _run_owned(args: argparse.Namespace, checked: Any, config: Any, sim: Any, rig: Any,
                     db: Path, data_dir: Path, basis: BasisSupply) -> int:
    """Run the scan through an in-process :class:`gonio.service.GonioService` (the same door
    as the daemon's API, without its queue worker), then copy the result to ``-o``.
    ``checked`` is the plan checked on the rig (:class:`gonio.plans.checked.CheckedPlan`)."""
    import asyncio

    from gonio.cli.sim_session import attach_sim, calibrate_in_foreground, calibration_covers_rig
    from gonio.jobstates import JobState
    from gonio.service import GonioService, JobRequest
    from gonio.store import JobStore

    out: Path = args.output
    plan = checked.plan
    store = JobStore(db)
    print(f"data directory {data_dir} (job store {db})", file=sys.stderr)
    # The same rule as the daemon: the latest calibration job here, else the rig config's
    # [calibration] factors; --calibration overrides both.
    override = None
    if args.calibration is not None:
        from gonio.calibration import check_plausible, sensor_full_scale

        if not args.calibration.is_file():
            raise UsageError(f"calibration file {args.calibration} does not exist")
        override = _read_calibration(args.calibration)
        check_plausible(override, sensor_full_scale(config),
                        f"calibration file {args.calibration}")
    service = GonioService(store, rig, rig_config=config, basis=basis, data_dir=data_dir,
                           calibration=override, fit_exports=not args.no_export_fits)
    try:
        if sim is not None:
            attach_sim(service, sim)
        elif args.rig is not None:
            from gonio.cli.sim_session import sim_specimen_truth

            # A rig `gonio sim` runs: results record the simulated material (the truth row
            # of `gonio render`), as with --sim.
            truth = sim_specimen_truth(args.rig, config)
            if truth is not None:
                service.specimen_truth = lambda: truth
        # Resume an interrupted job only when it is this scan: the same plan on the same rig.
        job = service.unfinished_job(plan)
        if job is not None:
            print(f"resuming job {job.id} from its checkpoint ({job.done_angles} of "
                  f"{job.total_angles} angles done)", file=sys.stderr)
            if job.state is JobState.PAUSED:
                # Left paused by Ctrl-C (or by a daemon): running this command again is the
                # user's resume; the engine would otherwise wait for an API call that never
                # comes in the foreground.
                store.set_state(job.id, JobState.RUNNING)
        else:
            from gonio.calibration import exposure_warning

            exposure_s = plan.exposure.exposure_s
            if (sim is not None and override is None and plan.kind != "calibration"
                    and (not calibration_covers_rig(service)
                         or exposure_warning(service.calibration(), exposure_s))):
                # The simulated rig's calibration is measured at the scan's exposure (one
                # at another exposure would leave the scan off by the ratio).
                why = await calibrate_in_foreground(service, sim, exposure_s)
                if why is not None:
                    raise UsageError(why)
            if sim is None and plan.kind != "calibration":
                _check_calibration(args, checked.pairs, config, service.calibration(),
                                   data_dir)
            # A scan at another exposure than the calibration in effect is refused by
            # service.submit below, naming both exposures (Calibration.check_exposure).
            # What the submission records as the job's arc warning, said here too (a job whose
            # basis is known only later says it through the progress bar's events).
            for warning in service.dry_run(checked).warnings:
                print(f"warning: {warning}", file=sys.stderr)
            job = service.submit(JobRequest(plan=plan), checked=checked,
                                 accept_uncalibrated=bool(args.accept_uncalibrated))
        bar = _progress(service, job.id, disabled=args.no_progress)
        try:
            final = await service.run_in_foreground(job.id)
        except asyncio.CancelledError:
            # Ctrl-C (asyncio.run cancels this task, then raises KeyboardInterrupt): the
            # engine has stopped measuring; leave the job paused at its checkpoint, not
            # "running" for ever, and say how to go on.
            bar.close()
            _left_interrupted(store, job.id, db, args)
            raise
        finally:
            bar.close()
            if sim is not None:
                sim.load("specimen")
    finally:
        await service.stop()
    row = service.get_job(job.id)
    if final is not JobState.COMPLETED:
        print(f"job {job.id} {final.value}: {row.reason}", file=sys.stderr)
        return 1
    assert row.result_path is not None
    # A copy: the data directory keeps its result (what 'gonio jobs show' reports stays true).
    _copy_result(service.result_path(job.id), out, job.id)
    summary = row.result or {}
    if plan.kind == "calibration":
        from gonio.calibration import CALIBRATION_FILE

        cal_out = out.with_name(out.stem + ".calibration.json")
        shutil.copyfile(data_dir / CALIBRATION_FILE, cal_out)
        n_pairs = len(checked.pairs)
        # In effect from now on for this data directory's scans (the latest calibration job
        # here, as the daemon applies it): it said "apply it with --calibration", which a
        # later scan here does not need.
        print(f"job {job.id} completed: calibration of {counted(n_pairs, 'pair')}, in effect "
              f"now for this rig's later scans (data directory {data_dir}); a copy is in "
              f"{cal_out} (--calibration {cal_out} applies it to a scan with another data "
              "directory)")
        return 0
    print_scan_summary(job.id, summary, out, f"kept in {service.result_path(job.id)}")
    return 0


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
    units = "1/sr" if calibrated else "sensor units (uncalibrated)"
    err = headline_error(summary)
    err_text = f"{err['key']} {err['text']}" if err else "no error estimate"
    n = summary.get("n_samples", summary.get("readings"))
    where = f"wrote {out} ({kept})" if out is not None else kept
    lines: list[tuple[str, bool]] = [
        (f"job {job_id} completed: {n} samples in {units}, {err_text}; {where}", False)]
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


def print_scan_summary(job_id: int, summary: dict[str, Any], out: Path | None,
                       kept: str) -> None:
    """Print :func:`scan_summary`: its lines to standard output, its warnings to standard
    error."""
    for line, to_stderr in scan_summary(job_id, summary, out, kept):
        print(line, file=sys.stderr if to_stderr else sys.stdout)


def _arc_lines(summary: dict[str, Any]) -> list[tuple[str, bool]]:
    """The arc an auto-arc scan chose and its test, or a forced half turn's warning; the
    basis the test's verdict chose (``(line, to_stderr)`` pairs)."""
    lines: list[tuple[str, bool]] = []
    if summary.get("arc_asymmetric"):
        lines.append((f"warning: {summary['arc_asymmetric']}", True))
    elif isinstance(summary.get("arc_test_p_value"), int | float):
        verdict = "twofold symmetric" if summary.get("arc_symmetric") else "NOT twofold symmetric"
        lines.append((f"  arc: {summary.get('arc_deg', 0):g} deg; the first round read the "
                      f"specimen {verdict} (chi-square "
                      f"{summary.get('arc_test_statistic', float('nan')):.1f} on "
                      f"{summary.get('arc_test_dof')} degrees of freedom, "
                      f"p = {summary['arc_test_p_value']:.3g})", False))
    if summary.get("basis_switch"):
        lines.append((f"  basis: {summary['basis_switch']}", False))
    return lines


def _calibration_warnings(args: argparse.Namespace, plan: Any, config: Any,
                          pairs: Any) -> list[str]:
    """The dry run's ``uncalibrated: ...`` and ``exposure: ...`` warnings for ``plan``
    (measuring ``pairs``) on this rig, if any."""
    from gonio.calibration import (
        Calibration,
        calibration_in_effect,
        exposure_warning,
        uncalibrated_warning,
    )
    from gonio.paths import scan_data_dir

    if plan.kind == "calibration":
        return []
    if args.calibration is not None and args.calibration.is_file():
        cal = _read_calibration(args.calibration)
    else:
        cal = calibration_in_effect(args.data_dir or scan_data_dir(config), config)
    cal = cal if isinstance(cal, Calibration) else Calibration()
    uncal = uncalibrated_warning(cal, pairs)
    return [w for w in (_how_to_calibrate(uncal, args),
                        exposure_warning(cal, plan.exposure.exposure_s)) if w is not None]


def _how_to_calibrate(warning: str | None, args: argparse.Namespace) -> str | None:
    """An ``uncalibrated: ...`` warning (the API's and the page's words, which name no
    command) with the command that calibrates this rig from the command line."""
    if warning is None or not warning.startswith("uncalibrated:") or args.rig is None:
        return warning
    return (f"{warning}; here: with the white reference on the stage, 'gonio scan --rig "
            f"{args.rig} --white-reference 0.99 -o white.h5' (its calibration stays in effect "
            "for this rig's later scans)")


def _check_calibration(args: argparse.Namespace, pairs: Any, config: Any, cal: Any,
                       data_dir: Path) -> None:
    """Warn of an uncalibrated scan; refuse one of a rig that was calibrated (its own data
    directory holds a calibration, or one of other pairs is in effect) unless
    ``--accept-uncalibrated``."""
    from gonio.calibration import CALIBRATION_FILE, uncalibrated_refusal, uncalibrated_warning
    from gonio.paths import scan_data_dir

    warning = _how_to_calibrate(uncalibrated_warning(cal, pairs), args)
    if warning is None or cal.pairs:
        return  # covered, or partly: the submission refuses it, saying which pairs
    own: Path | None = scan_data_dir(config)
    why = uncalibrated_refusal(cal, pairs, own, data_dir)
    if why is not None and not args.accept_uncalibrated:
        assert own is not None  # a refusal names the rig's own calibration
        raise UsageError(f"{why}; leave out --data-dir/--db, give --calibration "
                         f"{own / CALIBRATION_FILE}, or add --accept-uncalibrated to measure "
                         "in sensor units")
    print(f"warning: {warning}", file=sys.stderr)


def _read_calibration(path: Path) -> Any:
    """A calibration JSON file, or a usage error naming the file and what it should be."""
    from pydantic import ValidationError

    from gonio.calibration import Calibration

    try:
        return Calibration.model_validate_json(path.read_text(encoding="utf-8"))
    except (ValidationError, UnicodeDecodeError) as exc:
        hint = (" (that is a TOML file: --calibration takes the JSON a calibration job "
                "writes, e.g. white.calibration.json from 'gonio scan --white-reference')"
                if path.suffix == ".toml" else "")
        first = exc.errors()[0]["msg"] if isinstance(exc, ValidationError) else str(exc)
        first = first.removeprefix("Value error, ")
        raise UsageError(f"--calibration {path}: not a calibration file ({first}){hint}; "
                         "expected the JSON written by a calibration job "
                         "(OUTPUT.calibration.json of 'gonio scan --white-reference ALBEDO')"
                         ) from None


def _left_interrupted(store: Any, job_id: int, db: Path, args: argparse.Namespace) -> None:
    """Mark a job whose foreground run was interrupted ``paused`` (a measuring one; one that
    was reconstructing stays so and is finished at the next run) and print how to resume or
    abort it."""
    from gonio.jobstates import JobState

    row = store.get_job(job_id)
    if row.state in (JobState.RUNNING, JobState.SUSPENDED):
        row = store.set_state(job_id, JobState.PAUSED, reason="interrupted (Ctrl-C in gonio scan)")
    if row.state.value in _FINAL:
        return
    print(f"job {job_id} interrupted: {row.state.value} at its checkpoint, "
          f"{row.done_angles} of {row.total_angles} angles measured. Run the same command "
          f"again to resume it, or abort it with: gonio jobs abort {job_id} --db {db}",
          file=sys.stderr, flush=True)


def _angles_text(angles: list[float], most: int = 8) -> str:
    shown = [f"{a:g}" for a in angles]
    if len(shown) > most:
        shown = [*shown[: most - 2], "...", shown[-1]]
    return ", ".join(shown) + " deg"


def _duration_text(seconds: float) -> str:
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


def dry_run_summary(dr: Any, plan: Any, rig_name: str) -> str:
    """A few lines a person reads: angles, readings, duration (``--json`` has everything)."""
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
        what = ("twofold symmetric: on over half a turn" if arc_deg == 180.0
                else "not twofold symmetric: on over a full turn")
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
    lines += [f"  warning: {w}" for w in getattr(dr, "warnings", [])]
    lines.append("  (--json prints the whole plan: every position in visiting order)")
    return "\n".join(lines)


_FINAL = ("completed", "failed", "aborted", "halted")


def _scan_through_daemon(args: argparse.Namespace, plan: Any) -> int:
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
        if args.json:
            raise UsageError("--json goes with --dry-run")
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
        if args.no_wait:
            out = args.output or Path(_suggested_output(job_id, job.get("specimen")))
            print(f"job {job_id} queued on {client.url}; follow it and fetch its result "
                  f"with:\n  {wait_command(client.url, job_id, out)}")
            return 0
        print(f"job {job_id} queued on {client.url}", file=sys.stderr)
        # What the daemon said of the job, kept for a message if it goes away: its queueing
        # answer at first, then every poll's.
        return follow_and_fetch(client, job_id, args.output, no_progress=args.no_progress,
                                seen=dict(job), queued_here=True)


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
    (reads need none unless the daemon says so; the key stays out of shell history)."""
    import shlex

    cmd = f"gonio jobs --daemon {shlex.quote(url)} wait {job_id}"
    return cmd if out is None else f"{cmd} -o {shlex.quote(str(Path(out).absolute()))}"


def follow_and_fetch(client: DaemonClient, job_id: int, out: Path | None, *, no_progress: bool,
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
            _fetch_result(client, job_id, out)
        if row.get("kind") == "calibration":
            _calibration_fetched(client, job_id, out)
            return 0
    except DaemonUnreachable as exc:
        if not last:
            raise
        print(lost_daemon_message(client.url, job_id, last, str(exc), again, queued_here),
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
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


def _fetch_result(client: DaemonClient, job_id: int, out: Path) -> None:
    """Write completed job ``job_id``'s result file, as the daemon serves it, to ``out``
    (whole or not at all: a fetch cut short leaves no truncated file under that name); when
    that fails, say that the daemon keeps it and how to fetch it elsewhere."""
    import contextlib
    import os

    result = client.request("GET", f"/api/v1/jobs/{job_id}/result")
    part = out.with_name(f".{out.name}.part")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        part.write_bytes(result.content)
        os.replace(part, out)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            part.unlink(missing_ok=True)
        if not isinstance(exc, OSError):
            raise
        why = exc.strerror or str(exc)
        raise UsageError(f"job {job_id} completed, but its result could not be written to "
                         f"{out} ({why}); the daemon keeps it: fetch it elsewhere with "
                         f"'{wait_command(client.url, job_id, None)} -o FILE'") from None


def _calibration_fetched(client: DaemonClient, job_id: int, out: Path | None) -> None:
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
    cal_out = out.with_name(out.stem + ".calibration.json")
    cal_out.write_text(json.dumps(json.loads(made), indent=2))
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


def _follow(client: Any, job_id: int, disabled: bool, poll_s: float = 0.5,
            seen: dict[str, Any] | None = None) -> dict[str, Any]:
    """Poll the job with a progress bar until it ends; returns its last detail (``seen``, when
    given, holds the last detail answered, for a message if the daemon goes away)."""
    from tqdm import tqdm

    # The first answer before the bar: a job the daemon does not have (gonio jobs wait 99)
    # is refused without an empty bar above the refusal.
    row: dict[str, Any] = client.request("GET", f"/api/v1/jobs/{job_id}")
    bar = tqdm(total=None, unit="angle", desc=f"job {job_id}", disable=disabled, file=sys.stderr)
    told: str | None = None
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
                bar.write(_suspended_line(job_id, reason, through_daemon=True),
                          file=sys.stderr)
            told = reason
            if row["state"] in _FINAL:
                return row
            time.sleep(poll_s)
            row = client.request("GET", f"/api/v1/jobs/{job_id}")
    finally:
        bar.close()


def _suspended_line(job_id: int, reason: str, through_daemon: bool = False) -> str:
    """What a terminal shows when a job suspends: the bar alone said 'suspended' and no why,
    and then nothing while the job waited for the device (a scan that seemed to hang)."""
    then = ("the daemon retries and goes on once it answers (Ctrl-C stops following, not the "
            "job)" if through_daemon else
            "the scan retries and goes on once it answers; Ctrl-C leaves the job paused, and "
            "the same command resumes it")
    return f"job {job_id} suspended: {reason}\n  {then}"


def _progress(service: Any, job_id: int, disabled: bool) -> Any:
    from tqdm import tqdm

    bar = tqdm(total=None, unit="angle", desc=f"job {job_id}", disable=disabled, file=sys.stderr)

    def on_event(ev: Any) -> None:
        if ev.job_id != job_id:
            return
        if ev.type == "progress":
            bar.total = ev.data["total"]
            bar.n = ev.data["done"]
            eta = ev.data.get("eta_s")
            bar.set_postfix_str(f"eta {eta:.0f} s" if eta is not None else "")
            bar.refresh()
        elif ev.type == "state":
            bar.set_description_str(f"job {job_id} {ev.data['state']}")
            if ev.data["state"] == "suspended" and ev.data.get("reason"):
                bar.write(_suspended_line(job_id, ev.data["reason"]), file=sys.stderr)
        elif ev.type in ("arc_warning", "physical_bounds", "design_gap", "arc_asymmetric"):
            bar.write(f"warning: {ev.data['message']}", file=sys.stderr)
        elif ev.type == "arc_test":
            bar.write(f"arc: {ev.data['message']}", file=sys.stderr)
        elif ev.type == "adaptive_done" and ev.data.get("message"):
            # Stopped at the plan's limit while its rule still asked for more angles.
            bar.write(f"note: {ev.data['message']}", file=sys.stderr)

    service.add_event_listener(on_event)
    return bar


def _jobs(args: argparse.Namespace) -> int:
    from gonio.store import JobStore

    if args.action != "wait" and (args.output is not None or args.no_progress):
        raise UsageError("-o and --no-progress go with wait (gonio jobs --daemon URL wait ID "
                         "-o FILE)")
    if args.daemon is not None:
        return _jobs_through_daemon(args)
    if args.action == "wait":
        raise UsageError(
            "jobs wait follows a job a daemon runs: give its address, e.g. 'gonio jobs --daemon "
            f"http://127.0.0.1:8600 wait {args.job_id if args.job_id is not None else 'ID'} "
            "-o FILE' (a job of a foreground 'gonio scan' is followed by that scan; run the same "
            "command again to resume one it left)")
    if args.action in ("cancel", "reorder"):
        raise UsageError(
            f"jobs {args.action} acts on a daemon's queue: give its address, e.g. 'gonio jobs "
            f"--daemon http://127.0.0.1:8600 {args.action} "
            f"{args.job_id if args.job_id is not None else 'ID'}"
            + (" --position 0'" if args.action == "reorder" else "'")
            + " (the key in $GONIO_API_KEY or --api-key)")
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
        print(json.dumps([{"id": r.id, "state": r.state.value, "kind": r.kind,
                           "specimen": r.specimen, "done": r.done_angles,
                           "total": r.total_angles, "reason": r.reason,
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


def _jobs_through_daemon(args: argparse.Namespace) -> int:
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
                         "rebuild ID --db DATA_DIR' on the daemon's data directory (the daemon "
                         "may keep running: it serves the rebuilt file)")
    if args.action != "reorder" and (args.position is not None or args.priority is not None
                                     or args.accept_uncalibrated):
        raise UsageError("--position, --priority and --accept-uncalibrated go with reorder")
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
                print(f"{r['id']:>4}  {r['state']:<14} {r['kind']:<11} "
                      f"{r['done_angles']:>4}/{r['total_angles']:<4}  {r['specimen']}"
                      + (f"  ({why})" if why else ""))
            return 0
        job = args.job_id
        assert job is not None  # refused above
        if args.action == "wait":
            if args.json:
                raise UsageError(f"wait prints the scan's summary; 'gonio jobs --daemon "
                                 f"{args.daemon} show {job} --json' gives the job as JSON")
            if args.output is not None:
                # Before the wait, not after an hour's scan.
                _check_output(args.output, "nothing was fetched; the daemon keeps the job")
            return follow_and_fetch(client, job, args.output, no_progress=args.no_progress)
        if args.action == "show":
            row = client.request("GET", f"/api/v1/jobs/{job}")
            print(json.dumps(row, indent=2) if args.json else
                  f"job {job}: {row['kind']} '{row['specimen']}', {row['state']}, "
                  f"{row['done_angles']}/{row['total_angles']} angles, priority "
                  f"{row.get('priority', 0)}"
                  + (f" ({row['reason']})" if row.get("reason") else "")
                  + (f"\n  result: {args.daemon.rstrip('/')}/api/v1/jobs/{job}/result "
                     f"(fetch it: {wait_command(client.url, job, None)} -o FILE)"
                     if row["state"] == "completed" else ""))
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
        return 0
    state = row.get("state", "?")
    if args.action == "cancel":
        print(f"job {job} cancelled: taken out of the queue, it will not run (state {state})")
    elif args.action == "abort":
        print(f"job {job}: abort asked (state {state}; lights off and the stage stopped, its "
              f"readings stay in the store; 'gonio jobs --daemon {args.daemon} show {job}' "
              "says when it has ended)")
    else:
        print(f"job {job} reordered: priority {row.get('priority', 0)}, state {state}")
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
    from gonio.timeleft import QueuedRun, finishing_estimate, start_estimates

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
        finishing=(finishing_estimate(store.list_jobs(["completed"]))
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
    for line in _detail_lines(d):
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


def _detail_lines(d: dict[str, Any]) -> list[str]:
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
    lines.append("  (--json: every field, as GET /api/v1/jobs/ID)")
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
    return queue_wait(((r.id, r.state) for r in rows if r.state in ACTIVE_STATES),
                      hold[0] if hold is not None else None, maintenance)


def _interrupted_note(db: Path, rows: list[Any]) -> str | None:
    """What the list's 'running' (or suspended, reconstructing) means when no process runs
    jobs from the store: the job was interrupted (a daemon stopped, SIGTERM or kill -9; a
    gonio scan killed) and waits for the next one; None when nothing is active or a process
    holds the store."""
    from gonio.locks import LockBusy, claim_store

    active = [r for r in rows if r.state.value in ("running", "suspended", "reconstructing")]
    if not active:
        return None
    try:
        claim_store(db).release()
    except LockBusy:
        return None  # a daemon or a gonio scan runs them: the states are live
    except OSError:
        return None  # cannot tell (no write access to the store's directory)
    return _interrupted_text(db, active)


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
    from gonio.finishing import rebuild_result
    from gonio.store import NotFound

    if args.job_id is None:
        raise UsageError("jobs rebuild needs a job id, e.g. 'gonio jobs rebuild 3 --db "
                         "DATA/gonio.sqlite'")
    data_dir = args.data_dir if args.data_dir is not None else args.db.resolve().parent
    try:
        before = store.get_job(args.job_id).state
    except NotFound as exc:
        raise UsageError(str(exc)) from None
    if before.value in ("completed", "failed"):
        # Only these may be rebuilt (rebuild_result refuses the others, saying why): the line
        # said "rebuilding" before the refusal of a paused job.
        print(f"rebuilding job {args.job_id}'s result from the job store's readings",
              file=sys.stderr)
    old = store.get_job(args.job_id).summary or {}
    summary = rebuild_result(store, data_dir, args.job_id, BasisSupply())
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
    with lock:
        store = JobStore(args.db)
        try:
            row = store.set_state(args.job_id, JobState.ABORTED, reason="aborted by request "
                                  "(gonio jobs abort)")
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
    return 0
