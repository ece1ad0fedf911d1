"""The one module the REST layer sits on: jobs, control, events, results, rig status.

Every request and response type is a pydantic model (they become the API schema). Errors are
typed so the API can map them: :class:`NotFound` -> 404, :class:`Conflict` (including
:class:`gonio.jobstates.IllegalTransition`) -> 409, :class:`gonio.plans.models.PlanError` and
:class:`gonio.motion.StageMoveError` -> 422.

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
import threading
from collections.abc import AsyncIterator, Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from pydantic import BaseModel, Field

from gonio import hal
from gonio.calibration import Calibration, calibration_in_effect
from gonio.diskspace import DiskFull, disk_full_message, is_disk_full, low_space
from gonio.engine_loop import EngineLoop
from gonio.fields import FINITE, Count
from gonio.jobstates import ACTIVE_STATES, IllegalTransition, JobState, check_action
from gonio.maintenance import LOCK_FILE_NAME, MaintenanceLock
from gonio.motion import StageMoveError
from gonio.plans.checked import CheckedPlan, check_plan
from gonio.plans.dryrun import DryRun, arc_may_apply, dry_run
from gonio.plans.models import (
    DEFAULT_SPAN_DEG,
    AnyPlan,
    Plan,
    PlanError,
    parse_plan,
    parse_stored_plan,
)
from gonio.rigdescription import RigDescription
from gonio.store import EventRow, JobRow, JobStore, ReadingRow
from gonio.store import NotFound as StoreNotFound
from gonio.worker import BasisProvider, Worker, default_basis_provider

if TYPE_CHECKING:  # the design numerics load on the first design, not with the service
    from gonio.results import ResultCache, ResultFile
    from gonio.sampling_design import DesignRequest, DesignResult

log = logging.getLogger("gonio.service")

__all__ = [
    "Conflict",
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
]


class NotFound(StoreNotFound):
    """No such job, or the job has no result yet (API: 404)."""


class Conflict(ValueError):
    """The request conflicts with the job's or the service's state (API: 409)."""


# --------------------------------------------------------------------------- schema
class JobRequest(BaseModel):
    """A scan request: the plan, and where it goes in the queue."""

    model_config = FINITE

    plan: Plan
    priority: Count = Field(default=0, ge=-1000, le=1000, description="higher runs first")


class ReorderRequest(BaseModel):
    model_config = FINITE

    priority: Count | None = Field(default=None, ge=-1000, le=1000)
    position: Count | None = Field(default=None, ge=0, le=2**31, description="0 = next to run")


class JobInfo(BaseModel):
    """One line of the job list."""

    id: int
    state: JobState
    kind: str
    specimen: str
    priority: int
    created: float
    started: float | None
    finished: float | None
    done_angles: int
    total_angles: int
    reason: str | None

    @classmethod
    def from_row(cls, row: JobRow) -> JobInfo:
        return cls(
            id=row.id, state=row.state, kind=row.kind, specimen=row.specimen,
            priority=row.priority, created=row.created, started=row.started,
            finished=row.finished, done_angles=row.done_angles, total_angles=row.total_angles,
            reason=row.reason,
        )


class JobDetail(JobInfo):
    """Everything about one job in one call."""

    plan: dict[str, Any]
    eta_s: float | None = Field(description="estimated seconds to the end of measuring: the "
                                "measured time per stage angle times the angles left, "
                                "counted down since the last angle")
    eta_max_s: float | None = Field(default=None, description="adaptive plans: bound on "
                                    "eta_s if every refinement round runs in full")
    activity: str | None = Field(default=None, description="what the job is doing or "
                                 "waiting for beyond measuring (e.g. the first basis build)")
    activity_fraction: float | None = Field(default=None, description="fraction of the "
                                            "activity done, when known")
    queue_position: int | None = Field(description="0 = next to run; null unless queued")
    result_path: str | None
    result: dict[str, Any] | None = Field(description="summary: metrics, readings, paths")
    rig: dict[str, Any]


class Event(BaseModel):
    seq: int
    type: str
    job_id: int | None
    time: float
    data: dict[str, Any]

    @classmethod
    def from_row(cls, ev: EventRow) -> Event:
        return cls(seq=ev.seq, type=ev.type, job_id=ev.job_id, time=ev.time, data=ev.data)


class DeviceState(BaseModel):
    name: str
    ok: bool
    detail: dict[str, Any] = Field(default_factory=dict)


class RunningJob(BaseModel):
    """Progress of the job being measured now."""

    id: int
    done_angles: int = Field(description="stage angles measured so far")
    total_angles: int = Field(description="stage angles planned so far (adaptive plans grow)")
    eta_s: float | None = Field(description="estimated seconds to the end of measuring")


class ServiceStatus(BaseModel):
    """What the worker is doing, from memory (no store read, no device call)."""

    current_job: int | None = Field(description="job being measured or reconstructed")
    queue_held: str | None = Field(description="why the queue takes no new job (halt, a failed "
                                   "job's stop, maintenance lock); null if it runs")
    running: RunningJob | None = Field(description="progress while a job is measuring")


class RigStatus(BaseModel):
    connected: bool
    error: str | None = None
    current_job: int | None = None
    queue_held: str | None = None
    devices: list[DeviceState] = Field(default_factory=list)


class StageRequest(BaseModel):
    """A manual stage command: commissioning (set the zero at the holder's reference mark) and
    loading specimens. Refused while a job is active; ``stop`` is always accepted."""

    model_config = FINITE

    action: Literal["move", "home", "stop", "clear_faults"] = Field(
        description="move to angle_deg; home = make the present position 0 deg; stop; "
                    "clear_faults = reboot / clear latched faults")
    angle_deg: float | None = Field(None, description="target of a move, degrees")


class StageState(BaseModel):
    position_deg: float
    moving: bool
    homed: bool
    faults: list[str] = Field(default_factory=list)


class DeviceError(RuntimeError):
    """A device fault while serving a manual command (the API answers 503 with the reason)."""


T = TypeVar("T")

_PREVIEW_CACHE = 8
"""Preview PNGs kept in memory (a few tens of kB each)."""
_RENDER_CACHE = 3
"""Rendered figures kept in memory (about 1-3 MB each): the job on the page, the one it is
compared with, one more. More kept the daemon growing for six scans (bench/bench_memory.py)."""


# --------------------------------------------------------------------------- service
class GonioService:
    """Jobs, control and events over one rig.

    Parameters
    ----------
    store : JobStore
    rig : a :class:`gonio.hal.Rig`, or a callable building one (connected on first use)
    rig_config : the :class:`gonio.config.RigConfig` (snapshot in results; its
        ``[calibration]`` factors are used until a calibration job replaces them)
    basis_provider : callable returning the reconstruction basis (default: ``default_basis``)
    data_dir : folder for result files and the latest calibration
    calibration : applied to every scan instead of the one in effect (``gonio scan
        --calibration``); default: :meth:`calibration`'s rule
    """

    def __init__(
        self,
        store: JobStore,
        rig: hal.Rig | Callable[[], hal.Rig],
        rig_config: Any = None,
        basis_provider: BasisProvider | None = None,
        data_dir: str | Path = "gonio-data",
        calibration: Calibration | None = None,
    ):
        self.store = store
        self._calibration = calibration
        self._rig: hal.Rig = rig if isinstance(rig, hal.Rig) else rig()
        self.rig_config = rig_config
        # Absolute once: result paths in the store are relative to it, and must not follow
        # the process's working directory.
        self.data_dir = Path(data_dir).absolute()
        self.desc = RigDescription.from_rig(self._rig)
        self._connected = False
        self._connect_error: str | None = None
        self._connect_lock = asyncio.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._cond: asyncio.Condition | None = None
        self._version = 0
        self._task: asyncio.Task[None] | None = None  # the worker, on the engine loop
        # The worker, the engine and every device call run on their own loop and thread, so
        # request handling on the API's loop cannot delay a scan (gonio/engine_loop.py).
        self._engine = EngineLoop()
        self._preview_lock = threading.Lock()
        self._previews: dict[tuple[str, int], bytes] = {}
        self._renders: dict[tuple[Any, ...], bytes] = {}
        # Every read of a result file for serving goes through one cache (made on first use:
        # HDF5 loads with it).
        self._result_cache: ResultCache | None = None
        self.stage_deg: float | None = None
        """Last known stage position, degrees (None until a job or a manual move reports it)."""
        self._basis_lock = threading.Lock()
        self._design_lock = threading.Lock()  # one sampling design at a time (self.design)
        self._basis: Any = None
        # OS locks this service owns for its life (data directory, rig endpoints: see
        # gonio.daemon.build_app); released by stop().
        self.owned: list[Any] = []
        # Why the worker died, once it has: /health then fails and the daemon exits non-zero.
        self.worker_failure: str | None = None
        self.on_fatal: Callable[[], None] | None = None
        provenance: dict[str, Any] = {}
        if rig_config is not None and hasattr(rig_config, "model_dump_json"):
            provenance["rig_config"] = rig_config.model_dump_json()
        self.worker = Worker(
            store, self._get_rig, self.desc, self.data_dir,
            basis_provider or default_basis_provider, self.calibration, provenance,
        )
        # While the maintenance lock (a file in the data directory) is set, no job starts.
        self.maintenance = MaintenanceLock(self.data_dir / LOCK_FILE_NAME)
        self.worker.gate = self.maintenance.reason
        store.add_listener(self._on_event)

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        """Reconcile jobs left active by a previous process and start the worker.

        The worker runs on the service's engine loop, a thread of its own
        (:class:`gonio.engine_loop.EngineLoop`); this loop serves requests and events.
        """
        self._loop = asyncio.get_running_loop()
        self._cond = asyncio.Condition()
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
        self.store.remove_listener(self._on_event)
        for lock in reversed(self.owned):
            lock.release()
        self.owned.clear()

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

    def design_basis(self) -> Any:
        """The basis sampling designs are computed against: the one scans reconstruct with.

        Blocking: the first call loads (or builds) it through the basis provider; it is kept
        for later designs.
        """
        with self._basis_lock:
            if self._basis is None:
                # The scans' basis: its symmetry serves the dry runs' arc check too.
                self._basis = self.worker.remember_basis(self.worker.basis_provider())
            return self._basis

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
               checked: CheckedPlan | None = None) -> JobInfo:
        """Validate a request against the rig and queue it. Raises :class:`PlanError`.

        ``checked``: the request's plan as the caller already checked it on this rig
        (:meth:`check`), so it is not checked again; the worker starts the job with it.
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
        symmetry = self.worker.basis_symmetry() if arc_may_apply(plan) else None
        checked = check_plan(checked if checked is not None and checked.plan == plan else plan,
                             self.desc)
        if plan.finishing != "calibration":
            self._check_calibration_covers(checked)
        full = self.disk_full
        if full is not None:
            # Queued now, it would measure for minutes and then fail writing its result.
            raise DiskFull(f"{full}; the job was not queued")
        row = self.store.create_job(
            kind=plan.kind, specimen=plan.specimen, plan=plan.model_dump(mode="json"),
            rig=self.desc.model_dump(mode="json"), priority=request.priority,
        )
        self.worker.take_checked(row.id, checked)
        self.worker.note_arc(row.id, plan, symmetry)
        self.worker.wake()
        return JobInfo.from_row(row)

    def _check_calibration_covers(self, checked: CheckedPlan) -> None:
        """Refuse, before anything moves, a plan the calibration in effect covers only in part
        (its result would mix sensor units and 1/sr). Raises :class:`PlanError` naming the
        pairs, or :class:`gonio.calibration.CalibrationError` for a damaged calibration."""
        from gonio.calibration import PartialCalibration

        try:
            self.calibration().check_covers(checked.pairs, "this plan")
        except PartialCalibration as exc:
            raise PlanError(str(exc)) from None

    def list_jobs(self, state: str | None = None) -> list[JobInfo]:
        return [JobInfo.from_row(r) for r in self.store.list_jobs([state] if state else None)]

    def _row(self, job_id: int) -> JobRow:
        try:
            return self.store.get_job(job_id)
        except StoreNotFound:
            raise NotFound(f"no job with id {job_id}") from None

    def get_job(self, job_id: int) -> JobDetail:
        """One job's full status: one row read, plus the queue position if it is queued.

        Cheap enough to serve many polling clients: no plan is re-parsed, the ETA is the
        engine's last estimate (updated at each checkpoint), not recomputed.
        """
        row = self._row(job_id)
        eta = eta_max = None
        p = self.worker.progress(job_id)
        if p is not None:
            # Counted down while measuring; frozen while paused or suspended.
            eta = p.eta_now() if row.state is JobState.RUNNING else p.eta_s
            if p.eta_max_s is not None:
                eta_max = max(p.eta_max_s - (p.eta_s or 0.0) + (eta or 0.0), eta or 0.0)
        activity = fraction = None
        if self.worker.current_job == job_id:
            # Reconstructing, or an adaptive job loading its basis before the first reading.
            report = self.worker.activity_report()
            if report is not None:
                activity, fraction = report
        qpos = self.store.queue_position(job_id) if row.state is JobState.QUEUED else None
        base = JobInfo.from_row(row).model_dump()
        return JobDetail(**base, plan=row.plan, eta_s=eta, eta_max_s=eta_max,
                         activity=activity, activity_fraction=fraction, queue_position=qpos,
                         result_path=row.result_path, result=row.summary, rig=row.rig)

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
        return JobInfo.from_row(self._row(job_id))

    def resume(self, job_id: int) -> JobInfo:
        row = self._row(job_id)
        check_action("resume", row.state, job_id)
        self.worker.resume_measurement(job_id)
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
                    self.store.set_state(job_id, JobState.ABORTED, reason="aborted by request")
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
                priority: int | None = None, position: int | None = None) -> JobInfo:
        if request is not None:
            priority, position = request.priority, request.position
        if priority is None and position is None:
            raise Conflict("reorder needs a priority or a position")
        self._row(job_id)
        return JobInfo.from_row(self.store.reorder(job_id, priority=priority, position=position))

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
        held = self.worker.held if self.worker.held is not None else self.worker.gate()
        return ServiceStatus(current_job=self.worker.current_job, queue_held=held,
                             running=running)

    def record_event(self, type_: str, data: dict[str, Any], job_id: int | None = None) -> Event:
        """Log an event of the daemon (e.g. the maintenance lock) for every subscriber."""
        return Event.from_row(self.store.append_event(job_id, type_, data))

    def check(self, plan: AnyPlan) -> CheckedPlan:
        """``plan`` checked on this rig (what :meth:`submit` checks, minus the calibration
        and the disk); hand the result to :meth:`dry_run` and :meth:`submit` so neither checks
        it again. Raises :class:`PlanError`."""
        return check_plan(plan, self.desc)

    def dry_run(self, plan: AnyPlan | CheckedPlan | dict[str, Any]) -> DryRun:
        """Check and time a plan from the stage's last known position (else 0 deg, said so)."""
        p = plan if isinstance(plan, BaseModel | CheckedPlan) else parse_plan(plan)
        kind = p.plan if isinstance(p, CheckedPlan) else p
        return dry_run(p, self.desc, self.stage_deg,
                       basis_ready=not self.worker.basis_build_needed(),
                       basis=self.worker.basis_symmetry() if arc_may_apply(kind) else None)

    @property
    def disk_full(self) -> str | None:
        """Why no job starts or is queued: the data directory's disk is full, or a write
        to it failed for lack of space and it has not had room since (None: it has room)."""
        return self.worker.disk_full or low_space(self.data_dir)

    # ------------------------------------------------------------------ events
    @property
    def seq(self) -> int:
        """Sequence number of the latest event."""
        return self.store.last_seq()

    def _on_event(self, ev: EventRow) -> None:
        # The stage's last known position, for dry runs: every checkpoint and manual stage
        # command reports it.
        pos = ev.data.get("actual_deg") if ev.type == "progress" else (
            ev.data.get("position_deg") if ev.type == "stage" else None)
        if isinstance(pos, int | float):
            self.stage_deg = float(pos)
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            loop.create_task(self._bump())
        else:
            asyncio.run_coroutine_threadsafe(self._bump(), loop)

    def add_event_listener(self, fn: Callable[[Event], None]) -> Callable[[EventRow], None]:
        """Call ``fn(event)`` right after each event is stored, in the committing thread.

        Runs before the code that caused the event continues (e.g. before the worker takes the
        next job), so keep ``fn`` short. Returns the handle for :meth:`remove_event_listener`.
        """
        def listener(ev: EventRow) -> None:
            fn(Event.from_row(ev))

        self.store.add_listener(listener)
        return listener

    def remove_event_listener(self, handle: Callable[[EventRow], None]) -> None:
        self.store.remove_listener(handle)

    async def _bump(self) -> None:
        assert self._cond is not None
        async with self._cond:
            self._version += 1
            self._cond.notify_all()

    async def subscribe(self, since_seq: int = 0, job_id: int | None = None
                        ) -> AsyncIterator[Event]:
        """Stored events after ``since_seq``, then live ones as they happen; none is lost.

        Every event is committed to the store before subscribers are woken, and each wake-up
        re-reads the store from the last delivered ``seq``, so a burst is never dropped.
        """
        if self._cond is None:
            self._cond = asyncio.Condition()
        last = since_seq
        while True:
            version = self._version
            batch = self.store.events_after(last, 500, job_id=job_id)
            for ev in batch:
                last = ev.seq
                yield Event.from_row(ev)
            if batch:
                continue
            async with self._cond:
                await self._cond.wait_for(lambda v=version: self._version != v)  # type: ignore[misc]

    # ------------------------------------------------------------------ results
    def result_path(self, job_id: int) -> Path:
        """Where job ``job_id``'s result file is: the store's path, relative to the data
        directory (an absolute one, from a foreign store, is taken as it is)."""
        row = self._row(job_id)
        if not row.result_path:
            raise NotFound(f"job {job_id} has no result yet (it is {row.state.value})")
        return self.data_dir / row.result_path

    def rebuild_hint(self, job_id: int) -> str:
        """What to do about a job whose result file is missing or damaged."""
        return (f"rebuild it from the readings the job store holds: gonio jobs rebuild "
                f"{job_id} --db {self.store.path}")

    def checked_result_path(self, job_id: int) -> Path:
        """Job ``job_id``'s result file, once it has been read whole (and kept in the cache),
        so a truncated or damaged file is never served as if it were good.

        Blocking (reads the file): call it from a thread in async code.

        Raises
        ------
        NotFound
            No such job, no result yet, or the file is missing.
        gonio.results.ResultFileError
            The file is damaged; the message names the job and how to rebuild it.
        """
        self.result(job_id)
        return self.result_path(job_id)

    def damaged_results(self) -> list[str]:
        """One line per completed job whose result file is missing or damaged
        (:func:`gonio.results.check_result_file`, cheap: no dataset is read whole)."""
        from gonio.results import ResultFileError, check_result_file

        out = []
        for row in self.store.list_jobs([JobState.COMPLETED.value]):
            if not row.result_path:
                continue
            try:
                check_result_file(self.data_dir / row.result_path)
            except ResultFileError as exc:
                out.append(f"job {row.id}: {exc}; {self.rebuild_hint(row.id)}")
        return out

    def metrics(self, job_id: int) -> dict[str, Any]:
        row = self._row(job_id)
        if row.summary is None:
            raise NotFound(f"job {job_id} has no result yet (it is {row.state.value})")
        from gonio.figures import headline_error

        out = dict(row.summary)
        # The one error number to show, with its meaning (the same words as `gonio scan`).
        out["headline_error"] = headline_error(out)
        return out

    def result(self, job_id: int) -> ResultFile:
        """A job's result file, read whole; the last few are kept (:class:`ResultCache`).

        Blocking (reads the file): call it from a thread in async code.

        Raises
        ------
        NotFound
            No such job, or it has no result yet.
        gonio.results.ResultFileError
            The file cannot be read (damaged, truncated); the message names the job and
            how to rebuild it.
        """
        from gonio.results import ResultFileError

        path = self.result_path(job_id)
        if not path.is_file():
            raise NotFound(f"job {job_id}'s result file {path.name} is missing from the data "
                           f"directory; {self.rebuild_hint(job_id)}")
        try:
            return self._results().get(path)
        except ResultFileError as exc:
            raise ResultFileError(f"job {job_id}'s result file is damaged: {exc}; "
                                  f"{self.rebuild_hint(job_id)}") from None

    def _results(self) -> ResultCache:
        with self._preview_lock:
            if self._result_cache is None:
                from gonio.results import ResultCache

                # Two: a job and the one it is compared with (a table is 5-10 MB in memory).
                self._result_cache = ResultCache(size=2)
            return self._result_cache

    def reconstruction(self, job_id: int) -> ResultFile:
        """A job's result file that holds a reconstructed BRDF (for the plots of the page).

        Raises
        ------
        NotFound
            No such job, no result yet, the file is missing, or it has no BRDF (calibration).
        """
        res = self.result(job_id)
        if res.table is None:
            raise NotFound(f"job {job_id} has no reconstructed BRDF (a calibration job has none)")
        return res

    def preview_png(self, job_id: int) -> bytes:
        """PNG preview of the reconstructed table (:func:`gonio.brdf.pictures.preview.preview_png`).

        Blocking (reads the result file, renders): call it from a thread in async code. The
        PNG of the last few results is kept, since a finished result file never changes.

        Raises
        ------
        NotFound
            The job has no result yet, or it is a calibration job (no BRDF).
        """
        path = self.result_path(job_id)
        key = (str(path), path.stat().st_mtime_ns if path.is_file() else 0)
        with self._preview_lock:
            cached = self._previews.get(key)
        if cached is not None:
            return cached
        res = self.result(job_id)
        if res.table is None:
            raise NotFound(f"job {job_id} is a {res.attrs.get('kind')} job without a BRDF")
        from gonio.brdf.pictures.preview import preview_png

        png = preview_png(res.table, title=f"job {job_id}: {res.table.name}")
        with self._preview_lock:
            self._previews[key] = png
            while len(self._previews) > _PREVIEW_CACHE:
                self._previews.pop(next(iter(self._previews)))
        return png

    def export(self, job_id: int, fmt: str) -> tuple[Path, str]:
        """A job's result exported as ``fmt`` (:mod:`gonio.export`): file path and file name.

        Blocking (may fit and resample for seconds): call it from a thread in async code.
        Exports are kept under ``data_dir/exports`` and reused while the result file is
        unchanged.

        Raises
        ------
        NotFound
            The job has no result yet, or its result has no BRDF (a calibration job).
        """
        from gonio.export import FORMATS, ExportError, check_format, export_result

        check_format(fmt)
        path = self.result_path(job_id)
        self.result(job_id)  # missing or damaged: said with the way to rebuild it
        name = f"gonio-job-{job_id}-{fmt}{FORMATS[fmt]}"
        out = self.data_dir / "exports" / name
        if out.is_file() and out.stat().st_mtime_ns >= path.stat().st_mtime_ns:
            return out, name
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            export_result(path, fmt, out)
        except ExportError as exc:
            raise NotFound(f"job {job_id}: {exc}") from None
        return out, name

    def render_png(self, job_id: int, compare: int | None = None) -> bytes:
        """Rendering of a job's reconstruction (:func:`gonio.figures.render_inputs`).

        With ``compare``, that job's reconstruction is shown below for comparison; without,
        the true material above it when the result records one (simulated rig). Blocking
        (seconds: it renders six views per material): call it from a thread. The last few
        PNGs are kept, since finished result files never change.

        Raises
        ------
        NotFound
            A job has no result yet, or it is a calibration job (no BRDF).
        """
        from gonio.figures import FigureError, render_inputs

        paths = [self.result_path(job_id)]
        if compare is not None:
            paths.append(self.result_path(compare))
        key = ("render", *((str(p), p.stat().st_mtime_ns if p.is_file() else 0) for p in paths))
        with self._preview_lock:
            cached = self._renders.get(key)
        if cached is not None:
            return cached
        ids = [job_id] if compare is None else [job_id, compare]
        for jid in ids:
            self.result(jid)  # missing or damaged: said with the way to rebuild it
        try:
            png = render_inputs(paths)
        except FigureError as exc:
            raise NotFound(str(exc).replace(str(paths[0]), f"job {job_id}")) from None
        with self._preview_lock:
            self._renders[key] = png
            while len(self._renders) > _RENDER_CACHE:
                self._renders.pop(next(iter(self._renders)))
        return png

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
        """Run one manual stage command and return the stage state after it (see
        :meth:`_stage_command`); it runs on the engine loop, where the devices live."""
        return await self._on_engine(self._stage_command(request))

    async def _stage_command(self, request: StageRequest) -> StageState:
        """Run one manual stage command and return the stage state after it.

        The queue is held for the duration so no job starts under a manual move.

        Raises
        ------
        Conflict
            A job is active (``stop`` excepted: stopping is always allowed).
        StageMoveError
            A move without ``angle_deg`` or outside the stage's travel limits.
        DeviceError
            The stage reported a fault or stopped answering.
        """
        if request.action == "move":
            lo, hi = self.desc.stage_min_deg, self.desc.stage_max_deg
            if request.angle_deg is None:
                raise StageMoveError("a stage move needs angle_deg (degrees)")
            if not lo <= request.angle_deg <= hi:
                raise StageMoveError(
                    f"angle_deg {request.angle_deg:g} is outside the stage's travel limits "
                    f"[{lo:g}, {hi:g}] deg (min_deg/max_deg in the rig config)")
        active = self.active_job()
        if active is not None and request.action != "stop":
            raise Conflict(f"job {active.id} is {active.state.value}: the stage is in use; wait "
                           "for it, or pause or abort it, before moving the stage by hand")
        was_held = self.worker.held is not None
        manual = f"manual stage command: {request.action}"
        if not was_held:
            # Only for the command's duration: not a decision to outlive a crash.
            self.worker.hold(manual, durable=False)
        try:
            rig = await self._get_rig()
            stage = rig.stage
            if request.action == "move":
                assert request.angle_deg is not None
                await stage.move_to(request.angle_deg)
            elif request.action == "home":
                await stage.home()
            elif request.action == "stop":
                await stage.stop()
            else:
                await stage.clear_faults()
            st = await hal.status_at_rest(stage)
        except hal.DeviceFault as exc:
            raise DeviceError(f"stage {request.action} failed: {exc}") from exc
        finally:
            if not was_held and self.worker.held == manual:  # not a halt that came meanwhile
                self.worker.release()
        self.record_event("stage", {"action": request.action, "angle_deg": request.angle_deg,
                                    "position_deg": st.position_deg})
        return StageState(position_deg=st.position_deg, moving=st.moving, homed=st.homed,
                          faults=list(st.faults))

    async def stage_status(self) -> StageState:
        """Where the stage is, whether it moves, is homed, has faults (connects if needed).

        Raises
        ------
        DeviceError
            The stage does not answer or the rig cannot be connected.
        """
        async def read() -> hal.StageStatus:
            rig = await self._get_rig()
            return await rig.stage.status()

        try:
            st = await self._on_engine(read())  # where the drivers' connections live
        except (hal.DeviceFault, OSError) as exc:
            raise DeviceError(f"stage status failed: {exc}") from exc
        return StageState(position_deg=st.position_deg, moving=st.moving, homed=st.homed,
                          faults=list(st.faults))

    def active_job(self) -> JobInfo | None:
        jobs = [r for r in self.store.list_jobs() if r.state in ACTIVE_STATES]
        return JobInfo.from_row(jobs[0]) if jobs else None
