"""The one module the REST layer sits on: jobs, control, events, results, rig status.

A thin door: it checks requests and hands them to the part that owns them. The queue runner
(:mod:`gonio.worker`), event pub/sub (:mod:`gonio.event_hub`), the served results and their
caches (:mod:`gonio.result_views`), manual stage commands (:mod:`gonio.stage_control`) and the
reconstruction basis (:mod:`gonio.basis_supply`) live in their own modules.

Every request and response type is a pydantic model (:mod:`gonio.service_models`, re-exported
here; they become the API schema). Errors are typed so the API can map them: :class:`NotFound`
-> 404, :class:`Conflict` (including :class:`gonio.jobstates.IllegalTransition`) -> 409,
:class:`gonio.plans.models.PlanError` and :class:`gonio.motion.StageMoveError` -> 422.

Typical use::

    service = GonioService(JobStore(db), rig_factory, rig_config=cfg, data_dir=data)
    await service.start()          # reconcile the store, start the worker
    info = service.submit(JobRequest(plan=UniformPlan(rotations=8)))
    async for ev in service.subscribe(since_seq=0): ...
    await service.stop()
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections.abc import AsyncIterator, Callable, Coroutine, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from pydantic import BaseModel

from gonio import hal
from gonio.basis_supply import BasisSupply
from gonio.calibration import (
    Calibration,
    calibration_in_effect,
    exposure_warning,
    uncalibrated_refusal,
    uncalibrated_warning,
)
from gonio.diskspace import DiskFull, disk_full_message, is_disk_full, low_space
from gonio.engine import PAUSE_ASKED_EVENT
from gonio.engine_loop import EngineLoop
from gonio.event_hub import EventHub
from gonio.finishing import rebuild_hint
from gonio.jobstates import (
    ACTIVE_STATES,
    FINISHED_STATES,
    IllegalTransition,
    JobState,
    check_action,
    queue_wait,
)
from gonio.maintenance import LOCK_FILE_NAME, MaintenanceLock
from gonio.paths import scan_data_dir
from gonio.plans.arc import may_switch_basis
from gonio.plans.checked import CheckedPlan, check_plan
from gonio.plans.dryrun import BASIS_BUILD_S, DryRun, arc_may_apply, dry_run
from gonio.plans.models import (
    DEFAULT_SPAN_DEG,
    AnyPlan,
    PlanError,
    parse_plan,
    parse_stored_plan,
)
from gonio.plans.validation import plan_pairs
from gonio.queue_exposure import StartCalibration, exposure_clashes
from gonio.result_views import ResultViews, download_stem
from gonio.rigdescription import RigDescription
from gonio.service_models import (
    Conflict,
    DeviceError,
    DeviceState,
    Event,
    JobDetail,
    JobInfo,
    JobRequest,
    NotFound,
    ReorderRequest,
    RigStatus,
    RunningJob,
    ServiceStatus,
    StageRequest,
    StageState,
    job_row,
)
from gonio.stage_control import StageControl
from gonio.store import EventRow, JobRow, JobStore, ReadingRow
from gonio.store import NotFound as StoreNotFound
from gonio.timeleft import (
    FinishingEstimate,
    QueuedRun,
    StartEstimate,
    finishing_estimate,
    most_channels,
    start_estimates,
)
from gonio.worker import Worker

if TYPE_CHECKING:  # the design numerics load on the first design, not with the service
    from gonio.brdf.reconstruction.basis import Basis
    from gonio.results import ResultFile
    from gonio.sampling_design import DesignRequest, DesignResult

log = logging.getLogger("gonio.service")
JOB_LOG = logging.getLogger("gonio.jobs")
"""The daemon's console line per job (``gonio.daemon.log_job_events`` writes the others)."""

__all__ = [
    "Conflict",
    "DeviceError",
    "DeviceState",
    "Event",
    "GonioService",
    "IllegalTransition",
    "JobDetail",
    "JobInfo",
    "JobRequest",
    "NotFound",
    "PlanError",
    "ReorderRequest",
    "RigStatus",
    "RunningJob",
    "ServiceStatus",
    "StageRequest",
    "StageState",
]


T = TypeVar("T")
CALIBRATION_AHEAD = "calibration_ahead"
"""Key of a scan's ``created`` event data: the calibration job that let it be queued without
asking (:meth:`GonioService.unasked_uncalibrated` names it, and how it ended)."""
UNCALIBRATED_ACCEPTED = "uncalibrated_accepted"
"""Key of a scan's ``created`` event data (whether its user accepted that it may measure
uncalibrated), and the type of the event a reorder with ``accept_uncalibrated`` records on each
scan it moves ahead of a queued calibration (:meth:`GonioService.unasked_uncalibrated`)."""


# --------------------------------------------------------------------------- service
#: How long ``resume`` waits for the engine to take the request before it answers, s.
RESUME_ANSWER_WAIT_S = 5.0


def _on_an_event_loop() -> bool:
    """The caller runs inside an event loop (it must not block it)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return False
    return True


def _plan_exposure(row: JobRow) -> float | None:
    """The exposure a job's stored plan reads at, seconds, or None when it records none."""
    at = (row.plan.get("exposure") or {}).get("exposure_s")
    return float(at) if isinstance(at, int | float) else None


def _measures_at(row: JobRow, exposure_s: float) -> bool:
    """Whether job ``row``'s plan reads at ``exposure_s`` (an unrecorded exposure does not)."""
    at = _plan_exposure(row)
    return at is not None and math.isclose(at, exposure_s, rel_tol=1e-6)


class GonioService:
    """Jobs, control and events over one rig.

    Parameters
    ----------
    store : JobStore
    rig : a :class:`gonio.hal.Rig`, or a callable building one (connected on first use)
    rig_config : the :class:`gonio.config.RigConfig` (snapshot in results; its
        ``[calibration]`` factors are used until a calibration job replaces them)
    basis : the process's reconstruction basis, shared with the worker and finishing
        (default: a :class:`gonio.basis_supply.BasisSupply` of the default basis)
    data_dir : folder for result files and the latest calibration
    calibration : applied to every scan instead of the one in effect (``gonio scan
        --calibration``); default: :meth:`calibration`'s rule
    fit_exports : store the export fits in every scan's result (``[results] export_fits``;
        False: scans finish seconds sooner and each export fits when it is made)
    own_data_dir : the rig's own data directory, whose calibration a scan here would be
        uncalibrated against (:meth:`uncalibrated_refusal`); default: ``gonio scan``'s for the
        rig config (:func:`gonio.paths.scan_data_dir`); ``gonio scan --sim`` gives its own
    """

    def __init__(
        self,
        store: JobStore,
        rig: hal.Rig | Callable[[], hal.Rig],
        rig_config: Any = None,
        basis: BasisSupply | None = None,
        data_dir: str | Path = "gonio-data",
        calibration: Calibration | None = None,
        fit_exports: bool = True,
        own_data_dir: Path | None = None,
    ):
        self.store = store
        self._own_data_dir = own_data_dir
        self._calibration = calibration
        self._rig: hal.Rig = rig if isinstance(rig, hal.Rig) else rig()
        self.rig_config = rig_config
        # Absolute once: result paths in the store are relative to it, and must not follow
        # the process's working directory.
        self.data_dir = Path(data_dir).absolute()
        self.desc = RigDescription.from_rig(self._rig)
        self._max_angles_of: dict[int, int | None] = {}  # adaptive jobs' bound (_max_angles)
        # Queued jobs' dry-run measuring time and whether it is a bound (_measuring_estimate).
        self._measuring_of: dict[int, tuple[float, bool] | None] = {}
        self._finishing_cache: tuple[float, FinishingEstimate] | None = None
        self._connected = False
        self._connect_error: str | None = None
        self._connect_lock = asyncio.Lock()
        self._task: asyncio.Task[None] | None = None  # the worker, on the engine loop
        # The worker, the engine and every device call run on their own loop and thread, so
        # request handling on the API's loop cannot delay a scan (gonio/engine_loop.py).
        self._engine = EngineLoop()
        self.events = EventHub(store)
        """Event pub/sub over the store (:meth:`subscribe` and the listeners go through it)."""
        self.results = ResultViews(store, self.data_dir)
        """Every read of a result file for serving, and its caches."""
        self.stage_deg: float | None = None
        """Last known stage position, degrees (None until a job or a manual move reports it)."""
        self._design_lock = threading.Lock()  # one sampling design at a time (self.design)
        self.basis = basis if basis is not None else BasisSupply()
        # OS locks this service owns for its life (data directory, rig endpoints: see
        # gonio.daemon.build_app); released by stop().
        self.owned: list[Any] = []
        # Why the worker died, once it has: /health then fails and the daemon exits non-zero.
        self.worker_failure: str | None = None
        self.on_fatal: Callable[[], None] | None = None
        provenance: dict[str, Any] = {}
        if rig_config is not None and hasattr(rig_config, "model_dump_json"):
            provenance["rig_config"] = rig_config.model_dump_json()
        # While the maintenance lock (a file in the data directory) is set, no job starts.
        self.maintenance = MaintenanceLock(self.data_dir / LOCK_FILE_NAME)
        self.worker = Worker(
            store, self._get_rig, self.desc, self.data_dir, self.basis, self.calibration,
            provenance, gate=self.maintenance.reason, fit_exports=fit_exports,
        )
        self.worker.start_refusal = self.unasked_uncalibrated
        self.stage = StageControl(self.desc, self._get_rig, self.worker, self.active_job,
                                  self.record_event)
        """Manual stage commands (commissioning, loading specimens)."""
        store.add_listener(self._track_stage)
        store.add_listener(self._track_completions)

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        """Reconcile jobs left active by a previous process and start the worker.

        The worker runs on the service's engine loop, a thread of its own
        (:class:`gonio.engine_loop.EngineLoop`); this loop serves requests and events.
        """
        self.events.start()
        try:
            self.store.reconcile(self._can_resume)
        except Exception as exc:
            if not is_disk_full(exc):
                raise
            # Start anyway (``/health`` says why nothing runs): the jobs left active stay
            # as they are and are reconciled once the disk has room.
            self.worker.note_disk_full(
                disk_full_message("the job store's start-up records", self.store.path),
                lambda: self.store.reconcile(self._can_resume))
        low = low_space(self.data_dir)
        if low is not None:
            self.worker.note_disk_full(low)
        self._engine.start()
        await self._engine.run(self._start_worker())

    async def _start_worker(self) -> None:
        self._task = asyncio.create_task(self._run_worker(), name="gonio-worker")

    async def _run_worker(self) -> None:
        """The worker's loop; if it ever raises, the daemon is broken and must say so.

        A worker that died silently left the API accepting jobs nobody would run; instead the
        failure is recorded (``/health`` answers 503 with it) and ``on_fatal`` asks the server
        to exit, with a non-zero status, so a supervisor (systemd) restarts the daemon. The job
        it was measuring stays active in the store and resumes from its checkpoint then.
        """
        try:
            await self.worker.run_forever()
        except asyncio.CancelledError:
            raise
        except BaseException as exc:
            self.worker_failure = f"{type(exc).__name__}: {exc}"
            log.critical("the job worker died (%s); the daemon stops so it can be restarted",
                         self.worker_failure, exc_info=exc)
            with contextlib.suppress(Exception):  # the store may be what failed
                self.store.append_event(None, "worker_failed", {"error": self.worker_failure})
            if self.on_fatal is not None:
                self.on_fatal()

    async def stop(self) -> None:
        """Stop the worker (an active job stays active and resumes at the next start)."""
        if self._engine.running:
            await self._engine.run(self._stop_worker())
            await asyncio.to_thread(self._engine.close)
        else:
            await self._stop_worker()
        self._say_what_stays_active()
        self.events.close()
        self.store.remove_listener(self._track_stage)
        self.store.remove_listener(self._track_completions)
        for lock in reversed(self.owned):
            lock.release()
        self.owned.clear()

    def _say_what_stays_active(self) -> None:
        """Log each job the stop leaves active and what the next start does with it: the
        console said only "Shutting down" of a scan stopped midway."""
        try:
            jobs = self.store.active_jobs()
        except Exception:  # the store may be what failed; the stop goes on
            log.debug("no list of active jobs at stop", exc_info=True)
            return
        then = {"paused": "it stays paused until resumed after the next start",
                "reconstructing": "its reconstruction starts again from the stored readings "
                                  "when the daemon starts again on this data directory"}
        for job in jobs:
            JOB_LOG.info("job %d (%s, %r) interrupted by the daemon's stop at %d of %d angles: "
                         "%s", job.id, job.kind, job.specimen, job.done_angles,
                         job.total_angles,
                         then.get(job.state.value, "it resumes from its checkpoint when the daemon "
                                         "starts again on this data directory"))

    async def _stop_worker(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        await self.worker.stop()
        if self._connected:
            await self._rig.close()
            self._connected = False

    async def _on_engine(self, coro: Coroutine[Any, Any, T]) -> T:
        """Run ``coro`` where the devices live: the engine loop once started, else here."""
        if self._engine.running:
            return await self._engine.run(coro)
        return await coro

    def _can_resume(self, job: JobRow) -> str | None:
        try:
            plan = parse_stored_plan(job.plan)
        except PlanError as exc:
            return f"interrupted by a restart and its plan no longer parses: {exc}"
        snap = job.rig.get("pairs")
        now = self.desc.model_dump(mode="json")["pairs"]
        if snap is not None and snap != now:
            return ("interrupted by a restart, and the rig's pairs changed since it started; "
                    "its readings cannot be combined with new ones. Submit it again")
        del plan
        return None

    async def _get_rig(self) -> hal.Rig:
        async with self._connect_lock:
            if not self._connected:
                try:
                    await self._rig.connect()
                except Exception as exc:
                    self._connect_error = str(exc)
                    raise
                self._connected = True
                self._connect_error = None
            return self._rig

    def design_basis(self) -> Basis:
        """The basis sampling designs are computed against: the one scans reconstruct with.

        Blocking: the first call (of any user of the basis) loads or builds it
        (:meth:`gonio.basis_supply.BasisSupply.get`).
        """
        return self.basis.get()

    # ------------------------------------------------------------------ sampling design
    def design(self, request: DesignRequest) -> DesignResult:
        """Optimise the geometry ``request`` asks for against :meth:`design_basis`.

        Blocking for up to the request's time limit (call it from a thread in async code).
        One design at a time: a search uses a whole CPU core, and a second one would halve
        the first's descents.

        Raises
        ------
        Conflict
            Another design is running.
        gonio.brdf.design.errors.FeasibilityError, gonio.brdf.design.errors.DesignError
            Constraints no design satisfies; the message says which to relax.
        """
        from gonio.sampling_design import run_design

        if not self._design_lock.acquire(blocking=False):
            raise Conflict("another design is running on this daemon; try again when it has "
                           "finished (at most its time limit)")
        try:
            return run_design(self.design_basis(), request)
        finally:
            self._design_lock.release()

    def evaluate_preset(self, name: str, rotations: int,
                        span_deg: float = DEFAULT_SPAN_DEG) -> DesignResult:
        """An industrial geometry (V&F Table 1) evaluated like an optimised design (blocking:
        the first call may load the basis). Raises ``UnknownPresetError`` naming the known
        presets."""
        from gonio.brdf.design.presets import get_preset
        from gonio.sampling_design import evaluate_preset

        preset = get_preset(name)
        return evaluate_preset(self.design_basis(), preset, rotations, span_deg)

    def calibration(self) -> Calibration:
        """The calibration applied to scans: the latest calibration job, else the rig config
        (or the one given to the constructor, which overrides both)."""
        if self._calibration is not None:
            return self._calibration
        return calibration_in_effect(self.data_dir, self.rig_config)

    @property
    def on_job_start(self) -> Callable[[JobRow], None] | None:
        """Called before a job's first reading, new or resumed (e.g. a simulated rig puts the
        white reference or the job's specimen on the stage)."""
        return self.worker.on_job_start

    @on_job_start.setter
    def on_job_start(self, fn: Callable[[JobRow], None] | None) -> None:
        self.worker.on_job_start = fn

    @property
    def specimen_truth(self) -> Callable[[], dict[str, Any] | None] | None:
        """Simulated rigs: the recipe of the material on the stage, stored with each
        reconstruction (``provenance/true_material``) so renderings can show the truth."""
        return self.worker.specimen_truth

    @specimen_truth.setter
    def specimen_truth(self, fn: Callable[[], dict[str, Any] | None] | None) -> None:
        self.worker.specimen_truth = fn

    # ------------------------------------------------------------------ foreground
    # ``gonio scan`` drives one job to its end in its own process, through this service but
    # without the queue worker (:meth:`start` is not called).
    def unfinished_job(self, plan: AnyPlan) -> JobInfo | None:
        """An unfinished job with exactly ``plan`` on this rig (a killed foreground scan), to
        resume from its checkpoint rather than start again; None if there is none.

        Every job left active keeps its state (a ``recovered`` event each): a foreground run
        decides only about its own job; the daemon judges the others at its start.
        """
        self.store.reconcile(lambda job: None)
        want, rig = plan.model_dump(mode="json"), self.desc.model_dump(mode="json")
        same = [j for j in self.store.active_jobs() if j.plan == want and j.rig == rig]
        return JobInfo.from_row(same[0]) if same else None

    async def run_in_foreground(self, job_id: int) -> JobState:
        """Measure, reconstruct and write job ``job_id`` now, on this loop; its final state.

        Raises
        ------
        Conflict
            The queue worker runs (:meth:`start`): submit the job instead.
        """
        if self._task is not None:
            raise Conflict("this service's worker runs the queue; submit the job and let it run")
        return await self.worker.run_job(self._row(job_id))

    # ------------------------------------------------------------------ jobs
    def submit(self, request: JobRequest | dict[str, Any],
               checked: CheckedPlan | None = None, *,
               accept_uncalibrated: bool = False) -> JobInfo:
        """Validate a request against the rig and queue it. Raises :class:`PlanError`.

        ``checked``: the request's plan as the caller already checked it on this rig
        (:meth:`check`), so it is not checked again; the worker starts the job with it.
        ``accept_uncalibrated``: the user accepted that the scan may measure in sensor units
        on a rig calibrated elsewhere (:meth:`uncalibrated_refusal`). Kept with the job: one
        queued without it runs only if a calibration covers it by the time it starts
        (:meth:`unasked_uncalibrated`).
        """
        if not isinstance(request, JobRequest):
            from pydantic import ValidationError

            try:
                request = JobRequest.model_validate(request)
            except ValidationError as exc:
                raise PlanError(f"invalid job request: {exc}") from None
        plan: AnyPlan = request.plan
        # Every check that needs no hardware, before queueing. A warning (a half-turn plan and
        # a basis without the twofold symmetry) does not refuse the job: the joint fit still
        # takes its readings, only the other half turn rests on the prior. It goes in the job's
        # own events instead, so whoever looks at the job later sees it.
        symmetry = self.basis.symmetry() if arc_may_apply(plan) else None
        checked = check_plan(checked if checked is not None and checked.plan == plan else plan,
                             self.desc)
        if plan.finishing != "calibration":
            self._check_calibration_covers(checked, request.priority)
            self._check_calibration_exposure(plan, request.priority)
        full = self.disk_full
        if full is not None:
            # Queued now, it would measure for minutes and then fail writing its result.
            raise DiskFull(f"{full}; the job was not queued")
        row = self.store.create_job(
            kind=plan.kind, specimen=plan.specimen, plan=plan.model_dump(mode="json"),
            rig=self.desc.model_dump(mode="json"), priority=request.priority,
            total_angles=len(checked.angles_deg),
            created=(None if plan.kind == "calibration"
                     else self._acceptance_record(plan, accept_uncalibrated)),
        )
        self.worker.take_checked(row.id, checked)
        self.basis.note_arc(self.store, row.id, plan, symmetry)
        self.worker.wake()
        return self._info(row)

    def uncalibrated_refusal(self, plan: AnyPlan, priority: int = 0) -> str | None:
        """Why a scan of ``plan`` needs the user's acceptance before it is queued
        (:func:`gonio.calibration.uncalibrated_refusal`: most likely this daemon runs on
        another data directory than the rig's own, which holds its calibration), None when
        it does not (a calibration job, a plan that cannot run: :meth:`submit` says why; a
        calibration job that will run before it: one under way or paused, or one queued at
        ``priority`` or above, the scan's own, since the queue takes the higher priority first
        and the earlier job among equals)."""
        why = self._uncalibrated_why(plan)
        if why is None:
            return None
        if self.calibration_ahead(priority)[0]:
            # A calibration job will run before this scan (`gonio serve --sim` queues one at
            # start), so the scan is finished with its calibration. Its refusal stopped `gonio
            # serve --sim --demo-scan` whenever a `gonio sim` rig of the same geometry had been
            # calibrated in the user data folder. A scan submitted at a higher priority than
            # a queued calibration would run first, uncalibrated: that one is still asked.
            return None
        return (f"{why}. Restart the daemon on that data directory (or without --data-dir), "
                "run a calibration job, or send accept_uncalibrated=true to measure in sensor "
                "units all the same")

    def unasked_uncalibrated(self, job: JobRow, plan: AnyPlan) -> str | None:
        """Why queued scan ``job`` must not start: it would measure uncalibrated on a rig
        calibrated elsewhere (:meth:`_uncalibrated_why`) and its user never accepted that.
        None when it may start.

        Such a scan was queued without asking because a calibration job was to run first
        (:meth:`uncalibrated_refusal`); that calibration was then cancelled, removed or failed.
        Run anyway, it would measure for minutes in sensor units, which nobody asked for.
        Jobs queued by a gonio that did not keep the acceptance (no ``uncalibrated_accepted``
        in their ``created`` event) start as they always did.
        """
        why = self._uncalibrated_why(plan)
        if why is None:
            return None
        created = self.store.last_event(job.id, "created")
        if created is None or UNCALIBRATED_ACCEPTED not in created.data:
            return None
        if created.data[UNCALIBRATED_ACCEPTED] or \
                self.store.has_event(job.id, UNCALIBRATED_ACCEPTED):
            return None
        cal = created.data.get(CALIBRATION_AHEAD)
        if isinstance(cal, int):
            try:
                ended = self.store.get_job(cal).state.value
            except StoreNotFound:
                ended = "removed"
            ending = {"aborted": "was cancelled", "removed": "was removed",
                      "failed": "failed"}.get(ended, f"is {ended}")
            how = (f"It was queued without asking because calibration job {cal} was to run "
                   f"before it; that job {ending} and nothing has calibrated the rig since")
        else:
            how = ("It was queued without asking, before the rig was calibrated elsewhere, "
                   "and no calibration in effect here covers it")
        return (f"{why}. {how}. Nothing was measured: run a calibration job and queue the "
                "scan again, or queue it accepting sensor units (the page asks; the API's "
                "accept_uncalibrated=true; gonio scan --accept-uncalibrated)")

    def _acceptance_record(self, plan: AnyPlan, accepted: bool) -> dict[str, Any]:
        """What a new scan's ``created`` event keeps for :meth:`unasked_uncalibrated`: whether
        its user accepted sensor units and, when it was queued unasked only because a
        calibration job was to run first, that job's id."""
        record: dict[str, Any] = {UNCALIBRATED_ACCEPTED: accepted}
        if not accepted and self._uncalibrated_why(plan) is not None:
            ahead = [r.id for r in self.store.list_jobs()
                     if r.kind == "calibration" and r.state not in FINISHED_STATES]
            if ahead:
                record[CALIBRATION_AHEAD] = ahead[0]
        return record

    def _uncalibrated_why(self, plan: AnyPlan) -> str | None:
        """Why a scan of ``plan`` would be uncalibrated on a rig calibrated elsewhere
        (:func:`gonio.calibration.uncalibrated_refusal`), whatever the queue holds; None for a
        calibration job, a plan that cannot run or a scan the calibration in effect covers."""
        if plan.kind == "calibration":
            return None
        try:
            pairs = plan_pairs(plan, self.desc)
        except ValueError:
            return None
        try:
            own: Path | None = (self._own_data_dir if self._own_data_dir is not None
                                else scan_data_dir(self.rig_config))
        except AttributeError:  # a rig without a rig config (tests, notebooks)
            own = None
        return uncalibrated_refusal(self.calibration(), pairs, own, self.data_dir)

    def _calibration_overtaken(self) -> Callable[
            [list[tuple[int, str]], list[tuple[int, str]]], tuple[list[int], int, str]] | None:
        """For :meth:`reorder`: a function of the queue order before and after a move that
        gives the queued scans that would be uncalibrated (:meth:`_uncalibrated_why`) and no
        longer run after a queued calibration they ran after before, that calibration's job id
        and the first scan's reason; None when no reorder can do that (no calibration queued,
        or one under way or paused, which runs before every queued job).

        Such a scan was queued without the user's acceptance because the calibration ran
        first (:meth:`uncalibrated_refusal`); run before it, it would measure in sensor units
        unasked.
        """
        rows = self.store.list_jobs()
        pending = [r for r in rows if r.kind == "calibration" and r.state not in FINISHED_STATES]
        if not any(r.state == JobState.QUEUED for r in pending) or \
                any(r.state != JobState.QUEUED for r in pending):
            return None
        plans = {r.id: r for r in rows if r.state == JobState.QUEUED and r.kind != "calibration"}
        why: dict[int, str] = {}
        for job_id, row in plans.items():
            try:
                reason = self._uncalibrated_why(parse_plan(row.plan))
            except ValueError:
                continue
            if reason is not None:
                why[job_id] = reason
        if not why:
            return None

        def behind_calibration(order: list[tuple[int, str]]) -> set[int]:
            first = next((k for k, (_, kind) in enumerate(order) if kind == "calibration"),
                         len(order))
            return {job_id for job_id, _ in order[first + 1:]}

        def overtaken(before: list[tuple[int, str]],
                      after: list[tuple[int, str]]) -> tuple[list[int], int, str]:
            jobs = sorted((behind_calibration(before) - behind_calibration(after)) & why.keys())
            if not jobs:
                return [], 0, ""
            cal = next(job_id for job_id, kind in after if kind == "calibration")
            return jobs, cal, why[jobs[0]]

        return overtaken

    def _check_calibration_covers(self, checked: CheckedPlan, priority: int = 0) -> None:
        """Refuse, before anything moves, a plan the calibration in effect covers only in part
        (its result would mix sensor units and 1/sr), or whose factors have another number of
        channels than the sensors read (the job would fail when it finishes) unless a
        calibration job runs before it (:meth:`calibration_ahead`; the scan queued at
        ``priority``). Raises :class:`PlanError` naming the pairs, or
        :class:`gonio.calibration.CalibrationError` for a damaged calibration."""
        from gonio.calibration import PartialCalibration

        cal = self.calibration()
        try:
            cal.check_covers(checked.pairs, "this plan")
        except PartialCalibration as exc:
            raise PlanError(str(exc)) from None
        why = self.channel_refusal(checked.pairs, cal, priority)
        if why is not None:
            raise PlanError(why)

    def _calibration_jobs(self, priority: int) -> tuple[list[JobRow], list[JobRow]]:
        """The unfinished calibration jobs in the order they run, split: those that run before
        a scan queued now at ``priority`` (under way or paused, then those queued at that
        priority or above in the queue's order: the higher priority first, then the queue's
        position, so a scan queued now runs after them) and those queued behind it. The one
        reading of the queue :meth:`calibration_ahead` and :meth:`exposure_ahead_refusal`
        judge; the last of ``before`` is the calibration in effect when the scan starts."""
        active = [row for row in self.store.active_jobs() if row.kind == "calibration"]
        before: list[JobRow] = []
        behind: list[JobRow] = []
        for row in self.store.queue():
            if row.kind == "calibration":
                (before if row.priority >= priority else behind).append(row)
        return active + before, behind

    def calibration_ahead(self, priority: int = 0,
                          exposure_s: float | None = None) -> tuple[bool, str]:
        """Whether a calibration job runs before a scan queued now at ``priority``
        (:meth:`_calibration_jobs`), with ``exposure_s`` given: whether the last of them, the
        calibration in effect when the scan starts, measures at it; and, when none does but
        one is queued behind, the words that say so and what to do (else "")."""
        before, behind = self._calibration_jobs(priority)
        if exposure_s is not None:
            # The exposure in effect when the scan starts is the last calibration's to run
            # before it: one at the plan's exposure followed by one at another does not do.
            # One whose exposure is not recorded is left to the worker, as the queue's walk
            # (gonio.queue_exposure) leaves it.
            before = [r for r in before[-1:]
                      if _plan_exposure(r) is None or _measures_at(r, exposure_s)]
            behind = [r for r in behind if _measures_at(r, exposure_s)]
        if before or not behind:
            return bool(before), ""
        cal = behind[0]
        return False, (f" (calibration job {cal.id} is queued at priority {cal.priority}, below "
                       f"this scan's {priority}: it would run after the scan; queue the scan "
                       f"at priority {cal.priority} or lower, or raise the calibration's "
                       "priority first)")

    def channel_refusal(self, pairs: Sequence[hal.PairSpec],
                        cal: Calibration | None = None, priority: int = 0) -> str | None:
        """Why a scan measuring ``pairs`` is refused at submission because the calibration in
        effect (``cal``, default :meth:`calibration`) was measured with other sensors (its
        factors have another number of channels than the sensors read,
        :meth:`gonio.calibration.Calibration.check_channels`), or None: no mismatch, or a
        calibration job calibrates these sensors before the scan, queued at ``priority``,
        starts (:meth:`calibration_ahead`; the worker checks again then), as for the
        exposure. The one decision behind both
        :meth:`submit`'s refusal and the dry run's warning (the page's Check plan,
        ``gonio scan --daemon URL --dry-run``)."""
        from gonio.calibration import ChannelMismatch, sensor_channels

        try:
            (cal if cal is not None else self.calibration()).check_channels(
                pairs, sensor_channels(self.desc), "this plan")
        except ChannelMismatch as exc:
            ahead, behind = self.calibration_ahead(priority)
            if not ahead:
                return f"{exc}{behind}"
        return None

    def _check_calibration_exposure(self, plan: AnyPlan, priority: int = 0) -> None:
        """Refuse a scan at another exposure than the calibration in effect
        (:meth:`gonio.calibration.Calibration.check_exposure`): raises :class:`PlanError`
        naming both exposures. A calibration job at the plan's exposure that runs before the
        scan, queued at ``priority`` (:meth:`calibration_ahead`), lets it be queued behind it:
        the worker checks again when the scan starts."""
        from gonio.calibration import ExposureMismatch

        exposure_s = plan.exposure.exposure_s
        try:
            self.calibration().check_exposure(exposure_s, "this plan")
        except ExposureMismatch as exc:
            ahead, behind = self.calibration_ahead(priority, exposure_s)
            if not ahead:
                # The calibration that will be in effect, when one runs first, is named.
                why = self.exposure_ahead_refusal(priority, exposure_s)
                raise PlanError(why if why is not None else f"{exc}{behind}") from None
            return
        why = self.exposure_ahead_refusal(priority, exposure_s)
        if why is not None:
            raise PlanError(why)

    def exposure_ahead_refusal(self, priority: int, exposure_s: float) -> str | None:
        """Why a scan at ``exposure_s`` queued now at ``priority`` would be refused when it
        starts: the last calibration job to run before it (:meth:`_calibration_jobs`), the
        one in effect when it starts, measures at another exposure (the worker refuses that,
        :meth:`gonio.calibration.Calibration.check_exposure`). None when none runs before
        it, the last one measures at ``exposure_s``, or its exposure is not recorded (the
        worker judges it at the start).

        A scan queued behind ``gonio serve --sim``'s calibration job at another exposure was
        accepted, waited, and failed "not started" once that calibration was in effect; one
        queued behind two calibrations, at its exposure and then at another, was accepted
        because the first measured at its exposure."""
        before, _ = self._calibration_jobs(priority)
        if not before:
            return None
        last = before[-1]
        at = _plan_exposure(last)
        if at is None or _measures_at(last, exposure_s):
            return None
        which = ("which runs before it" if len(before) == 1 else
                 f"the last of the {len(before)} calibration jobs that run before it")
        return (f"this plan reads at exposure {exposure_s:g} s and calibration job {last.id}, "
                f"{which}, measures at {at:g} s: counts are not rescaled between "
                "exposures, so the scan would be refused when it starts; scan at "
                f"{at:g} s, or queue a calibration at {exposure_s:g} s first")

    def list_jobs(self, state: str | None = None) -> list[JobInfo]:
        rows = [r for r in self.store.list_jobs([state] if state else None)
                if not self.worker.being_removed(r.id)]
        queued = any(r.state is JobState.QUEUED for r in rows)
        wait = self._queue_wait() if queued else None
        starts = self._start_estimates(wait) if queued else {}
        refusals = self.start_refusals() if queued else {}
        return [JobInfo.from_row(r, self._max_angles(r), wait, start=starts.get(r.id),
                                 start_refusal=refusals.get(r.id))
                for r in rows]

    def _start_estimates(self, wait: str | None) -> dict[int, StartEstimate]:
        """Each queued job's estimated start (:func:`gonio.timeleft.start_estimates`), by id.

        ``wait``: :meth:`_queue_wait` now. The rig is free after the job holding it: its
        ``time_left_s`` (a calibration's ``eta_s``, which has no reconstruction), an adaptive
        one's bounded by its ``eta_max_s``. Not known while the queue waits (``wait``: a hold,
        the maintenance lock, a paused or suspended job), while the disk is full, or while the
        job holding the rig has no estimate. Each queued job lasts its dry run's measuring
        (:meth:`_measuring_estimate`) plus, for a scan, the finishing estimate; the first scan
        also waits for a basis build when one is due and no job under way does it first.
        """
        queued = [r for r in self.store.queue() if not self.worker.being_removed(r.id)]
        if not queued:
            return {}
        free_s: float | None = 0.0
        bound = False
        source = ""
        build_due = self.basis.build_needed()
        # An auto-arc scan whose test may call its specimen asymmetric waits, then, for that
        # basis to be built (once): a bound counts it ("starts within 17 s" started after 65).
        asym_due = self.basis.asymmetric_build_needed()
        full = self.disk_full
        if wait is not None:
            free_s, source = None, wait
        elif full is not None:
            free_s, source = None, f"no job starts while {full}"
        else:
            listed = {r.id for r in queued}
            for row in self.store.active_jobs():
                if self.worker.being_removed(row.id):
                    continue  # removed (answered 204) while its engine stops: not listed
                if row.id in listed:
                    # Taken by the worker between the two reads: it is answered as queued
                    # here, so it is not also the job it waits for ("starts in about 37 s
                    # (job 4's time left)" for job 4 itself, which started at once).
                    continue
                d = self.get_job(row.id)
                left = d.eta_s if row.kind == "calibration" else d.time_left_s
                if row.kind == "calibration" and row.state is JobState.RECONSTRUCTING:
                    left = 0.0  # its factors take a moment: it has no finishing estimate
                if row.kind != "calibration":
                    build_due = False  # its time left holds the build, when one is due
                if left is None:
                    what = ("its finishing has run past its estimate"
                            if row.state is JobState.RECONSTRUCTING
                            else "it has no time estimate yet")
                    free_s, source = None, f"job {row.id} holds the rig and {what}"
                    break
                if d.eta_max_s is not None and d.eta_s is not None and d.eta_max_s > d.eta_s:
                    left += d.eta_max_s - d.eta_s
                    bound = True
                if asym_due and (branch := self._asymmetric_branch_s(row)) is not None:
                    left += branch
                    bound = True
                    asym_due = False
                elif self._asymmetric_build_due(row) is not None:
                    asym_due = False  # its time left holds the build (its test said so)
                free_s = (free_s or 0.0) + left
                source = f"job {row.id}'s time left"
        finishing = self._finishing_estimate().seconds
        runs: list[QueuedRun] = []
        for row in queued:
            measuring = self._measuring_estimate(row)
            if measuring is None:
                runs.append(QueuedRun(row.id, None))
                continue
            seconds, is_bound = measuring
            if row.kind != "calibration":
                seconds += finishing
                if build_due:
                    seconds += BASIS_BUILD_S
                    build_due = False
                if asym_due and may_switch_basis(row.plan):
                    seconds += self.basis.asymmetric_build_s() or 0.0
                    is_bound = True
                    asym_due = False
            runs.append(QueuedRun(row.id, seconds, is_bound))
        return {run.job_id: est for run, est in
                zip(runs, start_estimates(free_s, bound, source, runs), strict=True)}

    def _measuring_estimate(self, row: JobRow) -> tuple[float, bool] | None:
        """A queued job's measuring time by its dry run (from 0 deg), seconds, and whether it
        is a bound (an adaptive or auto-arc plan's ``max_estimated_s``), once per job; None
        for a plan the dry run cannot time on this rig."""
        if row.id not in self._measuring_of:
            try:
                r = dry_run(parse_stored_plan(row.plan), self.desc)
            except Exception:
                # A stored plan this gonio cannot time (an older one, another rig): its start
                # is unknown, and every job list must still answer; logged once, as the
                # answer is kept.
                log.warning("job %d: its plan cannot be timed for a start estimate", row.id,
                            exc_info=True)
                self._measuring_of[row.id] = None
            else:
                self._measuring_of[row.id] = ((r.max_estimated_s, True)
                                              if r.max_estimated_s is not None
                                              else (r.estimated_s, False))
        return self._measuring_of[row.id]

    def _queue_wait(self) -> str | None:
        """:func:`gonio.jobstates.queue_wait` of this daemon now: its queue hold (or the
        maintenance lock) and the jobs that own the rig."""
        return queue_wait(((r.id, r.state) for r in self.store.active_jobs()),
                          self.worker.held, self.worker.gate())

    def _max_angles(self, row: JobRow) -> int | None:
        """An adaptive job's most stage angles (the dry run's bound), once per job: its plan
        and the rig do not change while the daemon runs."""
        if row.kind != "adaptive":
            return None
        if row.id not in self._max_angles_of:
            try:
                bound = dry_run(parse_stored_plan(row.plan), self.desc).max_angles
            except PlanError:
                bound = None  # a plan this rig cannot run: its progress stays done/total
            self._max_angles_of[row.id] = bound
        return self._max_angles_of[row.id]

    def _finishing_estimate(self) -> FinishingEstimate:
        """:func:`gonio.timeleft.finishing_estimate` of this store, read at most every few
        seconds (a polling page asks once a second)."""
        now = time.monotonic()
        cached = self._finishing_cache  # once: a completion may clear it from another thread
        if cached is None or now - cached[0] > 5.0:
            completed = self.store.list_jobs([JobState.COMPLETED.value])
            cached = (now, finishing_estimate(completed, most_channels(self.desc)))
            self._finishing_cache = cached
        return cached[1]

    def _row(self, job_id: int) -> JobRow:
        if self.worker.being_removed(job_id):
            # DELETE answered 204: the job is gone for every caller, though its engine takes
            # a moment to stop before the store forgets it.
            raise NotFound(f"no job with id {job_id} (it was removed)")
        return job_row(self.store, job_id)

    def get_job(self, job_id: int) -> JobDetail:
        """One job's full status: one row read, plus the queue position if it is queued.

        Cheap enough to serve many polling clients: no plan is re-parsed, the ETA is the
        engine's last estimate (updated at each checkpoint), not recomputed.
        """
        row = self._row(job_id)
        activity = None
        if self.worker.current_job == job_id:
            # Reconstructing, or an adaptive job loading its basis before the first reading.
            activity = self.worker.activity_report()
        queued = row.state is JobState.QUEUED
        active = row.state in (JobState.RUNNING, JobState.PAUSED, JobState.SUSPENDED,
                               JobState.RECONSTRUCTING)
        est = build = finishing_for = None
        if active and row.kind != "calibration":
            est = self._finishing_estimate()
            build = BASIS_BUILD_S if self.basis.build_needed() else None
            asym = self._asymmetric_build_due(row)
            if asym is not None:  # the test found the specimen asymmetric (science.md 7.4)
                build = (build or 0.0) + asym
            if row.state is JobState.RECONSTRUCTING and self.worker.current_job == job_id:
                finishing_for = self.worker.finishing_seconds()
        wait = self._queue_wait() if queued else None
        return JobDetail.from_row(
            row, self._max_angles(row), wait,
            queue_position=self.store.queue_position(job_id) if queued else None,
            progress=self.worker.progress(job_id), activity=activity, finishing=est,
            basis_build_s=build, finishing_for_s=finishing_for,
            start=self._start_estimates(wait).get(job_id) if queued else None,
            start_refusal=self.start_refusals().get(job_id) if queued else None)

    def _asymmetric_branch_s(self, row: JobRow) -> float | None:
        """For a queue bound, when the asymmetric basis is not built (the caller knows):
        seconds an auto-arc job holding the rig may still wait for it, its test not having
        spoken yet (after the test, its time left holds the build,
        :meth:`_asymmetric_build_due`); None otherwise."""
        from gonio.plans.arc import ARC_TEST_EVENT

        if row.kind == "calibration" or not may_switch_basis(row.plan):
            return None
        if row.plan.get("arc") != "auto":
            # A fixed full turn is tested when it finishes: until the build is under way
            # (then its time left holds it, :meth:`_asymmetric_build_due`), it may come.
            return None if self._asymmetric_build_due(row) is not None else (
                self.basis.asymmetric_build_s() or 0.0)
        if self.store.last_event(row.id, ARC_TEST_EVENT) is not None:
            return None
        return self.basis.asymmetric_build_s() or 0.0

    def _asymmetric_build_due(self, row: JobRow) -> float | None:
        """Seconds ``row``'s finishing will wait for the basis for specimens without twofold
        symmetry to be built: its auto-arc test called the specimen asymmetric and that basis
        is not built yet (:meth:`BasisSupply.asymmetric_build_s`); None otherwise."""
        from gonio.plans.arc import ARC_TEST_EVENT

        if not self.basis.asymmetric_build_needed():
            return None
        if (self.worker.current_job == row.id and self.worker.activity == "asymmetric_basis"):
            # Finishing waits for it now (a fixed full turn's test is made there, with no
            # event before it): its time is the build's, not the reconstruction's estimate.
            return self.basis.asymmetric_build_s()
        if row.plan.get("arc") != "auto":
            return None
        ev = self.store.last_event(row.id, ARC_TEST_EVENT)
        if ev is None or ev.data.get("statistic") is None or ev.data.get("symmetric", True):
            return None
        return self.basis.asymmetric_build_s()

    def readings(self, job_id: int, after_angle: int = -1) -> list[ReadingRow]:
        """The readings stored so far for a job (angles with index > ``after_angle``).

        Raises
        ------
        NotFound
            For an unknown job (rather than an empty list).
        """
        self._row(job_id)
        return [r for r in self.store.readings(job_id) if r.angle_index > after_angle]

    def pause(self, job_id: int, immediate: bool = False) -> JobInfo:
        """Pause at the next checkpoint (or now: the angle in progress is repeated)."""
        row = self._row(job_id)
        check_action("pause", row.state, job_id)
        if not self.worker.pause_measurement(job_id, immediate):
            raise Conflict(
                f"job {job_id} is not being measured right now; it cannot be paused"
            )
        # Kept, so that a restart before the checkpoint does not forget it: the job came
        # back running, though "pause asked" was answered (the lab may reach for the
        # specimen); the engine of the resumed job reads it (PAUSE_ASKED_EVENT).
        self.store.append_event(job_id, PAUSE_ASKED_EVENT, {"immediate": immediate})
        return JobInfo.from_row(self._row(job_id))

    def resume(self, job_id: int) -> JobInfo:
        """Resume a paused job; the answer is the job once its engine has taken the request
        (normally ``running``; still ``paused`` if it has not within
        :data:`RESUME_ANSWER_WAIT_S`). The answer read ``paused`` every time: the engine
        resumes on its own loop a moment after the request, and a script reading the answer
        concluded the resume had failed. Called on an event loop (a test's), it answers at
        once: waiting there could hold up the very loop that resumes the job.

        Raises
        ------
        Conflict
            No engine holds the job (the worker has not taken it up yet): nothing would
            resume it.
        """
        row = self._row(job_id)
        check_action("resume", row.state, job_id)
        if not self.worker.resume_measurement(job_id):
            raise Conflict(f"job {job_id} is paused but the worker has not taken it up yet "
                           "(the daemon is starting or loading its basis, or no job starts "
                           "while the maintenance lock or a full disk holds the queue: "
                           "GET /api/v1/rig says which); try the resume again once it has")
        if not _on_an_event_loop():
            deadline = time.monotonic() + RESUME_ANSWER_WAIT_S
            while self._row(job_id).state is JobState.PAUSED and time.monotonic() < deadline:
                time.sleep(0.02)
        return JobInfo.from_row(self._row(job_id))

    # Abort, cancel, remove and halt decide under the worker's lock (Worker.changes): a job
    # the worker has handed to its engine is changed by asking the engine (which stops before
    # any move when it has not moved yet), any other job in the store; never both.
    def abort(self, job_id: int) -> JobInfo:
        with self.worker.changes:
            row = self._row(job_id)
            check_action("abort", row.state, job_id)
            if self.worker.stop_starting(job_id, "aborted before it started"):
                pass  # taken from the queue, not moved yet: its engine ends it now
            elif self.worker.abort_measurement(job_id):
                pass  # its engine stops it: lights off, stage stopped
            elif row.state is JobState.QUEUED:
                self.store.set_state(job_id, JobState.ABORTED,
                                     reason="aborted before it started")
            elif row.state is JobState.RECONSTRUCTING:
                if not self.worker.abort_reconstruction(job_id):
                    # Its finishing is not running here (it would be resumed): every
                    # reading is stored, so a rebuild can still finish it.
                    hint = rebuild_hint(self.store, job_id, self.data_dir)
                    self.store.set_state(job_id, JobState.ABORTED, reason="aborted by request "
                                         "while it was being finished"
                                         + (f"; {hint}" if hint else ""))
            else:
                # Active in the store but not running here (e.g. paused before a restart).
                self.store.set_state(job_id, JobState.ABORTED, reason="aborted by request")
            return JobInfo.from_row(self._row(job_id))

    def cancel(self, job_id: int) -> JobInfo:
        """Take a queued job out of the queue (it becomes aborted; nothing was measured).

        A job the worker has just taken from the queue is cancelled too, as long as its
        stage has not moved: its engine ends it before the first move.
        """
        with self.worker.changes:
            row = self._row(job_id)
            if not self.worker.stop_starting(job_id, "cancelled before it started"):
                check_action("cancel", row.state, job_id)
                self.store.set_state(job_id, JobState.ABORTED,
                                     reason="cancelled before it started")
            return JobInfo.from_row(self._row(job_id))

    def reorder(self, job_id: int, request: ReorderRequest | None = None, *,
                priority: int | None = None, position: int | None = None,
                accept_uncalibrated: bool = False) -> JobInfo:
        """Move queued job ``job_id`` (a new priority and/or queue position).

        Refused with :class:`Conflict` when a queued scan that would be uncalibrated, queued
        without asking because a queued calibration ran first, would then run before it
        (:meth:`_calibration_overtaken`), unless ``accept_uncalibrated``: then each scan so moved
        keeps that acceptance (an ``uncalibrated_accepted`` event) for its start. Refused too
        when a queued scan would then start under a calibration at another exposure than its
        own, which the worker refuses at the start (:meth:`_exposure_overtaken`).
        """
        if request is not None:
            priority, position = request.priority, request.position
        if priority is None and position is None:
            raise Conflict("reorder needs a priority or a position")
        self._row(job_id)
        overtaken = self._calibration_overtaken()
        exposure_overtaken = self._exposure_overtaken()
        accepted: list[int] = []

        def check(before: list[tuple[int, str]], after: list[tuple[int, str]]) -> None:
            if exposure_overtaken is not None:
                why = exposure_overtaken(before, after)
                if why is not None:
                    raise Conflict(f"not reordered: {why}")
            if overtaken is None:
                return
            jobs, cal, why = overtaken(before, after)
            if not jobs:
                return
            if accept_uncalibrated:
                accepted.extend(jobs)
                return
            raise Conflict(
                f"not reordered: job {', '.join(str(j) for j in jobs)} would then run before "
                f"calibration job {cal}, uncalibrated ({why}); it was queued without asking "
                f"because the calibration ran first. Keep it behind job {cal} (no higher "
                f"priority, no earlier place), let job {cal} finish first, or send "
                "accept_uncalibrated=true to measure it in sensor units all the same")

        row = self.store.reorder(job_id, priority=priority, position=position, check=check)
        for job in accepted:
            # What the user accepted travels with the job: its start does not refuse it
            # (unasked_uncalibrated), whichever calibration runs or does not run before it.
            self.store.append_event(job, UNCALIBRATED_ACCEPTED, {"by": "reorder"})
        return self._info(row)

    def _exposure_start(self, rows: Sequence[JobRow]) -> StartCalibration:
        """The calibration a queued job starts under when no queued calibration job runs
        before it (:class:`gonio.queue_exposure.StartCalibration`): a calibration job under
        way or paused (among ``rows``, the unfinished jobs), else the calibration in effect."""
        from gonio.calibration import CalibrationError

        active = [r for r in rows if r.kind == "calibration" and r.state is not JobState.QUEUED]
        if active:
            # The worker goes on with the first of them (by id) before it takes the queue.
            return StartCalibration(_plan_exposure(active[0]), active[0].id)
        try:
            cal = self.calibration()
        except CalibrationError:
            # A damaged calibration file must not block moving the calibration job that
            # replaces it; the worker says what is wrong when a scan starts.
            return StartCalibration(None)
        return StartCalibration(cal.exposure_s if cal.pairs else None)

    def start_refusals(self) -> dict[int, str]:
        """The queued scans the worker would refuse when they start, as the queue stands, by
        id, with what their row says (the job list's ``start_refusal``): those that would
        start under a calibration at another exposure
        (:func:`gonio.queue_exposure.exposure_clashes`).

        Submission and :meth:`reorder` refuse what would cause it, but a calibration job
        cancelled, failed or queued at a higher priority, or a calibration file replaced,
        leaves a queued scan to fail "not started" at its turn, perhaps overnight; its row
        now says so while it waits."""
        queue = self.store.queue()  # in the order the worker takes them
        if not any(r.kind != "calibration" for r in queue):
            return {}
        clashes = exposure_clashes([(r.id, r.kind) for r in queue],
                                   {r.id: _plan_exposure(r) for r in queue},
                                   self._exposure_start(self.store.active_jobs()))
        return {job_id: clash.status() for job_id, clash in clashes.items()}

    def _exposure_overtaken(self) -> Callable[
            [list[tuple[int, str]], list[tuple[int, str]]], str | None] | None:
        """For :meth:`reorder`: a function of the queue order before and after a move that
        says which queued scan would then start under a calibration at another exposure than
        its own (:func:`gonio.queue_exposure.exposure_clashes`) though it did not before, and
        what to do; None when it says nothing. None when no calibration job is queued (a move
        cannot change which calibration a scan starts under).

        The worker refuses such a scan when it starts (counts are not rescaled between
        exposures): a calibration at 0.02 s moved ahead of a scan at 0.01 s made that scan
        fail "not started" long after the move that decided it.
        """
        rows = self.store.list_jobs([JobState.QUEUED.value, *(st.value for st in ACTIVE_STATES)])
        if not any(r.kind == "calibration" and r.state is JobState.QUEUED for r in rows):
            return None
        exposures = {r.id: _plan_exposure(r) for r in rows}
        start = self._exposure_start(rows)

        def overtaken(before: list[tuple[int, str]], after: list[tuple[int, str]]) -> str | None:
            was = exposure_clashes(before, exposures, start)
            now = {k: v for k, v in exposure_clashes(after, exposures, start).items()
                   if k not in was}
            if not now:
                return None
            clash = now[min(now)]
            return (f"job {clash.job_id} reads at exposure {clash.exposure_s:g} s and "
                    f"{clash.under()}: counts are not rescaled between exposures, so it would "
                    f"be refused when it starts. Keep job {clash.job_id} where it runs under a "
                    f"calibration at {clash.exposure_s:g} s, or queue a calibration at "
                    f"{clash.exposure_s:g} s before it")

        return overtaken

    def _info(self, row: JobRow) -> JobInfo:
        """One job's row as :meth:`list_jobs` gives it, its start estimate included when it
        is queued (a submission's and a reorder's answer said ``starts_in_estimate: null``,
        which means "not queued")."""
        if row.state is not JobState.QUEUED:
            return JobInfo.from_row(row, self._max_angles(row))
        wait = self._queue_wait()
        return JobInfo.from_row(row, self._max_angles(row), wait,
                                start=self._start_estimates(wait).get(row.id),
                                start_refusal=self.start_refusals().get(row.id))

    def remove(self, job_id: int) -> None:
        """Delete a queued or finished job and its readings (not its result file).

        A job the worker has just taken from the queue, whose stage has not moved, is ended
        before it moves and deleted as soon as its engine has stopped (a moment later).
        """
        with self.worker.changes:
            row = self._row(job_id)
            if self.worker.stop_starting(job_id, "removed before it started", remove=True):
                return
            check_action("remove", row.state, job_id)
            self.store.delete_job(job_id)

    def halt(self) -> None:
        """Emergency halt: stop the running job at once, no cleanup; hold the queue. A job
        being started is halted too (or stays queued, when it had not left the queue)."""
        with self.worker.changes:
            self.worker.halt_measurement()
            self.worker.hold("emergency halt")

    def release_queue(self) -> None:
        """Let the worker take queued jobs again after a halt or a stop-on-failure."""
        self.worker.release()

    def status(self) -> ServiceStatus:
        """What the worker is doing right now (for /metrics and status pages)."""
        job_id = self.worker.measuring()
        p = self.worker.progress(job_id) if job_id is not None else None
        running = None
        if job_id is not None and p is not None:
            running = RunningJob(id=job_id, done_angles=p.done, total_angles=p.total,
                                 eta_s=p.eta_s)
        return ServiceStatus(current_job=self.worker.current_job,
                             queue_held=self.worker.queue_held(),
                             running=running)

    def record_event(self, type_: str, data: dict[str, Any], job_id: int | None = None) -> Event:
        """Log an event of the daemon (e.g. the maintenance lock) for every subscriber."""
        return self.events.record(type_, data, job_id)

    def check(self, plan: AnyPlan) -> CheckedPlan:
        """``plan`` checked on this rig (what :meth:`submit` checks, minus the calibration
        and the disk); hand the result to :meth:`dry_run` and :meth:`submit` so neither checks
        it again. Raises :class:`PlanError`."""
        return check_plan(plan, self.desc)

    def dry_run(self, plan: AnyPlan | CheckedPlan | dict[str, Any]) -> DryRun:
        """Check and time a plan from the stage's last known position (else 0 deg, said so),
        with its finishing as this store's last scans took (:func:`finishing_estimate`)."""
        p = plan if isinstance(plan, BaseModel | CheckedPlan) else parse_plan(plan)
        kind = p.plan if isinstance(p, CheckedPlan) else p
        est = self._finishing_estimate()
        return dry_run(p, self.desc, self.stage_deg,
                       basis_ready=not self.basis.build_needed(),
                       basis=self.basis.symmetry() if arc_may_apply(kind) else None,
                       asymmetric_build_s=(self.basis.asymmetric_build_s()
                                           if may_switch_basis(kind) else None),
                       asymmetric_basis=self.basis.has_asymmetric,
                       finishing_s=est.seconds, finishing_source=est.source)

    def calibration_warnings(self, pairs: Sequence[hal.PairSpec], exposure_s: float,
                             priority: int = 0) -> list[str]:
        """What the calibration in effect means for a scan of ``pairs`` at ``exposure_s``
        queued now at ``priority``, for the dry runs (the page's Check plan, ``gonio scan
        --daemon URL --dry-run``): a partial calibration and one of other sensors (the
        refusals :meth:`submit` would answer, prefixed ``not calibrated:``), no calibration
        at all (values in sensor units) and one at another exposure (refused).

        A calibration job that runs before the scan (:meth:`calibration_ahead`: under way,
        paused, or queued at ``priority`` or above; for the exposure, the last of them at the
        plan's exposure) settles the missing and the other-exposure calibration: those are not
        said then (the worker checks again when the scan starts), as :meth:`submit` does not
        refuse them; one queued below ``priority`` is named with what to do. A partial
        calibration is refused whatever is queued, so it is always said."""
        cal = self.calibration()
        channels = self.channel_refusal(pairs, cal, priority)
        missing = uncalibrated_warning(cal, pairs)
        if missing is not None and not cal.pairs:
            ahead, behind = self.calibration_ahead(priority)
            missing = None if ahead else f"{missing}{behind}"
        exposure = exposure_warning(cal, exposure_s)
        if exposure is not None:
            ahead, behind = self.calibration_ahead(priority, exposure_s)
            ahead_refusal = None if ahead else self.exposure_ahead_refusal(priority, exposure_s)
            exposure = (None if ahead else f"{exposure}{behind}" if ahead_refusal is None
                        else f"exposure: {ahead_refusal}")
        else:
            # The calibration in effect when the scan starts: one queued before it.
            ahead_refusal = self.exposure_ahead_refusal(priority, exposure_s)
            exposure = None if ahead_refusal is None else f"exposure: {ahead_refusal}"
        return [w for w in (missing,
                            None if channels is None else f"not calibrated: {channels}",
                            exposure)
                if w is not None]

    @property
    def disk_full(self) -> str | None:
        """Why no job starts or is queued: the data directory's disk is full, or a write
        to it failed for lack of space and it has not had room since (None: it has room)."""
        return self.worker.disk_full or low_space(self.data_dir)

    # ------------------------------------------------------------------ events
    @property
    def seq(self) -> int:
        """Sequence number of the latest event."""
        return self.events.seq

    def _track_stage(self, ev: EventRow) -> None:
        # The stage's last known position, for dry runs: every checkpoint and manual stage
        # command reports it.
        pos = ev.data.get("actual_deg") if ev.type == "progress" else (
            ev.data.get("position_deg") if ev.type == "stage" else None)
        if isinstance(pos, int | float):
            self.stage_deg = float(pos)

    def _track_completions(self, ev: EventRow) -> None:
        # A job completed: the finishing estimate is read again at the next ask, not up to
        # 5 s later (the job list asks for it whenever jobs are queued, so a cached estimate
        # from before the completion was served to the next job's time left).
        if ev.type == "state" and ev.data.get("state") == JobState.COMPLETED.value:
            self._finishing_cache = None

    def add_event_listener(self, fn: Callable[[Event], None]) -> Callable[[EventRow], None]:
        """Call ``fn(event)`` right after each event is stored (:meth:`EventHub.add_listener`)."""
        return self.events.add_listener(fn)

    def remove_event_listener(self, handle: Callable[[EventRow], None]) -> None:
        self.events.remove_listener(handle)

    def subscribe(self, since_seq: int = 0, job_id: int | None = None) -> AsyncIterator[Event]:
        """Stored events after ``since_seq``, then live ones; none is lost
        (:meth:`EventHub.subscribe`)."""
        return self.events.subscribe(since_seq, job_id)

    # ------------------------------------------------------------------ results
    # Served through one set of caches (gonio/result_views.py): blocking calls (they read the
    # result file, render, export), to be called from a thread in async code.
    def result_path(self, job_id: int) -> Path:
        """Where job ``job_id``'s result file is (:meth:`ResultViews.result_path`)."""
        return self.results.result_path(job_id)

    def checked_result_path(self, job_id: int) -> Path:
        """Job ``job_id``'s result file, once read whole (see :class:`ResultViews`)."""
        return self.results.checked_result_path(job_id)

    def result_file_name(self, job_id: int) -> str:
        """The name job ``job_id``'s result file downloads under: the job and its specimen
        (:func:`gonio.result_views.download_stem`), ``.h5``."""
        return f"{download_stem(job_id, self._row(job_id).specimen)}.h5"

    def colour_csv_name(self, job_id: int) -> str:
        """The name job ``job_id``'s colour CSV downloads under: the job and its specimen, as
        its result file and exports (:func:`gonio.result_views.download_stem`), then
        ``-colour.csv``."""
        return f"{download_stem(job_id, self._row(job_id).specimen)}-colour.csv"

    def damaged_results(self) -> list[str]:
        """One line per completed job whose result file is missing or damaged."""
        return self.results.damaged_results()

    def metrics(self, job_id: int) -> dict[str, Any]:
        """A job's summary with its headline error (:meth:`ResultViews.metrics`)."""
        return self.results.metrics(job_id)

    def result(self, job_id: int) -> ResultFile:
        """A job's result file, read whole (:meth:`ResultViews.result`)."""
        return self.results.result(job_id)

    def reconstruction(self, job_id: int) -> ResultFile:
        """A job's result file holding a BRDF (:meth:`ResultViews.reconstruction`)."""
        return self.results.reconstruction(job_id)

    def colour_standard(self, name: str) -> tuple[Any, list[str]]:
        """A stored colour standard of this daemon's data directory by name
        (:func:`gonio.result_colour.stored_standard` in its ``standards/``): its colour report
        and warnings. Raises :class:`NotFound` for an unknown name, ``ColourError`` for a file
        that cannot be read as a standard."""
        from gonio.result_colour import STANDARDS_DIR, UnknownStandard, stored_standard

        try:
            return stored_standard(self.data_dir / STANDARDS_DIR, name)
        except UnknownStandard as exc:
            raise NotFound(str(exc)) from None

    def colour_standard_names(self) -> list[str]:
        """The stored colour standards of this daemon's data directory, by name."""
        from gonio.result_colour import STANDARDS_DIR, standard_names

        return standard_names(self.data_dir / STANDARDS_DIR)

    def store_colour_standard(self, name: str, text: str) -> dict[str, Any]:
        """Keep a colour CSV as the stored standard ``name``
        (:func:`gonio.result_colour.store_standard`): what it holds, and whether it replaced
        one. Raises ``ColourError`` for a name or text that cannot be one (nothing written)."""
        from gonio.result_colour import STANDARDS_DIR, store_standard

        report, said, replaced = store_standard(self.data_dir / STANDARDS_DIR, name, text)
        return {"name": report.name, "replaced": replaced,
                "illuminant": report.conditions.illuminant,
                "observer": report.conditions.observer,
                "geometries": len(report.geometries), "warnings": said}

    def delete_colour_standard(self, name: str) -> str:
        """Remove the stored standard ``name`` (:func:`gonio.result_colour.delete_standard`):
        the name it had. Raises :class:`NotFound` for an unknown name, listing the stored
        ones."""
        from gonio.result_colour import STANDARDS_DIR, UnknownStandard, delete_standard

        try:
            return delete_standard(self.data_dir / STANDARDS_DIR, name)
        except UnknownStandard as exc:
            raise NotFound(str(exc)) from None

    def preview_png(self, job_id: int) -> bytes:
        """PNG preview of a job's table (:meth:`ResultViews.preview_png`)."""
        return self.results.preview_png(job_id)

    def export(self, job_id: int, fmt: str, with_mesh: bool = False) -> tuple[Path, str]:
        """A job's result exported as ``fmt`` (:meth:`ResultViews.export`)."""
        return self.results.export(job_id, fmt, with_mesh)

    def export_warnings(self, path: Path) -> list[str]:
        """The warnings of an export :meth:`export` made (:meth:`ResultViews.export_warnings`)."""
        return self.results.export_warnings(path)

    def render_png(self, job_id: int, compare: int | None = None) -> bytes:
        """Rendering of a job's reconstruction (:meth:`ResultViews.render_png`)."""
        return self.results.render_png(job_id, compare)

    def fit_curves(self, job_id: int) -> dict[str, Any]:
        """A job's samples and the reconstruction's curves through them
        (:meth:`ResultViews.fit_curves`)."""
        return self.results.fit_curves(job_id)

    def polar_curves(self, job_id: int, theta_i_deg: float, phi_i_deg: float) -> dict[str, Any]:
        """A job's in-plane and cross-plane BRDF at one incidence
        (:meth:`ResultViews.polar_curves`)."""
        return self.results.polar_curves(job_id, theta_i_deg, phi_i_deg)

    # ------------------------------------------------------------------ rig
    async def rig_status(self) -> RigStatus:
        devices = await self._on_engine(self._device_states())
        st = self.status()
        return RigStatus(
            connected=self._connected, error=self._connect_error,
            current_job=st.current_job, queue_held=st.queue_held, devices=devices,
        )

    async def _device_states(self) -> list[DeviceState]:
        devices: list[DeviceState] = []
        if self._connected:
            rig = self._rig
            for name, call in [("stage", rig.stage.status),
                               *((n, lt.status) for n, lt in rig.lights.items()),
                               *((n, s.status) for n, s in rig.sensors.items())]:
                try:
                    st = await asyncio.wait_for(call(), timeout=2.0)
                    faults = tuple(getattr(st, "faults", ()))
                    ok = not faults and bool(getattr(st, "ok", True)) and bool(
                        getattr(st, "in_band", True))
                    detail = {k: v for k, v in vars(st).items()
                              if isinstance(v, int | float | str | bool | tuple)}
                    devices.append(DeviceState(name=name, ok=ok, detail=detail))
                except Exception as exc:  # report, do not raise: this is a status page
                    devices.append(DeviceState(name=name, ok=False, detail={"error": str(exc)}))
        return devices

    async def stage_command(self, request: StageRequest) -> StageState:
        """Run one manual stage command and return the stage state after it
        (:meth:`gonio.stage_control.StageControl.command`), on the engine loop, where the
        devices live."""
        return await self._on_engine(self.stage.command(request))

    async def stage_status(self) -> StageState:
        """Where the stage is, whether it moves, is homed, has faults (connects if needed;
        :meth:`gonio.stage_control.StageControl.status`)."""
        return await self._on_engine(self.stage.status())

    def active_job(self) -> JobInfo | None:
        jobs = [r for r in self.store.list_jobs() if r.state in ACTIVE_STATES]
        return JobInfo.from_row(jobs[0]) if jobs else None
