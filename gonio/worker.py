"""Runs jobs one at a time: the measurement (engine), then the reconstruction and result file.

Order: a job the previous process left active (resumed from its checkpoint) first, then queued
jobs by priority (high first), then queue position (FIFO by default). A failed job does not
stop the queue unless its plan sets ``stop_queue_on_failure``; an emergency halt holds the
queue until :meth:`Worker.release`. Those holds are stored (they survive a crash and a
restart); while :attr:`Worker.gate` gives a reason (the maintenance lock) no job starts or
resumes at all.

Finishing a measured job (calibration or reconstruction, and the result file:
:mod:`gonio.finishing`) runs in a thread (``asyncio.to_thread``) so the event loop keeps
serving the API and events while the numerics run.

A job is the store's until the worker hands it to its engine (:meth:`Worker._hand_to_engine`),
then the engine's until measuring ends; the service's abort, cancel, remove and halt decide
under the same lock (:attr:`Worker.changes`), so a request at any point of a start-up either
changes the stored job before the worker looks again or reaches the engine, which connects the
rig under the plan's fault policy and stops before any stage move (docs/engine.md, "Start-up").

A full disk (:mod:`gonio.diskspace`) never stops the worker: the job in hand is marked
``failed`` with "disk full" (once the store can record it), and no job starts until the data
directory's file system has room again (:attr:`Worker.disk_full`).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import threading
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gonio import hal, heap
from gonio.basis_supply import BasisSupply
from gonio.calibration import (
    Calibration,
    CalibrationError,
    sensor_channels,
)
from gonio.diskspace import (
    FREE_MARGIN_BYTES,
    disk_full_message,
    free_bytes,
    is_disk_full,
    low_space,
)
from gonio.engine import Progress, ScanEngine
from gonio.engine_loop import running_in
from gonio.finishing import Finishing, FinishingStopped, finish_job, rebuild_hint
from gonio.jobstates import FINISHED_STATES, QUEUE_HOLD, IllegalTransition, JobState
from gonio.plans.checked import CheckedPlan, check_plan
from gonio.plans.dryrun import BasisSymmetry, arc_may_apply
from gonio.plans.models import AdaptivePlan, AnyPlan, PlanError, parse_stored_plan
from gonio.rigdescription import RigDescription
from gonio.store import JobRow, JobStore, NotFound

if TYPE_CHECKING:  # the numerics load with the first basis
    from gonio.brdf.reconstruction.basis import Basis
    from gonio.refinement import PosteriorRefiner

log = logging.getLogger("gonio.worker")

KEEP_CHECKED = 64
"""Checked plans of submitted jobs the worker keeps before it drops those of jobs that are no
longer queued (:meth:`Worker.take_checked`)."""

GATE_POLL_S = 1.0
"""How often a closed gate (maintenance lock) is looked at again, seconds."""
DISK_POLL_S = 1.0
"""How often a full disk is looked at again, seconds."""

def needs_basis_to_measure(plan: AnyPlan) -> bool:
    """True for plans whose measurement itself uses the basis: adaptive plans with the
    posterior rule plan their later rounds with it (docs/science.md 7.3)."""
    return isinstance(plan, AdaptivePlan) and plan.rule == "posterior"


class Worker:
    """The job queue's single consumer.

    Parameters
    ----------
    store : JobStore
    get_rig : async callable returning the connected rig (connects on first use)
    rig_desc : RigDescription of that rig
    data_dir : results go to ``data_dir/results/job-<id>.h5``; calibrations to
        ``data_dir/calibration.json``
    basis : the process's reconstruction basis (:class:`gonio.basis_supply.BasisSupply`)
    calibration : callable returning the calibration to apply to scans
    provenance : extra provenance stored in every result (e.g. the rig config)
    fit_exports : store the factored and principled fits in every scan's result (a few
        seconds each; exports then need no refit)
    gate : callable saying why no job may start or resume now (None: they may), e.g. the
        maintenance lock; looked at again at least every :data:`GATE_POLL_S` while it blocks
    """

    def __init__(
        self,
        store: JobStore,
        get_rig: Callable[[], Awaitable[hal.Rig]],
        rig_desc: RigDescription,
        data_dir: Path,
        basis: BasisSupply,
        calibration: Callable[[], Calibration] = Calibration,
        provenance: dict[str, Any] | None = None,
        fit_exports: bool = True,
        gate: Callable[[], str | None] | None = None,
    ):
        self.store = store
        self.get_rig = get_rig
        self.desc = rig_desc
        self.data_dir = Path(data_dir)
        self.basis = basis
        self.calibration = calibration
        self.on_job_start: Callable[[JobRow], None] | None = None
        self.start_refusal: Callable[[JobRow, AnyPlan], str | None] | None = None
        """Why a queued job must not start although its plan still checks (the service's
        :meth:`gonio.service.GonioService.unasked_uncalibrated`); asked once, before anything
        moves, for a job that has measured nothing yet."""
        self.provenance = provenance or {}
        self.fit_exports = fit_exports
        self._engine: ScanEngine | None = None  # the job being measured; see "measurement"
        self.current_job: int | None = None
        self.changes = threading.RLock()
        """Serialises the state changes the service makes for users (abort, cancel, remove,
        halt) with the worker taking a job, handing it to an engine and taking it back: a job
        is either the store's (the service changes it there) or the engine's (the service
        asks the engine), never both. Held only for store calls, never across an await."""
        # A halt that came while the current job was being started, before its engine.
        self._halt_asked = False
        # The job to delete once its engine has stopped (removed before it moved).
        self._remove_when_stopped: int | None = None
        # Jobs this process gave up on after a transition it did not expect (logged).
        self._skip: set[int] = set()
        # The queue hold survives restarts: it is read back from the store.
        stored = store.hold(QUEUE_HOLD)
        self.held: str | None = stored[0] if stored is not None else None
        self.gate: Callable[[], str | None] = gate if gate is not None else (lambda: None)
        self._wake = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None  # where run_forever runs
        self._recon_task: asyncio.Task[dict[str, Any]] | None = None
        # Set to abort the running finishing thread at its next step (it writes nothing then).
        self._finish_stop: threading.Event | None = None
        self._stopping = False
        self.activity: str | None = None
        """What the current job waits for beyond measuring (e.g. the basis), or None."""
        self._activity_since = 0.0
        # When the current job's finishing began (monotonic), or None while it is not
        # finishing: its time left counts from here, across the activities it goes through.
        self._finishing_since: float | None = None
        # Plans checked at their submission in this process, by job id (taken at the start).
        self._checked: dict[int, CheckedPlan] = {}
        self._checked_lock = threading.Lock()  # submission (API threads) and the loop
        self.disk_full: str | None = None
        """Why no job starts now: the disk filled (see :meth:`note_disk_full`), or None."""
        # What the store could not record while the disk was full, done once it has room.
        self._on_space: list[Callable[[], object]] = []
        self.specimen_truth: Callable[[], dict[str, Any] | None] | None = None
        """Set by simulated rigs: the recipe of the material on the stage, stored with each
        reconstruction as ``provenance/true_material`` so renderings can show the truth."""

    # ------------------------------------------------------------------ control
    def wake(self) -> None:
        """Look at the queue again (a job was submitted, resumed or released).

        Callable from any thread: the worker may run on its own loop (gonio.engine_loop).
        """
        loop = self._loop
        if loop is not None and not loop.is_closed() and not running_in(loop):
            loop.call_soon_threadsafe(self._wake.set)
        else:
            self._wake.set()

    def hold(self, reason: str, durable: bool = True) -> None:
        """Take no new job until :meth:`release`; ``durable`` holds survive restarts (a
        short hold around a manual command need not)."""
        self.held = reason
        if durable:
            self.store.set_hold(QUEUE_HOLD, reason, "queue_held", {"reason": reason})
        else:
            self.store.append_event(None, "queue_held", {"reason": reason})

    def queue_held(self) -> str | None:
        """Why the queue takes no new job now (a halt, a failed job's stop, a manual command,
        the gate: the maintenance lock); None if it runs."""
        return self.held if self.held is not None else self.gate()

    def release(self) -> None:
        self.held = None
        self.store.clear_hold(QUEUE_HOLD, "queue_released", {})
        self.wake()

    def abort_reconstruction(self, job_id: int) -> bool:
        """Abort ``job_id``'s finishing if it is the one running (from any thread).

        The finishing thread stops at its next step (after the basis, the reconstruction or
        the fits) and writes nothing; the job becomes ``aborted`` then, and the next job
        starts only after it. A finishing that completes before it looks again completes.
        """
        stop = self._finish_stop
        if self.current_job == job_id and stop is not None:
            stop.set()
            return True
        return False

    # ------------------------------------------------------------------ measurement
    # The one way into the job being measured (the service never holds the engine). Callable
    # from any thread: the engine passes the requests to its own loop.
    def measuring(self) -> int | None:
        """Id of the job whose angles are being measured now, or None."""
        eng = self._engine
        return eng.job_id if eng is not None else None

    def progress(self, job_id: int | None = None) -> Progress | None:
        """Progress of the measurement in hand (of ``job_id`` only, when given), or None."""
        eng = self._engine
        if eng is None or (job_id is not None and eng.job_id != job_id):
            return None
        return eng.progress

    def pause_measurement(self, job_id: int, immediate: bool = False) -> bool:
        """Pause ``job_id`` at its next checkpoint (or now); False if it is not measuring."""
        eng = self._engine_of(job_id)
        if eng is not None:
            eng.request_pause(immediate)
        return eng is not None

    def resume_measurement(self, job_id: int) -> bool:
        """Resume ``job_id`` after a pause; False if it is not the job in hand."""
        eng = self._engine_of(job_id)
        if eng is not None:
            eng.request_resume()
        return eng is not None

    def abort_measurement(self, job_id: int) -> bool:
        """Abort ``job_id`` (lights off, stage stopped); False if it is not measuring here."""
        eng = self._engine_of(job_id)
        if eng is not None:
            eng.request_abort()
        return eng is not None

    def halt_measurement(self) -> None:
        """Emergency halt of whatever is measuring or being started: stop at once, send
        nothing more (a job being started, not yet handed to its engine, is not started)."""
        with self.changes:
            eng = self._engine
            if eng is not None:
                eng.request_halt()
            elif self.current_job is not None:
                self._halt_asked = True

    def stop_starting(self, job_id: int, reason: str, remove: bool = False) -> bool:
        """Take back ``job_id`` if it was taken from the queue and its stage has not moved
        yet: its engine aborts with ``reason`` before any move (and the job is deleted once
        it has stopped, with ``remove``). False when that job is not starting here."""
        with self.changes:
            eng = self._engine_of(job_id)
            if eng is None or not eng.from_queue or not eng.abort_before_moving(reason):
                return False
            if remove:
                self._remove_when_stopped = job_id
            return True

    def being_removed(self, job_id: int) -> bool:
        """True while ``job_id`` is deleted (:meth:`stop_starting` with ``remove``) but its
        engine has not stopped yet: to everyone else it is gone already."""
        return self._remove_when_stopped == job_id

    def _engine_of(self, job_id: int) -> ScanEngine | None:
        eng = self._engine
        return eng if eng is not None and eng.job_id == job_id else None

    def next_job(self) -> JobRow | None:
        if self.gate() is not None or self.disk_full is not None:
            return None  # not even a resumed job: someone is working on the rig
        active = [j for j in self.store.active_jobs() if j.id not in self._skip]
        if active:
            return active[0]
        if self.held is not None:
            return None
        queue = [j for j in self.store.queue() if j.id not in self._skip]
        return queue[0] if queue else None

    # ------------------------------------------------------------------ loop
    async def run_forever(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._start_prewarm()
        while not self._stopping:
            if self.disk_full is not None:
                await self._wait_for_space()
                continue
            job = self.next_job()
            if job is None:
                self._wake.clear()
                if self.gate() is None:
                    await self._wake.wait()
                else:  # the gate may open without a wake-up (a lock file removed by hand)
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(self._wake.wait(), GATE_POLL_S)
                continue
            low = low_space(self.data_dir)
            if low is not None:  # the job would fail writing its result: wait for room
                self.note_disk_full(low)
                continue
            try:
                await self.run_job(job)
            except (IllegalTransition, NotFound) as exc:
                self._unexpected(job.id, exc)
            except Exception as exc:
                if not is_disk_full(exc):
                    raise
                # A checkpoint or a state change the store could not write: the job fails
                # with "disk full" once the store can say so.
                self._disk_full_failure(job, disk_full_message(
                    f"job {job.id}'s progress (the job store)", self.store.path), exc)

    def _unexpected(self, job_id: int, exc: Exception) -> None:
        """A state change the worker did not expect (a bug, or a race not yet closed): say
        so and go on serving; the job is failed if it is still queued or active."""
        log.error("job %s: unexpected state change (%s); the worker goes on", job_id, exc,
                  exc_info=exc)
        with self.changes, contextlib.suppress(IllegalTransition, NotFound):
            if self.store.get_job(job_id).state not in FINISHED_STATES:
                self._skip.add(job_id)  # not taken again by this process, whatever happens
                self.store.set_state(job_id, JobState.FAILED,
                                     reason=f"internal error: {exc}")

    # ------------------------------------------------------------------ a full disk
    def note_disk_full(self, reason: str, then: Callable[[], object] | None = None) -> None:
        """Take no job until the data directory has room again; then call ``then`` (what
        the store could not record meanwhile). Callable from any thread."""
        if self.disk_full is None:
            log.error("%s; no job starts until there is room again", reason)
        self.disk_full = reason
        if then is not None:
            self._on_space.append(then)
        self.wake()

    def _disk_full_failure(self, job: JobRow, reason: str, exc: BaseException,
                           then: str = "") -> None:
        """Fail ``job`` with ``reason`` now, or once the store has room to record it;
        ``then`` (the job's own next step, e.g. how to finish it) follows in its reason."""
        log.error("job %s: %s (%s)", job.id, reason, exc)

        def fail() -> None:
            if self.store.get_job(job.id).state not in FINISHED_STATES:
                self._fail(job, f"{reason}; {then}" if then else reason)

        try:
            fail()
        except Exception as again:
            if not is_disk_full(again):
                raise
            self.note_disk_full(reason, fail)
            return
        self.note_disk_full(reason)

    async def _wait_for_space(self) -> None:
        """Wait until the data directory's file system has :data:`FREE_MARGIN_BYTES` free and
        what the store could not record is recorded; then jobs run again."""
        while not self._stopping:
            self._wake.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wake.wait(), DISK_POLL_S)
            if free_bytes(self.data_dir) < FREE_MARGIN_BYTES:
                continue
            try:
                while self._on_space:
                    self._on_space[0]()
                    self._on_space.pop(0)
            except Exception as exc:
                if not is_disk_full(exc):
                    raise
                continue
            log.info("the data directory has room again: jobs run again")
            self.disk_full = None
            return

    async def run_once(self) -> JobRow | None:
        """Run the next job to its end (for the CLI and tests); None when the queue is empty."""
        job = self.next_job()
        if job is None:
            return None
        await self.run_job(job)
        return self.store.get_job(job.id)

    async def run_job(self, job: JobRow) -> JobState:
        """Measure, reconstruct and write one job; returns its final state."""
        with self.changes:
            self.current_job = job.id
            self._halt_asked = False
        try:
            return await self._run_job(job)
        finally:
            with self.changes:
                self.current_job = None
                self._halt_asked = False
                self._remove_when_stopped = None
                self._engine = None
                self._finish_stop = None
            self._set_activity(None)
            self._finishing_since = None
            self._recon_task = None
            heap.trim()  # what the job's arrays left in the arenas (gonio/heap.py)

    def take_checked(self, job_id: int, checked: CheckedPlan) -> None:
        """Keep the plan :meth:`gonio.service.GonioService.submit` checked for job
        ``job_id``: the job's start uses it instead of checking the stored plan again.

        Jobs cancelled or removed before they start leave theirs behind: past
        :data:`KEEP_CHECKED` kept plans, those of jobs no longer queued are dropped.
        """
        with self._checked_lock:
            self._checked[job_id] = checked
            if len(self._checked) <= KEEP_CHECKED:
                return
        waiting = {row.id for row in self.store.queue()}
        with self._checked_lock:
            for k in [k for k in self._checked if k not in waiting and k != job_id]:
                del self._checked[k]

    def _checked_plan(self, job: JobRow) -> CheckedPlan:
        """The job's plan, checked on this rig: as submitted in this process, else parsed
        from the store and checked (a restart, or a rig changed since). Raises PlanError."""
        with self._checked_lock:
            checked = self._checked.pop(job.id, None)
        if checked is not None and checked.rig == self.desc:
            return checked
        return check_plan(parse_stored_plan(job.plan), self.desc)

    async def _run_job(self, job: JobRow) -> JobState:
        try:
            checked = self._checked_plan(job)
        except PlanError as exc:
            return self._fail(job, f"plan no longer valid on this rig: {exc}")
        plan = checked.plan
        if job.state is not JobState.RECONSTRUCTING and plan.finishing != "calibration":
            # Checked at submission too; the calibration may have changed since (a new
            # calibration job, a file edited by hand). A result calibrated in part, at another
            # exposure, or with a damaged file, is refused before anything moves.
            try:
                cal = self.calibration()
                cal.check_covers(checked.pairs, f"job {job.id}")
                cal.check_channels(checked.pairs, sensor_channels(self.desc), f"job {job.id}")
                cal.check_exposure(plan.exposure.exposure_s, f"job {job.id}")
            except CalibrationError as exc:
                return self._fail(job, f"not started: {exc}", plan)
            refusal = (self.start_refusal(job, plan) if self.start_refusal is not None
                       and job.state is JobState.QUEUED else None)
            if refusal is not None:
                return self._fail(job, f"not started: {refusal}", plan)
        basis: Basis | None = None  # loaded before measuring when the plan needs it
        if job.state is not JobState.RECONSTRUCTING:
            refiner = None
            if needs_basis_to_measure(plan):
                # The adaptive rule needs the basis after the first round: load (or build) it
                # now, before anything moves, so the stage never waits mid-scan for it.
                basis = await self._basis_before_measuring(job)
                refiner = self._refiner(checked, basis)
            # A half-turn plan and a basis without the twofold symmetry: said before the first
            # reading whenever the basis is at hand (loaded above, or built). The file is read
            # once per version, mostly already by the submission's check.
            if arc_may_apply(plan):  # only then is the basis file worth a look
                self.basis.note_arc(self.store, job.id, plan, BasisSymmetry.of(basis)
                                    if basis is not None else self.basis.symmetry())
            engine = self._hand_to_engine(job, checked, refiner)
            if not isinstance(engine, ScanEngine):
                return engine
            if self.on_job_start is not None:
                # Before the first reading of a new or resumed job: e.g. a simulated rig puts
                # the white reference or the job's specimen on the stage (no rig command).
                self.on_job_start(job)
            # The engine connects the rig (a silent device is waited for, as mid-scan), then
            # measures; an abort or halt asked meanwhile ends the job before any move.
            final = await engine.run()
            with self.changes:  # the job goes back from the engine to the store
                self._engine = None
                if final is JobState.RUNNING and engine.abort_requested:
                    # Asked as the last angle was committed: it is not reconstructed.
                    self.store.set_state(job.id, JobState.ABORTED, reason="aborted by request")
                    final = JobState.ABORTED
                if self._remove_when_stopped == job.id and final is not JobState.RUNNING:
                    self.store.delete_job(job.id)
                    return final
            if final is not JobState.RUNNING:
                if final is JobState.FAILED and plan.stop_queue_on_failure:
                    self.hold(f"job {job.id} failed and asked to stop the queue")
                if final is JobState.HALTED:
                    self.hold("emergency halt")
                return final
        # A basis loaded before measuring serves the finishing too (no second load from disk).
        with self.changes:
            if job.state is JobState.RECONSTRUCTING:  # resumed: it may have been aborted
                current = self.store.get_job(job.id).state
                if current is not JobState.RECONSTRUCTING:
                    return current
            else:
                self.store.set_state(job.id, JobState.RECONSTRUCTING)
            # From here an abort stops the finishing (:meth:`abort_reconstruction`).
            how = self._finishing(basis)
            self._finish_stop = how.stop
            self._finishing_since = time.monotonic()
        self._recon_task = asyncio.create_task(
            asyncio.to_thread(finish_job, job.id, checked, how))
        try:
            summary = await self._recon_task
        except asyncio.CancelledError:
            # The worker is stopping: the job stays reconstructing and is finished again at
            # the next start; the thread stops at its next step instead of writing meanwhile.
            how.stop.set()
            raise
        except FinishingStopped as exc:
            log.info("%s", exc)
            # Every reading is stored: the lab may want the result after all.
            hint = rebuild_hint(self.store, job.id, self.data_dir)
            self.store.set_state(job.id, JobState.ABORTED, reason="aborted by request while "
                                 "it was being finished" + (f"; {hint}" if hint else ""))
            return JobState.ABORTED
        except Exception as exc:  # a failed reconstruction fails the job, never the worker
            if is_disk_full(exc):
                what = (f"the calibration of job {job.id}" if plan.finishing == "calibration"
                        else f"the result file of job {job.id}")
                hint = rebuild_hint(self.store, job.id, self.data_dir)
                self._disk_full_failure(job, disk_full_message(what, self.data_dir), exc,
                                        then=f"once there is room, {hint}" if hint else "")
                return JobState.FAILED
            if isinstance(exc, CalibrationError) and plan.finishing == "calibration":
                # The reference's readings are unusable (not a white diffuser...): say why.
                log.error("job %s: calibration refused: %s", job.id, exc)
                return self._fail(job, f"calibration refused: {exc}", plan)
            log.exception("job %s: finishing failed", job.id)
            hint = rebuild_hint(self.store, job.id, self.data_dir)
            return self._fail(job, f"reconstruction failed: {exc}"
                              + (f"; once the cause is mended, {hint}" if hint else ""), plan)
        self.store.set_result(job.id, summary.get("result_path"), summary)
        if summary.get("physical_bounds"):
            # Completed, but not plainly: the event log and its listeners (the CLI) say why.
            self.store.append_event(job.id, "physical_bounds",
                                    {"message": summary["physical_bounds"]})
        if summary.get("arc_asymmetric"):
            # Forced over half a turn, but the readings at opposite angles differ: why.
            self.store.append_event(job.id, "arc_asymmetric",
                                    {"message": summary["arc_asymmetric"]})
        if summary.get("basis_switch"):
            # The test's verdict chose the reconstruction basis (docs/science.md 7.4): which.
            self.store.append_event(job.id, "basis_switch", {
                "message": summary["basis_switch"],
                "basis": summary.get("reconstruction_basis"), "K": summary.get("K")})
        if summary.get("design_gap"):
            # The self-estimate is more than x2 from its design's expected error: why.
            self.store.append_event(job.id, "design_gap", {"message": summary["design_gap"]})
        self.store.set_state(job.id, JobState.COMPLETED)
        return JobState.COMPLETED

    def _fail(self, job: JobRow, reason: str, plan: AnyPlan | None = None) -> JobState:
        with self.changes:
            try:
                current = self.store.get_job(job.id).state
            except NotFound:  # removed meanwhile
                return JobState.ABORTED
            if current in FINISHED_STATES:  # aborted or cancelled meanwhile: that stands
                log.info("job %s: not failed (%s): it is %s already", job.id, reason,
                         current.value)
                return current
            self.store.set_state(job.id, JobState.FAILED, reason=reason)
        if plan is not None and plan.stop_queue_on_failure:
            self.hold(f"job {job.id} failed and asked to stop the queue")
        return JobState.FAILED

    def _refiner(self, checked: CheckedPlan, basis: Basis | None) -> PosteriorRefiner | None:
        """The posterior rule's bridge for adaptive plans that use it (docs/science.md 7.3);
        None without a basis (the engine then uses V&F's rule and says so). An auto-arc plan's
        refiner also gets the basis for specimens without twofold symmetry, for the rounds
        after its test calls the specimen so (docs/science.md 7.4), when this process has one
        and it is at hand without a build: the stage does not wait minutes mid-scan for it
        (the rounds then plan with the default basis and their events say so; finishing
        builds it)."""
        if basis is None or not needs_basis_to_measure(checked.plan):
            return None
        from gonio.refinement import PosteriorRefiner

        supply = self.basis

        def asymmetric() -> Basis | None:
            return None if supply.asymmetric_build_needed() else supply.asymmetric()

        auto = checked.plan.arc_mode() == "auto" and supply.has_asymmetric
        return PosteriorRefiner(lambda: basis, self.desc, checked.pairs, self.calibration(),
                                asymmetric_provider=asymmetric if auto else None)

    # ------------------------------------------------------------------ the basis, early
    def _start_prewarm(self) -> None:
        """At start: when the queue (or a job left active) holds a plan that measures with the
        basis and the basis must be built, build it now in a thread, while earlier jobs run."""
        if self.basis.prewarming or not self.basis.build_needed():
            return
        jobs = [*self.store.active_jobs(), *self.store.queue()]
        wanted = []
        for row in jobs:
            with contextlib.suppress(PlanError):
                if needs_basis_to_measure(parse_stored_plan(row.plan)):
                    wanted.append(row.id)
        if not wanted:
            return
        self.store.append_event(None, "basis_prewarm", {
            "jobs": wanted, "message": "building the reconstruction basis for the queued "
            "adaptive jobs (first use on this install)"})
        log.info("building the default basis for queued adaptive jobs %s", wanted)
        self.basis.prewarm()

    async def _basis_before_measuring(self, job: JobRow) -> Basis | None:
        """Load (or build) the basis before the job's first reading, off the event loop.

        The job's events say what happens (``basis_loading`` then ``basis_ready`` or
        ``basis_failed``) and its status shows the activity meanwhile. A basis that cannot
        be had does not fail the job: the engine measures with V&F's rule and says so.
        """
        build = self.basis.build_needed()
        self._set_activity("basis_before_measuring")
        self.store.append_event(job.id, "basis_loading", {
            "build": build,
            "message": ("building the reconstruction basis (first use on this install)"
                        if build else "loading the reconstruction basis")
            + " before the first reading: the adaptive rule plans later rounds with it"})
        t0 = time.monotonic()
        try:
            basis = await asyncio.to_thread(self.basis.get)
        except Exception as exc:
            log.exception("job %s: the basis could not be loaded", job.id)
            self.store.append_event(job.id, "basis_failed", {
                "message": f"{type(exc).__name__}: {exc}"[:300],
                "note": "the adaptive rounds use V&F's rule (threshold) instead"})
            return None
        finally:
            self._set_activity(None)
        self.store.append_event(job.id, "basis_ready",
                                {"seconds": round(time.monotonic() - t0, 2)})
        return basis

    def _hand_to_engine(self, job: JobRow, plan: CheckedPlan,
                        refiner: PosteriorRefiner | None) -> ScanEngine | JobState:
        """The engine that will measure ``job``, or the state to report when the job is not
        to be measured after all.

        The job was picked before the waits of its start-up (the basis); since then it may
        have been aborted, cancelled or removed, the queue held or the maintenance gate
        closed (a held or gated job stays queued), or a halt asked (a queued job stays
        queued, a resumed one is halted). All of this is decided under :attr:`changes`, and
        the engine is registered there, so from then on every request goes to the engine.
        """
        with self.changes:
            try:
                row = self.store.get_job(job.id)
            except NotFound:
                return JobState.ABORTED  # removed: there is nothing left to report on
            if row.state in FINISHED_STATES:
                return row.state
            if self._halt_asked:
                if row.state is JobState.QUEUED:
                    return row.state  # the halt holds the queue: it runs after the release
                self.store.set_state(job.id, JobState.HALTED, reason="emergency halt")
                return JobState.HALTED
            if row.state is JobState.QUEUED and (self.held is not None
                                                 or self.gate() is not None):
                return row.state
            self._engine = ScanEngine(None, self.store, job.id, plan, self.desc,
                                      refiner=refiner, connect=self.get_rig,
                                      on_arc=functools.partial(self._arc_chosen, job.id))
            return self._engine

    def _arc_chosen(self, job_id: int, test: dict[str, Any]) -> None:
        """An auto-arc job's verdict (the engine's ``on_arc``): a specimen called asymmetric,
        scanned on over a full turn, is reconstructed at finishing with the basis for such
        specimens (gonio.finishing, docs/science.md 7.4). When that basis must be built
        (minutes, the first time on an install), the build starts now, while the stage reads
        the other half turn, and the job's events say so; finishing waits only for the rest."""
        asymmetric = test.get("statistic") is not None and not test.get("symmetric", True)
        if not asymmetric or float(test.get("arc_deg", 180.0)) < 360.0:
            return
        supply = self.basis
        if not supply.asymmetric_build_needed() or not supply.prewarm_asymmetric():
            return
        self.store.append_event(job_id, "basis_prewarm", {
            "basis": "asymmetric",
            "message": "the specimen is not twofold symmetric: building the reconstruction "
                       "basis for such specimens while the other half turn is read (first "
                       "such scan on this install; later scans reuse it)"})
        log.info("job %d: building the basis for specimens without twofold symmetry while "
                 "the scan goes on", job_id)

    # ------------------------------------------------------------------ finishing
    def _finishing(self, basis: Basis | None = None) -> Finishing:
        """What :func:`gonio.finishing.finish_job` needs, from this worker's settings now;
        ``basis``, when the job already has one (loaded before measuring), instead of a new
        one from the supply."""
        return Finishing(
            store=self.store, desc=self.desc, data_dir=self.data_dir,
            basis=self.basis, basis_at_hand=basis,
            calibration=self.calibration,
            provenance=self.provenance, fit_exports=self.fit_exports,
            true_material=self.specimen_truth, on_activity=self._set_activity,
        )

    def _set_activity(self, what: str | None) -> None:
        self.activity = what
        self._activity_since = time.monotonic()

    def finishing_seconds(self) -> float | None:
        """How long the current job has been finishing (since it became ``reconstructing``
        in this process, through the basis and the reconstruction alike), seconds; None
        while no job finishes."""
        since = self._finishing_since
        return None if since is None else time.monotonic() - since

    def activity_report(self) -> tuple[str, float | None] | None:
        """What the current job waits for, in words, and the fraction done if known.

        While the basis must be built, the report counts how far the build has come
        (:meth:`gonio.basis_supply.BasisSupply.wait_report`).
        """
        what = self.activity
        if what is None:
            return None
        if what == "reconstructing":
            return ("reconstructing the BRDF from the readings", None)
        if what == "asymmetric_basis":
            return self.basis.asymmetric_wait_report(time.monotonic() - self._activity_since)
        # Before measuring, an adaptive job says why it waits for the basis.
        why = (" before the first reading (the adaptive rule needs it)"
               if what == "basis_before_measuring" else "")
        return self.basis.wait_report(why, time.monotonic() - self._activity_since)

    async def stop(self) -> None:
        self._stopping = True
        self.wake()
        if self._recon_task is not None:
            with contextlib.suppress(BaseException):
                await asyncio.shield(self._recon_task)
