"""``gonio scan``: one job in the foreground, or submitted to a running daemon.

``gonio scan`` keeps its job in a data directory with the daemon's layout (``--data-dir``,
default one per rig geometry under the user data folder, :func:`gonio.paths.scan_data_dir`;
``--sim`` has its own, :func:`gonio.paths.sim_scan_data_dir`):
the job store ``gonio.sqlite`` (``--db`` overrides), ``results/job-<id>.h5`` and the latest
``calibration.json``. The only file written beside ``-o OUT.h5`` is ``OUT.h5`` itself (and, for
``--white-reference``, ``OUT.calibration.json``). If the store holds an unfinished job with the
same plan on the same rig (the previous run was killed), the scan resumes it from its last
checkpoint instead of starting again. With ``--daemon URL`` the scan is the daemon's job
(:mod:`gonio.cli.daemon_jobs`); ``gonio jobs`` is :mod:`gonio.cli.jobs_command`.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gonio.cli import (
    StoppedBySignal,
    UsageError,
    finite_float,
    nonnegative_float,
    positive_float,
    positive_int,
)
from gonio.cli.daemon_client import add_daemon_options
from gonio.wording import counted

if TYPE_CHECKING:
    from gonio.basis_supply import BasisSupply
from gonio.cli.scan_report import (
    FINAL_STATES,
    appeared_text,
    calibration_copy_path,
    check_output_path,
    dry_run_summary,
    print_scan_summary,
    resumed_line,
    suspended_line,
    write_output,
)


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
    p.add_argument("--rule", choices=["posterior", "vf"], default=None,
                   help="with --adaptive: the refinement rule, posterior (default; where the "
                        "joint fit expects the error to fall most) or vf (V&F's PCHIP "
                        "midpoints)")
    p.add_argument("--min-gain", type=positive_float, default=None,
                   help="posterior rule: least drop of the self-estimated log_rmse a new "
                        "stage angle must buy (default 0.00002)")
    p.add_argument("--max-rotations", type=positive_int, default=None,
                   help="with --adaptive: most stage angles in all, the first round's included "
                        "(default 16 with the posterior rule, no cap with --rule vf)")
    p.add_argument("--threshold", type=positive_float, default=None,
                   help="with --adaptive, vf rule: relative error e (default 0.1)")
    p.add_argument("--max-samples", type=positive_int, default=None,
                   help="with --adaptive: the sample budget")
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
    p.add_argument("--json", action="store_true", help="with --dry-run: the full plan as "
                   "JSON; with --daemon --no-wait: the queued job as JSON")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-export-fits", action="store_true",
                   help="finish without the export fits (several seconds of CPU sooner); "
                   "'gonio export' then fits when it exports")
    # Required but for --daemon URL --no-wait (checked in _scan, which says so).
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="result file (.h5); required, except with --daemon URL --no-wait")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing -o file (and a calibration's OUTPUT."
                        "calibration.json); without it an existing file is refused before "
                        "anything moves")
    p.set_defaults(func=_scan)


def _plan(args: argparse.Namespace) -> Any:
    from gonio.plans.models import AdaptivePlan, CalibrationPlan, ExposureSettings, UniformPlan

    ex = ExposureSettings(exposure_s=args.exposure, averages=args.averages,
                          light_settle_s=args.light_settle)
    # Without --adaptive the adaptive options were silently dropped ('--rule vf' alone ran
    # the default uniform scan over half a turn, though --help says vf's default is a full
    # turn).
    adaptive_only = [flag for flag, v in (("--rule", args.rule), ("--min-gain", args.min_gain),
                                          ("--max-rotations", args.max_rotations),
                                          ("--threshold", args.threshold),
                                          ("--max-samples", args.max_samples)) if v is not None]
    if adaptive_only and not args.adaptive:
        raise UsageError(f"{', '.join(adaptive_only)} only apply to an adaptive scan: add "
                         "--adaptive, or drop them for a uniform scan of --rotations angles")
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
                                   ("threshold", args.threshold),
                                   ("span_deg", args.span)) if v is not None}
        return AdaptivePlan(specimen=_specimen(args), exposure=ex,
                            rule=args.rule or "posterior", max_samples=args.max_samples,
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
    if args.output is None and not args.no_wait and not args.dry_run:
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
        check_output_path(args.output, overwrite=args.overwrite,
                          calibration=args.white_reference is not None)
    if args.daemon:
        from gonio.cli.daemon_jobs import scan_through_daemon

        return scan_through_daemon(args, plan)
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
    import signal

    stopped: list[str] = []
    args.stopped_by = stopped
    # Set once the job has completed: a signal then no longer stops anything but lets the
    # result's copy to -o finish (it is a moment's work, and stopping it would lose it).
    finished: list[bool] = []
    args.scan_finished = finished
    # The loop's close resets the signals it handled to the default: give back the handlers
    # the process had (a test runner's, when main() runs in it).
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)}

    async def run() -> int:
        _stop_on_terminate(stopped, finished)
        return await _run_scan(args, plan, config, sim)

    try:
        return asyncio.run(run())
    except asyncio.CancelledError:
        if not stopped:
            raise
        # Stopped by SIGTERM or SIGHUP: the job was left as Ctrl-C leaves it, and said so.
        raise StoppedBySignal(signal.Signals[stopped[0]]) from None
    finally:
        for sig, handler in before.items():
            with contextlib.suppress(ValueError, TypeError):  # not the main thread
                signal.signal(sig, handler)
        if sim is not None:
            sim.close()


SIM_SCAN_MATERIALS = "sim-scan-materials.json"
"""In a ``gonio scan --sim`` data directory: the simulated material each job measured, by
job id (``null`` for the default), so an interrupted job resumes only on its own."""


def _sim_materials(data_dir: Path) -> dict[str, Any]:
    import json

    try:
        data = json.loads((data_dir / SIM_SCAN_MATERIALS).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _same_sim_material(data_dir: Path, job: Any, material: str | None, db: Path) -> None:
    """Refuse to resume ``job`` (the interrupted job this ``gonio scan --sim`` would resume,
    or None) when it was measuring another simulated material than ``material``.

    The plan and rig alone decided a resume, so ``--material pile-000`` after an interrupted
    scan of the default material finished that job on the new specimen: 18 angles of one
    material and 14 of another in one result, which named only the second as its truth. A
    job interrupted while reconstructing measures nothing more (its finishing records the
    truth it kept, :mod:`gonio.finishing`): it resumes whatever the material.
    """
    from gonio.jobstates import JobState

    if job is None or job.state is JobState.RECONSTRUCTING:
        return
    recorded = _sim_materials(data_dir)
    if str(job.id) not in recorded:
        return  # recorded by no earlier run (an older gonio): as before
    was_material = recorded[str(job.id)]
    if was_material == material:
        return
    was = "the default material" if was_material is None else f"material {was_material!r}"
    now = "the default material" if material is None else f"material {material!r}"
    again = "without --material" if was_material is None else f"with --material {was_material}"
    raise UsageError(
        f"job {job.id} was measuring {was} when it was interrupted ({job.done_angles} of "
        f"{job.total_angles} angles): its readings cannot be joined with {now}'s, so nothing "
        f"was measured. Run the same command {again} to finish it, or end it first ('gonio "
        f"jobs abort {job.id} --db {db}') and scan {now} again")


def _record_sim_material(data_dir: Path, job_id: int, material: str | None) -> None:
    """Note that job ``job_id`` measures ``material`` (:data:`SIM_SCAN_MATERIALS`)."""
    import json

    from gonio.atomicfile import write_atomically

    recorded = _sim_materials(data_dir)
    recorded[str(job_id)] = material
    write_atomically(data_dir / SIM_SCAN_MATERIALS, json.dumps(recorded).encode())


def _stop_on_terminate(stopped: list[str], finished: list[bool] | None = None) -> None:
    """Make SIGTERM and SIGHUP (``kill``, ``timeout``, a closed terminal or SSH session) stop
    the running foreground scan as Ctrl-C does: the engine stops and switches the lamps off,
    the job is left paused at its checkpoint and the message says how to go on. They killed
    the process where it stood: the job stayed ``running``, nothing was said, and the lamps
    were left as they were. A second SIGTERM stops the process at once; a second SIGHUP is
    ignored, and a signal ignored when the scan starts (``nohup``) stays ignored.

    Once the job has completed (``finished`` non-empty) there is no scan left to stop: the
    signal is noted and the command ends as it would have, copying the result to ``-o`` and
    printing its summary. (It was reported "interrupted", exit 130, and the copy skipped.)

    Call from the scan's main task (``asyncio.run``'s); ``stopped`` gets the signal's name.
    """
    import asyncio
    import os
    import signal

    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    assert task is not None

    def stop(sig: signal.Signals) -> None:
        if stopped:
            if sig is signal.SIGHUP:
                return  # a hangup says nothing more the second time; it never kills
            loop.remove_signal_handler(sig)  # back to the default: the second one kills
            os.kill(os.getpid(), sig)
            return
        stopped.append(sig.name)
        done = bool(finished)
        if not done:
            task.cancel()  # first: the message below can fail on a terminal that is gone
        try:
            print(f"{sig.name} received: " + (
                "the scan has already completed; writing its result and stopping" if done
                else "stopping the scan as Ctrl-C does"), file=sys.stderr, flush=True)
        except OSError:
            # The terminal is gone (a closed SSH session: EIO). Every later message would
            # fail the same way and cut the stop short: they go nowhere instead.
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            os.close(devnull)

    for sig in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is signal.SIG_IGN:
            continue  # nohup (or a parent) asked that it be ignored: it stays so
        with contextlib.suppress(ValueError, RuntimeError):  # not the main thread: as before
            loop.add_signal_handler(sig, stop, sig)


def _copy_result(src: Path, out: Path, job_id: int, *, overwrite: bool,
                 what: str = "its result") -> None:
    """Copy a completed job's file ``src`` (its result, or a calibration's calibration) to
    ``out`` (:func:`write_output`: a file that appeared there meanwhile is replaced only with
    ``overwrite``); when that fails, say where the file is."""
    try:
        write_output(out, src.read_bytes(), overwrite=overwrite)
    except FileExistsError:
        raise UsageError(appeared_text(out, job_id, f"it is kept in {src}: copy it from there, "
                                       "or give the scan --overwrite to replace such a file"
                                       )) from None
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise UsageError(f"job {job_id} completed, but {what} could not be copied to "
                         f"{out} ({why}); it is kept in {src}: copy it from there") from None


async def _run_scan(args: argparse.Namespace, plan: Any, config: Any, sim: Any = None) -> int:
    from gonio.basis_supply import BasisSupply
    from gonio.drivers.factory import build_rig
    from gonio.plans.arc import may_switch_basis
    from gonio.plans.dryrun import dry_run
    from gonio.rigdescription import RigDescription

    rig = build_rig(config)
    desc = RigDescription.from_rig(rig)
    # The in-process scan reconstructs with the default basis (built on first use), loaded
    # once for this run by whoever needs it first.
    basis = BasisSupply()
    if args.dry_run:
        est = _local_finishing(args, config)
        dr = dry_run(plan, desc, basis_ready=not basis.build_needed(), basis=basis.symmetry(),
                     asymmetric_build_s=(basis.asymmetric_build_s()
                                         if may_switch_basis(plan) else None),
                     finishing_s=est.seconds, finishing_source=est.source)
        more = [] if sim is not None else _calibration_warnings(args, plan, config, dr.pairs)
        if more:
            dr = dr.model_copy(update={"warnings": [*dr.warnings, *more]})
        print(dr.model_dump_json(indent=2) if args.json
              else dry_run_summary(dr, plan, config.rig.name,
                                   sim_calibration_s=_sim_calibration_s(args, plan, config,
                                                                        desc, sim),
                                   time_scale=args.time_scale if sim is not None else 1.0))
        return 0
    if args.json:
        raise UsageError("--json goes with --dry-run")
    from gonio.plans.checked import check_plan

    # Refuse a bad plan before connecting to anything; the check goes with the plan from here
    # (the dry run below and the submission do not make it again).
    checked = check_plan(plan, desc)
    from gonio.daemon import STORE_FILE
    data_dir = args.data_dir or own_data_dir(args, config)
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

    from gonio.cli.sim_session import attach_sim, calibrate_in_foreground, sim_calibration_needed
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
                           calibration=override, fit_exports=not args.no_export_fits,
                           own_data_dir=own_data_dir(args, config))
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
        if sim is not None:
            _same_sim_material(data_dir, job, getattr(args, "material", None), db)
            if job is not None and job.state is not JobState.RECONSTRUCTING:
                _record_sim_material(data_dir, job.id, getattr(args, "material", None))
        if job is not None:
            print(f"resuming job {job.id} from its checkpoint ({job.done_angles} of "
                  f"{job.total_angles} angles done)", file=sys.stderr)
            if job.state is JobState.PAUSED:
                # Left paused by Ctrl-C (or by a daemon): running this command again is the
                # user's resume; the engine would otherwise wait for an API call that never
                # comes in the foreground.
                store.set_state(job.id, JobState.RUNNING)
        else:
            for line in _other_unfinished(store, db):
                print(line, file=sys.stderr)
            exposure_s = plan.exposure.exposure_s
            if (sim is not None and override is None and plan.kind != "calibration"
                    and sim_calibration_needed(service.calibration(), service.desc.pairs,
                                               service.rig_config, exposure_s)):
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
        if sim is not None and plan.kind != "calibration":
            _record_sim_material(data_dir, job.id, getattr(args, "material", None))
        bar = _progress(service, job.id, disabled=args.no_progress)
        try:
            final = await service.run_in_foreground(job.id)
            if final is JobState.COMPLETED:
                finished = getattr(args, "scan_finished", None)
                if finished is not None:
                    finished.append(True)
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
    _copy_result(service.result_path(job.id), out, job.id, overwrite=args.overwrite)
    summary = row.result or {}
    if plan.kind == "calibration":
        from gonio.calibration import CALIBRATION_FILE

        cal_out = calibration_copy_path(out)
        _copy_result(data_dir / CALIBRATION_FILE, cal_out, job.id, overwrite=args.overwrite,
                     what="its calibration")
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


def _sim_calibration_s(args: argparse.Namespace, plan: Any, config: Any, desc: Any,
                       sim: Any) -> float | None:
    """How long the calibration ``gonio scan --sim`` runs before this plan takes, measuring
    the simulated white reference (as :func:`_run_owned` decides it: no calibration of every
    pair at the plan's exposure in effect in the data directory, and no ``--calibration``),
    or None when it runs none. The dry run said nothing of it, so the first scan took longer
    than it said."""
    from gonio.calibration import Calibration, calibration_in_effect
    from gonio.cli.sim_session import sim_calibration_needed, sim_calibration_plan
    from gonio.plans.dryrun import dry_run

    if sim is None or args.calibration is not None or plan.kind == "calibration":
        return None
    cal = calibration_in_effect(args.data_dir or own_data_dir(args, config), config)
    exposure_s = plan.exposure.exposure_s
    if isinstance(cal, Calibration) and not sim_calibration_needed(cal, desc.pairs, config,
                                                                   exposure_s):
        return None
    return float(dry_run(sim_calibration_plan(None, exposure_s), desc).estimated_s)


def _calibration_warnings(args: argparse.Namespace, plan: Any, config: Any,
                          pairs: Any) -> list[str]:
    """The dry run's ``uncalibrated: ...`` and ``exposure: ...`` warnings for ``plan``
    (measuring ``pairs``) on this rig, if any."""
    from gonio.calibration import (
        Calibration,
        ChannelMismatch,
        calibration_in_effect,
        exposure_warning,
        sensor_channels,
        uncalibrated_warning,
    )

    if plan.kind == "calibration":
        return []
    if args.calibration is not None and args.calibration.is_file():
        cal = _read_calibration(args.calibration)
    else:
        cal = calibration_in_effect(args.data_dir or own_data_dir(args, config), config)
    cal = cal if isinstance(cal, Calibration) else Calibration()
    uncal = uncalibrated_warning(cal, pairs)
    try:
        cal.check_channels(pairs, sensor_channels(config), "this plan")
        channels = None
    except ChannelMismatch as exc:
        # The submission refuses it: the dry run must not say the scan would run.
        channels = f"not calibrated: {exc}"
    return [w for w in (_how_to_calibrate(uncal, args), channels,
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

    warning = _how_to_calibrate(uncalibrated_warning(cal, pairs), args)
    if warning is None or cal.pairs:
        return  # covered, or partly: the submission refuses it, saying which pairs
    own: Path | None = own_data_dir(args, config)
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


def _other_unfinished(store: Any, db: Path) -> list[str]:
    """Notes on the unfinished jobs of this job store that this scan does not resume (another
    plan or specimen: e.g. ``-o`` named differently after a Ctrl-C, which names the specimen),
    so a paused scan is not forgotten: this one starts as a new job."""
    lines = []
    for row in store.active_jobs():
        lines.append(
            f"note: job {row.id} ('{row.specimen}', {row.state.value}, {row.done_angles} of "
            f"{row.total_angles} angles) is another unfinished job in this job store; this "
            "scan does not resume it (its plan, specimen or rig differs) and starts a new "
            f"job. Job {row.id} goes on when the command that started it runs again with the "
            "same plan and rig config (a daemon's job: when a daemon runs this data "
            f"directory again); 'gonio jobs abort {row.id} --db {db}' ends it")
    return lines


def _left_interrupted(store: Any, job_id: int, db: Path, args: argparse.Namespace) -> None:
    """Mark a job whose foreground run was interrupted ``paused`` (a measuring one; one that
    was reconstructing stays so and is finished at the next run) and print how to resume or
    abort it."""
    from gonio.jobstates import JobState

    row = store.get_job(job_id)
    if row.state in (JobState.RUNNING, JobState.SUSPENDED):
        by = (getattr(args, "stopped_by", None) or [None])[0]
        how = f"{by} to gonio scan" if by else "Ctrl-C in gonio scan"
        row = store.set_state(job_id, JobState.PAUSED, reason=f"interrupted ({how})")
    if row.state.value in FINAL_STATES:
        return
    print(f"job {job_id} interrupted: {row.state.value} at its checkpoint, "
          f"{row.done_angles} of {row.total_angles} angles measured. Run the same command "
          f"again to resume it, or abort it with: gonio jobs abort {job_id} --db {db}",
          file=sys.stderr, flush=True)


def own_data_dir(args: argparse.Namespace, config: Any) -> Path:
    """The data directory ``gonio scan`` uses without ``--data-dir``: ``--sim``'s own
    (:func:`gonio.paths.sim_scan_data_dir`), else the rig's (:func:`gonio.paths.scan_data_dir`,
    which ``gonio serve --rig`` shares)."""
    from gonio.paths import scan_data_dir, sim_scan_data_dir

    return sim_scan_data_dir(config) if getattr(args, "sim", False) else scan_data_dir(config)


def _local_finishing(args: argparse.Namespace, config: Any) -> Any:
    """The finishing estimate of the job store this scan would use (its last scans), read
    without creating anything: a dry run leaves no store behind."""
    from gonio.daemon import STORE_FILE
    from gonio.store import JobStore
    from gonio.timeleft import finishing_estimate, most_channels

    db = args.db or (args.data_dir or own_data_dir(args, config)) / STORE_FILE
    if not Path(db).is_file():
        return finishing_estimate([], most_channels(config))
    store = JobStore(db, durable=False)
    try:
        return finishing_estimate(store.list_jobs(["completed"]), most_channels(config))
    finally:
        store.close()


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
                bar.write(suspended_line(job_id, ev.data["reason"]), file=sys.stderr)
            elif ev.data["state"] == "running" and ev.data.get("from") == "suspended":
                bar.write(resumed_line(job_id), file=sys.stderr)
        elif ev.type in ("arc_warning", "physical_bounds", "design_gap", "arc_asymmetric"):
            bar.write(f"warning: {ev.data['message']}", file=sys.stderr)
        elif ev.type == "arc_test":
            bar.write(f"arc: {ev.data['message']}", file=sys.stderr)
        elif ev.type == "adaptive_done" and ev.data.get("message"):
            # Stopped at the plan's limit while its rule still asked for more angles.
            bar.write(f"note: {ev.data['message']}", file=sys.stderr)

    service.add_event_listener(on_event)
    return bar
