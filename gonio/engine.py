"""Runs one job's measurement on a :class:`gonio.hal.Rig`: steps, checkpoints, control, faults.

Per stage angle (docs/architecture.md, "One scan, one way"): move the stage (always
approaching from below, so backlash cancels); optionally read the dark signal with every light
off; then for each light: on, settle, read all of that light's sensors in parallel
(``asyncio.gather``) while checking the lamp's output, off. The angle's readings are
committed to the store (:meth:`gonio.store.JobStore.commit_angle`) in one transaction: that is
the checkpoint. It is written by a worker thread while the stage moves to the next angle, and
it is stored before anything that follows it is stored or reported (the next checkpoint, a
dark, a state change, a fault, a round's events, the end of :meth:`ScanEngine.run`); a process
killed before it completes resumes from the angle before. The engine keeps the steps and
readings it commits (it reads them from the store once, when a job starts or resumes), and
after each round asks the plan's rounds (:mod:`gonio.plans.rounds`) for the next angles.

Time that is not physical (moves, settling, exposures) is overhead, and most of it is device
round trips on shared links, so the angle sends few of them: the stage position is read before a
move only when a backlash overshoot may be needed, and a lamp is switched on unchecked: its
output check (the switch-on check too) runs during the exposure, when the link is idle. What
needs no angle waits for none: the checkpoint (a durable commit waits for the disk) and a
dark are written beside the device work that follows them; the switching off of an angle's
last light and, when no dark is read there, the switching on of the next angle's first light
run while the stage moves (the lamps are on another link).

Control, requested from outside (the service) at any time:

* pause: at the next checkpoint, or immediately (the angle in progress is dropped and
  repeated on resume);
* resume;
* abort: stop now, clean up, state ``aborted``;
* halt: stop now and send nothing more to the devices (no cleanup), state ``halted``.

Faults: a recoverable :class:`gonio.hal.DeviceFault` (stage fault, lost device, lamp out of
band, sensor saturation in every range the sensor has: a saturated reading is first taken again
in the sensor's lower gain ranges, docs/engine.md) suspends the job; the engine waits, tries
the device's recovery (``clear_faults``, reconnect, lamp re-check), waits a settle delay and
repeats the angle.
More than ``max_retries`` consecutive failures at one angle, or an unrecoverable fault, fail
the job with the reason: the rules are the plan's (:class:`gonio.plans.faults.Suspender`), the
engine carries them out. Cleanup (lights off, stage stopped) runs on every exit but a halt.
Given ``connect`` (the worker does), the engine first connects the rig under the same rules:
a device silent at connection is waited for like one silent mid-scan, and an abort or halt
asked before, during or after the connection ends the job before any stage move.

The engine sees only :mod:`gonio.hal` (import-linter enforces it).
"""

from __future__ import annotations

import asyncio
import bisect
import contextlib
import functools
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np

from gonio import hal
from gonio.calibration import readings_array
from gonio.diskspace import disk_full_message, is_disk_full
from gonio.engine_loop import running_in
from gonio.hal import PairSpec
from gonio.jobstates import FINISHED_STATES, JobState
from gonio.motion import plan_overshoot_legs
from gonio.plans.arc import ARC_TEST_EVENT
from gonio.plans.checked import CheckedPlan, check_plan
from gonio.plans.faults import Suspender, Trouble
from gonio.plans.models import AnyPlan, PlanError
from gonio.plans.rounds import Refiner, rounds_for
from gonio.plans.route import order_for_travel
from gonio.rigdescription import RigDescription
from gonio.store import JobStore, ReadingRow, StepRow

log = logging.getLogger("gonio.engine")

_T = TypeVar("_T")

PAUSE_ASKED_EVENT = "pause_asked"
"""Event type: a pause was asked of the job (``{"immediate": bool}``); a job resumed after a
restart with one later than its last state change comes back paused."""

STAGE_REFERENCE_EVENT = "stage_reference"
"""Event type: whether the stage was homed as the job started, and where it stood
(``{"homed": bool, "position_deg": float}``); :meth:`ScanEngine._check_stage_reference`
compares later readings of the stage with it."""


class SensorSaturated(hal.DeviceFault):
    """A reading reached the sensor's saturation level (recoverable: the engine retries)."""


class JobFailed(Exception):
    """The job cannot continue; ``str(exc)`` is the reason stored with the job."""


class _Interrupted(Exception):
    """The angle in progress was interrupted by a control request (pause, abort, halt)."""


@dataclass(frozen=True)
class Progress:
    """Where a running job is: ``done`` of ``total`` stage angles and the estimated time left.

    ``eta_s`` is measured: the median time of the last few angles times the angles left, as of
    ``at`` (Unix seconds: the last checkpoint, or when the job last paused, suspended or ran
    again: the countdown stands still meanwhile). ``eta_max_s`` bounds it for adaptive plans,
    whose later rounds are not planned yet (every gap refined, :func:`adaptive_bound`).
    """

    done: int
    total: int
    eta_s: float | None
    round: int = 0
    eta_max_s: float | None = None
    at: float = 0.0
    per_angle_s: float | None = None

    def eta_now(self, now: float | None = None) -> float | None:
        """``eta_s`` counted down since the last checkpoint (never below 0)."""
        if self.eta_s is None:
            return None
        elapsed = max(0.0, (time.time() if now is None else now) - self.at) if self.at else 0.0
        return max(0.0, self.eta_s - elapsed)


class ScanEngine:
    """Measure one job's plan on a rig, checkpointing every stage angle to the store.

    Parameters
    ----------
    rig : connected :class:`gonio.hal.Rig`, or None with ``connect``
    store : JobStore
    job_id : int
        The job (queued, or active after a restart: it resumes from its last checkpoint).
    plan : the job's plan, checked on ``rig_desc`` (:func:`gonio.plans.checked.check_plan`;
        a plain plan is checked here)
    rig_desc : RigDescription of ``rig`` (limits, speeds, pairs)
    refiner : optional, the posterior rule of adaptive plans
        (:class:`gonio.plans.rounds.Refiner`, e.g. :class:`gonio.refinement.PosteriorRefiner`).
        Without it ``rule="posterior"`` plans fall back to V&F's rule (the ``adaptive_done``
        / ``adaptive_round`` events name the rule); either rule refines within the plan's
        arc. The rounds are the plan kind's (:func:`gonio.plans.rounds.rounds_for`), the
        fault rules its fault policy's (:class:`gonio.plans.faults.Suspender`).
    connect : optional, returns the connected rig (connects it if needed). The engine calls
        it first, under the plan's fault policy like any other device call: a device silent
        at connection suspends the job and is waited for (``wait_for_device_s``), and an
        abort or halt requested meanwhile ends the job before anything moves.
    on_arc : optional, called with an auto-arc job's ``arc_test`` data when its test chooses
        the arc (or, for a resumed job, when the choice is read back), before the next round
        moves: the worker starts getting the basis that verdict reconstructs with
        (:meth:`gonio.basis_supply.BasisSupply.prewarm_asymmetric`). Must not block.
    """

    def __init__(
        self,
        rig: hal.Rig | None,
        store: JobStore,
        job_id: int,
        plan: AnyPlan | CheckedPlan,
        rig_desc: RigDescription,
        refiner: Refiner | None = None,
        connect: Callable[[], Awaitable[hal.Rig]] | None = None,
        on_arc: Callable[[dict[str, Any]], None] | None = None,
    ):
        if rig is None and connect is None:
            raise ValueError("ScanEngine needs a connected rig or a way to connect one")
        self._rig = rig
        self._connect = connect
        self.refiner = refiner
        self._on_arc = on_arc
        self.store = store
        self.job_id = job_id
        self.checked = check_plan(plan, rig_desc)
        self.plan = self.checked.plan
        self.desc = rig_desc
        self.pairs: list[PairSpec] = list(self.checked.pairs)
        self.lights: list[str] = list(self.checked.lights)
        self.sensors_of: dict[str, list[str]] = {
            lt: list(names) for lt, names in self.checked.sensors_of.items()}
        self.rounds = rounds_for(self.checked, refiner)
        self.suspender = Suspender(self.plan.faults)
        self.state = JobState(store.get_job(job_id).state)
        self.from_queue = self.state is JobState.QUEUED
        """True for a job that starts here (not one resumed after a restart)."""
        self._pause = False
        self._pause_immediate = False
        self._abort = False
        self._abort_reason = "aborted by request"
        self._halt = False
        # Held while the request flags are read or set together with ``moved`` (the API's
        # threads ask, the engine's loop moves): a stop "before anything moves" is exact.
        self._control = threading.Lock()
        self.moved = False
        """True once the engine has sent its first stage move (a job that has not moved can
        still be taken back as if it had never started)."""
        self._wake = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None  # the loop run() runs on
        self._angle_task: asyncio.Task[tuple[float, list[ReadingRow]]] | None = None
        # The store write in flight: the last angle's checkpoint, written by a worker thread
        # while the stage moves on, or a dark (:meth:`_write_beside`);
        # awaited before anything else is stored or reported (:meth:`_committed`).
        self._commit: asyncio.Task[None] | None = None
        # Switching off the last light of the last angle, sent while the stage moves on.
        self._lamp_off: asyncio.Task[None] | None = None
        self._dark_once: dict[str, tuple[float, ...]] | None = None
        self._angle_times: list[float] = []
        self._per_angle_estimate = self.checked.per_angle_s
        self._max_angles = self.checked.max_angles
        self.progress = Progress(0, 0, None)
        # The job's steps and readings as the store holds them, kept here as they are
        # written (read from the store once, when the job starts or resumes).
        self._steps: list[StepRow] = []
        self._homed_at_start: bool | None = None  # from the stage_reference event
        self._readings: dict[int, list[ReadingRow]] = {}

    # ------------------------------------------------------------------ control (any time)
    # The requests may come from another thread (the API's loop, when the engine runs on its
    # own, gonio.engine_loop): flags are set at once, the wake-up and the cancellation of the
    # angle in progress go through the engine's loop.
    def request_pause(self, immediate: bool = False) -> None:
        """Pause at the next checkpoint, or now (the current angle is repeated on resume)."""
        self._pause = True
        self._pause_immediate = self._pause_immediate or immediate
        self._signal(interrupt=immediate)

    def request_resume(self) -> None:
        self._pause = False
        self._pause_immediate = False
        self._signal(interrupt=False)

    def request_abort(self, reason: str = "aborted by request") -> None:
        with self._control:
            if not self._abort:
                self._abort_reason = reason
            self._abort = True
        self._signal(interrupt=True)

    def abort_before_moving(self, reason: str) -> bool:
        """Abort with ``reason`` if the stage has not moved yet; False (and nothing asked)
        if it has. Atomic with the engine's first move (:meth:`_check_before_move`)."""
        with self._control:
            if self.moved:
                return False
            if not self._abort:
                self._abort_reason = reason
            self._abort = True
        self._signal(interrupt=True)
        return True

    @property
    def abort_requested(self) -> bool:
        return self._abort

    def request_halt(self) -> None:
        """Emergency halt: stop at once and send nothing further to any device."""
        with self._control:
            self._halt = True
        self._signal(interrupt=True)

    @property
    def rig(self) -> hal.Rig:
        """The connected rig (only once :meth:`run` has connected it)."""
        if self._rig is None:
            raise RuntimeError(f"job {self.job_id}: the rig is not connected yet")
        return self._rig

    def _signal(self, interrupt: bool) -> None:
        loop = self._loop
        if loop is not None and not running_in(loop):
            loop.call_soon_threadsafe(self._signal_here, interrupt)
        else:
            self._signal_here(interrupt)

    def _signal_here(self, interrupt: bool) -> None:
        if interrupt:
            self._interrupt()
        self._wake.set()

    def _interrupt(self) -> None:
        if self._angle_task is not None and not self._angle_task.done():
            self._angle_task.cancel()

    # ------------------------------------------------------------------ state helpers
    def _set_state(self, new: JobState, reason: str | None = None, **data: object) -> None:
        if new is self.state:
            return
        self.store.set_state(self.job_id, new, reason=reason, data=dict(data) or None)
        self._hold_countdown(self.state, new)
        self.state = new

    def _hold_countdown(self, old: JobState, new: JobState) -> None:
        """The ETA counts down while the job measures only: frozen at what it was when the job
        pauses or suspends, counted on from there when it runs again (the time it stood still
        is not measuring time: after a 30 s pause it read 0 s until the next checkpoint)."""
        p, now = self.progress, time.time()
        if p.eta_s is None:
            return
        if old is JobState.RUNNING and new in (JobState.PAUSED, JobState.SUSPENDED):
            left = p.eta_now(now)
            assert left is not None
            spent = p.eta_s - left
            self.progress = replace(p, eta_s=left, at=now, eta_max_s=None if p.eta_max_s is None
                                    else p.eta_max_s - spent)
        elif new is JobState.RUNNING and old in (JobState.PAUSED, JobState.SUSPENDED):
            self.progress = replace(p, at=now)

    def _first_progress(self) -> Progress:
        """The progress before the steps are read: the job's stored counts (a resumed job's
        angles done; a new one's plan, counted at submission) at the rig's physical time per
        angle. :meth:`_measure_all` replaces it once it has the steps."""
        row = self.store.get_job(self.job_id)
        total = max(row.total_angles, len(self.checked.angles_deg))
        done = min(row.done_angles, total)
        per = self._per_angle_estimate
        eta_max = (None if self._max_angles is None
                   else per * max(self._max_angles - done, total - done))
        return Progress(done, total, per * (total - done), 0, eta_max, time.time(), per)

    def _next_progress(self, steps: Sequence[StepRow]) -> Progress:
        """The progress once ``steps`` are committed (:attr:`progress` is set when they are)."""
        done = sum(s.done for s in steps)
        total = len(steps)
        # Measured: the median of the last angles' wall times (a retry does not skew it). The
        # first angle of this run is left out: it includes the travel from where the stage was
        # (after the white reference, the start of a page scan: 2.4 s against 0.8 s per angle,
        # and with it alone the ETA read 13 s where 5 s were left). Until a second angle is
        # done, the rig's physical estimate.
        recent = self._angle_times[1:][-8:]
        per = float(np.median(recent)) if recent else self._per_angle_estimate
        rnd = max((s.round for s in steps), default=0)
        eta_max = None
        if self._max_angles is not None:
            eta_max = per * max(self._max_angles - done, total - done)
        return Progress(done, total, per * (total - done), rnd, eta_max, time.time(), per)

    # ------------------------------------------------------------------ main loop
    async def run(self) -> JobState:
        """Measure until every planned angle is committed or the job ends.

        Returns
        -------
        JobState
            ``RUNNING`` when all angles are measured (the caller reconstructs next), otherwise
            the terminal state reached (``FAILED``, ``ABORTED``, ``HALTED``).
        """
        self._loop = asyncio.get_running_loop()
        if self.state in FINISHED_STATES:
            return self.state  # ended before it started: nothing to measure, nothing to touch
        # An ETA from the moment the job is running, before the rig is connected and the stage
        # read (its steps are read then): set before the state, so no one reads "running"
        # without it.
        self.progress = self._first_progress()
        if self.state is JobState.QUEUED:
            self._set_state(JobState.RUNNING)
        elif self.state is JobState.PAUSED:
            self._pause = True  # restored after a restart: wait for an explicit resume
        elif self._pause_pending():
            # A pause asked and answered before the daemon stopped, its checkpoint not yet
            # reached: the job comes back paused, not measuring.
            self._pause = True
            self._set_state(JobState.PAUSED, note="paused as asked before the restart")
        elif self.state is JobState.SUSPENDED:
            self._set_state(JobState.RUNNING, note="resumed after restart")
        try:
            await self._connect_rig()
            await self._measure_all()
            await self._committed()
        except _Halt:
            await self._drop_lamp_off()  # an emergency halt sends nothing more
            self._set_state(JobState.HALTED, reason="emergency halt")
            return self.state
        except _Abort:
            await self._cleanup()
            self._set_state(JobState.ABORTED, reason=self._abort_reason)
            return self.state
        except JobFailed as exc:
            await self._cleanup()
            self._set_state(JobState.FAILED, reason=str(exc))
            return self.state
        except asyncio.CancelledError:
            # The worker itself is being cancelled (daemon shutdown): leave the rig safe and the
            # job active, so startup reconciliation resumes it from its checkpoint.
            await asyncio.shield(self._cleanup())
            raise
        except BaseException as exc:
            await self._cleanup()
            reason = (disk_full_message(f"job {self.job_id}'s readings (the job store)",
                                        self.store.path) if is_disk_full(exc)
                      else f"internal error: {exc!r}")
            self._set_state(JobState.FAILED, reason=reason)
            raise
        await self._cleanup()
        return self.state

    def _pause_pending(self) -> bool:
        """A resumed running or suspended job whose last ``pause_asked`` event comes after
        its last state change: the pause was asked, answered, and not yet reached."""
        if self.state not in (JobState.RUNNING, JobState.SUSPENDED):
            return False
        asked = self.store.last_event(self.job_id, PAUSE_ASKED_EVENT)
        if asked is None:
            return False
        job = self.store.get_job(self.job_id)
        if (self.plan.kind != "adaptive" and self.plan.arc_mode() != "auto"
                and job.total_angles and job.done_angles >= job.total_angles):
            return False  # nothing left to measure: it goes on to finish, as said
        changed = self.store.last_event(self.job_id, "state")
        return changed is None or asked.seq > changed.seq

    async def _connect_rig(self) -> None:
        """Connect the rig (when the engine was given ``connect``), with the same fault
        handling as an angle: a silent device suspends the job and is waited for; a pending
        abort or halt is acted on before the first attempt and after every one."""
        if self._connect is None:
            return
        retries = 0
        trouble: Trouble | None = None
        while True:
            await self._gate()
            try:
                await self._connect_once()
                return
            except hal.DeviceFault as fault:
                retries += 1
                if trouble is None:
                    trouble = self.suspender.trouble(fault)
                await self._suspend(fault, retries, trouble, recover=self._connect_once)

    async def _connect_once(self) -> None:
        assert self._connect is not None
        try:
            self._rig = await self._connect()
        except OSError as exc:  # no such port, no route: waiting will not help
            raise JobFailed(f"rig not available: {exc}") from None

    async def _measure_all(self) -> None:
        # The store is read once (a resumed job has steps and readings); from here on the
        # engine keeps both as it writes them.
        self._steps = self.store.steps(self.job_id)
        self._readings = {}
        for r in self.store.readings(self.job_id) if self._steps else ():
            self._readings.setdefault(r.angle_index, []).append(r)
        if not self._steps:
            await self._note_stage_reference()
            here = await self._stage_position()
            route = order_for_travel(self.checked.angles_deg, here, self.desc,
                                     self.plan.backlash_deg)
            self._add_steps(0, 0, route)
        else:
            # Resumed (after a restart of the daemon, perhaps of the rig): the stage's zero
            # must be the one the job started with.
            self._check_stage_reference(await self._stage_read(self.rig.stage.status))
        if self._steps and self.plan.arc_mode() == "auto":
            # A resumed auto-arc job continues on the arc it chose (its arc_test event).
            chosen = self.store.last_event(self.job_id, ARC_TEST_EVENT)
            if chosen is not None:
                self.rounds = rounds_for(self.checked, self.refiner, chosen.data)
                self._arc_chosen(chosen.data)
        self._load_dark()
        # An ETA from the first move on (the rig's physical time per angle, as after the first
        # angle), not none until the first checkpoint: the page showed no time for a whole
        # angle, and a job paused before it none at all.
        self.progress = self._next_progress(self._steps)
        todo = [s.angle_index for s in self._steps if not s.done]
        while True:
            if not todo:
                k0 = len(self._steps)
                if not await self._plan_next_round(self._steps):
                    return
                todo = [s.angle_index for s in self._steps[k0:]]
                continue
            await self._measure_with_retries(self._step_at(todo.pop(0)), self._steps)

    def _add_steps(self, k0: int, rnd: int, route: Sequence[float]) -> None:
        """Plan stage positions ``route`` as steps ``k0, k0 + 1, ...`` of round ``rnd``, in
        the store and here. Stored before the first of them is moved to: its ``planned``
        event is the last word before the stage moves (an abort or halt asked from then on
        still lands before the move, :meth:`_check_before_move`)."""
        rows = [(k0 + j, rnd, p % 360.0, p) for j, p in enumerate(route)]
        self.store.add_steps(self.job_id, rows)
        self._steps.extend(StepRow(k, r, a, p, False, None) for k, r, a, p in rows)

    def _step_at(self, angle_index: int) -> StepRow:
        return self._steps[self._where(angle_index)]

    def _where(self, angle_index: int) -> int:
        """Position of step ``angle_index`` in :attr:`_steps` (sorted by angle index)."""
        i = bisect.bisect_left(self._steps, angle_index, key=lambda s: s.angle_index)
        if i == len(self._steps) or self._steps[i].angle_index != angle_index:
            raise KeyError(angle_index)
        return i

    async def _stage_position(self) -> float:
        """The stage position for planning a route, with the same fault handling as an angle."""
        return await self._stage_read(self.rig.stage.position)

    async def _stage_read(self, read: Callable[[], Awaitable[_T]]) -> _T:
        """``read()`` of the stage, with the same fault handling as an angle."""
        retries = 0
        trouble: Trouble | None = None
        while True:
            await self._gate()
            try:
                return await read()
            except hal.DeviceFault as fault:
                retries += 1
                if trouble is None:
                    trouble = self.suspender.trouble(fault)
                await self._suspend(fault, retries, trouble)

    # ------------------------------------------------------------------ the stage's zero
    async def _note_stage_reference(self) -> None:
        """Record, as the job starts, whether the stage was homed (a ``stage_reference``
        event), so that a later loss of its zero can be told from a zero never set."""
        st = await self._stage_read(self.rig.stage.status)
        self._homed_at_start = st.homed
        self.store.append_event(self.job_id, STAGE_REFERENCE_EVENT, {
            "homed": st.homed, "position_deg": st.position_deg})

    def _check_stage_reference(self, st: hal.StageStatus) -> None:
        """Fail the job when the stage, homed as the job started, reads not homed on a stage
        whose zero a power cycle moves (:class:`gonio.hal.StageStatus`).

        A geared servo powered off under a paused or suspended job (or with the daemon)
        came back with whole motor turns forgotten, and the job went on reading at stage
        angles off by ``360 / gear`` degrees, labelled as the planned ones: nothing said so.
        The angles measured before stay in the store; the stage must be homed again (at the
        lab's own reference mark), which only the lab can do, so the job cannot go on.
        """
        if self._homed_at_start is None:
            ref = self.store.last_event(self.job_id, STAGE_REFERENCE_EVENT)
            self._homed_at_start = bool(ref.data.get("homed")) if ref is not None else False
        if not self._homed_at_start or st.homed or not st.zero_lost_at_power_up:
            return
        from gonio.wording import counted

        # From the store: on a resume the steps are not read yet while the rig connects.
        done = self.store.get_job(self.job_id).done_angles
        raise JobFailed(
            "the stage lost its zero during the job: it was homed when the job started and "
            "now reads not homed, so it was powered off or reset, and this stage's positions "
            "after a power-up may be off by whole motor turns (a geared servo). The readings "
            f"of the {counted(done, 'angle')} measured before stay in the job store, at the "
            "angles they were measured at. Move the stage to the specimen's reference mark "
            "and set its zero there (the lab page's Stage panel, or 'gonio stage --daemon URL "
            "move DEG', then 'home'; '--rig rig.toml' without a daemon), then scan again")

    def _load_dark(self) -> None:
        if self.plan.exposure.dark == "once":
            stored = self.store.darks(self.job_id)
            if stored:
                self._dark_once = stored[min(stored)]

    async def _measure_with_retries(self, step: StepRow, steps: Sequence[StepRow]) -> None:
        retries = 0
        trouble: Trouble | None = None  # the first fault at this angle, and when it came
        while True:
            await self._gate()
            t0 = time.monotonic()
            self._angle_task = asyncio.create_task(self._measure_angle(step))
            try:
                try:
                    actual, readings = await self._angle_task_result()
                except BaseException:
                    # The previous angle's checkpoint is stored before anything else is
                    # (a state change, a fault event) and before the job ends.
                    await self._committed()
                    raise
            except _Interrupted:
                continue  # the gate handles the request; the angle is repeated
            except hal.DeviceFault as fault:
                retries += 1
                if trouble is None:
                    trouble = self.suspender.trouble(fault)
                await self._suspend(fault, retries, trouble)
                continue
            self._angle_times.append(time.monotonic() - t0)
            done = replace(step, done=True, actual_deg=actual)
            p = self._next_progress(
                [s if s.angle_index != step.angle_index else done for s in steps]
            )
            await self._committed()  # the previous angle's (long done: a move ran since)
            # The checkpoint is written by a worker thread while the stage moves to the next
            # angle: a durable commit waits for the disk (several ms), the move for the
            # stage. It is awaited before anything else is stored, reported or measured
            # after the move (see _committed); a process killed before it completes resumes
            # from the angle before and measures this one again.
            self._commit = asyncio.create_task(self._commit_angle(step, actual, readings, p))
            # The engine's copy: what the store holds once that commit is done.
            self._steps[self._where(step.angle_index)] = done
            self._readings[step.angle_index] = readings
            return

    async def _commit_angle(self, step: StepRow, actual: float, readings: list[ReadingRow],
                            p: Progress) -> None:
        """Store one angle's checkpoint (readings, step done, progress event) off the loop.

        The engine's progress (what the service's status reports) moves first: the store
        publishes the progress event as the commit ends, and a client told "2 angles done"
        that then asks for the status must not read 1. A commit that fails puts it back.
        """
        before, self.progress = self.progress, p
        try:
            await asyncio.to_thread(
                self.store.commit_angle, self.job_id, step.angle_index, actual, readings,
                {"specimen_deg": step.specimen_deg, "position_deg": step.position_deg,
                 "eta_s": p.eta_s, "round": p.round},
            )
        except BaseException:
            self.progress = before
            raise

    def _write_beside(self, write: Callable[[], None]) -> None:
        """Start ``write`` (a dark) in a worker thread, as a checkpoint is.

        A durable write waits for the disk (several ms); what follows it needs the devices
        (the exposures), not the write. Called with nothing in flight (after
        :meth:`_committed`), so the store is written in the engine's order; awaited like a
        checkpoint before anything else is stored, reported or ended. A process killed before
        it completes has stored no checkpoint that needs it: the angle is measured again on
        resume.
        """
        assert self._commit is None, "a store write is still in flight"
        self._commit = asyncio.create_task(asyncio.to_thread(write))

    async def _committed(self) -> None:
        """Wait for the store write in flight (the last angle's checkpoint or a dark) to be
        stored; raises what the write raised (a full disk), once. Shielded: a cancelled
        engine still waits for a write under way when it cleans up."""
        task = self._commit
        if task is None:
            return
        try:
            await asyncio.shield(task)
        finally:
            if task.done():
                self._commit = None

    async def _angle_task_result(self) -> tuple[float, list[ReadingRow]]:
        assert self._angle_task is not None
        try:
            await asyncio.wait({self._angle_task})
        finally:
            if not self._angle_task.done():  # the engine itself was cancelled
                self._angle_task.cancel()
                with contextlib.suppress(BaseException):
                    await self._angle_task
        if self._angle_task.cancelled():
            raise _Interrupted()
        exc = self._angle_task.exception()
        if exc is not None:
            raise exc
        return self._angle_task.result()

    # ------------------------------------------------------------------ control at checkpoints
    async def _gate(self) -> None:
        """Act on pending requests; return when the engine may measure the next angle."""
        if self._halt or self._abort or self._pause or self.state is not JobState.RUNNING:
            await self._committed()  # a checkpoint is stored before the state that follows it
        while True:
            if self._halt:
                raise _Halt()
            if self._abort:
                raise _Abort()
            if not self._pause:
                if self.state is not JobState.RUNNING:
                    self._set_state(JobState.RUNNING)
                return
            if self.state is not JobState.PAUSED:
                await self._cleanup()
                self._set_state(
                    JobState.PAUSED, immediate=self._pause_immediate, done=self.progress.done
                )
            self._wake.clear()
            if self._pause and not (self._abort or self._halt):
                await self._wake.wait()

    async def _sleep(self, seconds: float) -> None:
        """Sleep, waking early for a control request (which the caller's gate then handles)."""
        self._wake.clear()
        if self._halt or self._abort or self._pause:
            return
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wake.wait(), timeout=seconds)

    # ------------------------------------------------------------------ one angle
    def _check_before_move(self) -> None:
        """Right before a stage move: act on a halt or abort asked since the last gate (the
        request may come from another thread at any time), else note that the stage moves."""
        with self._control:
            if self._halt:
                raise _Halt()
            if self._abort:
                raise _Abort()
            self.moved = True

    async def _measure_angle(self, step: StepRow) -> tuple[float, list[ReadingRow]]:
        stage = self.rig.stage
        self._check_before_move()
        target = step.position_deg
        if self.plan.backlash_deg > 0:
            # Coming from above: overshoot below so the final approach is positive again.
            here = await stage.position()
            for leg in plan_overshoot_legs(here, target, self.plan.backlash_deg,
                                           self.desc.stage_min_deg)[:-1]:
                await stage.move_to(leg)
        mode = self.plan.exposure.dark
        dark_due = mode == "every_angle" or (mode == "once" and self._dark_once is None)
        # Without a dark to read here, the first light is switched on while the stage moves.
        first = None if dark_due or not self.lights else self.rig.lights[self.lights[0]]
        actual, lit_at = await self._move_and_switch(target, first)
        dark: dict[str, tuple[float, ...]] = {}
        if dark_due:
            dark = await self._read_dark()
            await self._committed()  # the store is written in checkpoint order
            # Stored while the lamps and sensors work, before this angle's checkpoint.
            self._write_beside(functools.partial(self.store.add_darks, self.job_id,
                                                 step.angle_index, dark))
            if mode == "once":
                self._dark_once = dark
        elif mode == "once" and self._dark_once is not None:
            dark = self._dark_once
        ex = self.plan.exposure
        out: list[ReadingRow] = []
        for k, lname in enumerate(self.lights):
            light = self.rig.lights[lname]
            sensors = self.sensors_of[lname]
            last = k == len(self.lights) - 1
            measured = False
            # The output check is left to the exposure (``_read_sensors``): one round trip
            # fewer between switching on and triggering the sensors.
            if k > 0 or lit_at is None:
                await light.switch_on(check=False)
                lit_at = time.monotonic()
            try:
                # The light settles from its switch-on (the first one's during the move).
                settle = ex.light_settle_s - (time.monotonic() - lit_at)
                if settle > 0:
                    await asyncio.sleep(settle)
                results = await self._read_sensors(sensors, lamp=lname)
                # Auto-ranging while the lamp is still on: a saturated reading is taken again
                # in its sensor's next lower range, until one does not saturate.
                results = await self._range_down(sensors, results)
                measured = True
            finally:
                if last and measured:
                    # The angle's last light goes off while the angle is committed and the
                    # stage moves on: the next light is switched on only after it.
                    self._lamp_off = asyncio.create_task(_quietly(light.set_on(False)))
                else:
                    await _quietly(light.set_on(False))
            for sname, rd in zip(sensors, results, strict=True):
                if rd.saturated and self.plan.faults.saturation == "suspend":
                    raise SensorSaturated(sname, self._saturation_message(sname, lname),
                                          code="saturated")
                nch = len(rd.values)
                out.append(ReadingRow(
                    angle_index=step.angle_index,
                    commanded_deg=target,
                    actual_deg=actual,
                    light=lname,
                    sensor=sname,
                    raw=tuple(float(v) for v in rd.values),
                    dark=dark.get(sname, (0.0,) * nch),
                    exposure_s=rd.exposure_s,
                    averages=rd.averages,
                    saturated=rd.saturated,
                    t_read=rd.timestamp,
                    range_index=rd.range_index,
                    range_scale=rd.range_scale,
                ))
        # A reading taken in a lower range has its dark signal read in that range too (the
        # range's offset would otherwise be divided by its small scale), with every lamp off.
        ranged = sorted({(r.sensor, r.range_index) for r in out if r.range_index > 0})
        if ranged:
            await self._lamp_off_done()  # every lamp off
            darks = await self._read_range_darks(ranged)
            out = [replace(r, dark=darks[(r.sensor, r.range_index)]) if r.range_index else r
                   for r in out]
        return actual, out

    async def _move_and_switch(self, target: float, first: hal.Light | None
                               ) -> tuple[float, float | None]:
        """Move the stage to ``target`` while the lamps (another link) switch the previous
        angle's last light off and then, given ``first``, the next one on.

        Returns the position reached and when ``first`` was on (monotonic seconds; None
        without it). A fault of either is raised once both have ended (the lamps are
        switched off by the fault handling, as after any fault).
        """
        async def lamps() -> float | None:
            await self._lamp_off_done()
            if first is None:
                return None
            await first.switch_on(check=False)
            return time.monotonic()

        moved, lit = await asyncio.gather(self.rig.stage.move_to(target), lamps(),
                                          return_exceptions=True)
        errors = [r for r in (moved, lit) if isinstance(r, BaseException)]
        if errors:
            raise _primary(errors)
        assert isinstance(moved, float) and not isinstance(lit, BaseException)
        return moved, lit

    async def _lamp_off_done(self) -> None:
        """Wait until the previous angle's last light is off (it was switched off quietly:
        a lamp that did not answer is dealt with by the next request to it)."""
        task, self._lamp_off = self._lamp_off, None
        if task is not None:
            await task

    async def _drop_lamp_off(self) -> None:
        """Cancel a lamp switch-off not yet sent (an emergency halt sends nothing more)."""
        task, self._lamp_off = self._lamp_off, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task

    def _saturation_message(self, sensor: str, light: str) -> str:
        """Why a reading that saturated in every range the sensor has fails, and what to do."""
        ranges = self.rig.sensors[sensor].ranges
        ex = self.plan.exposure
        if len(ranges) > 1:
            where = (f"in every one of its {len(ranges)} ranges (down to {ranges[-1]:g} of the "
                     "nominal gain)")
            todo = "lower the exposure or the lamp level"
        else:
            where = "in its only range"
            todo = ("lower the exposure or the lamp level, or give the sensor lower gain stages "
                    "(gain_stages in the rig config)")
        return (f"saturated {where} with light {light!r} at {ex.exposure_s:g} s exposure; "
                f"{todo} if this persists")

    async def _range_down(self, names: Sequence[str], readings: Sequence[hal.SensorReading]
                          ) -> list[hal.SensorReading]:
        """Each saturated reading taken again in its sensor's next lower range until it no
        longer saturates or the sensor has no lower range (sensors in parallel)."""
        ex = self.plan.exposure

        async def settle(name: str, rd: hal.SensorReading) -> hal.SensorReading:
            sensor = self.rig.sensors[name]
            while rd.saturated and rd.range_index + 1 < len(sensor.ranges):
                rd = await sensor.read_in_range(ex.exposure_s, ex.averages, rd.range_index + 1)
            return rd

        if not any(r.saturated for r in readings):
            return list(readings)
        results = await asyncio.gather(
            *(settle(n, r) for n, r in zip(names, readings, strict=True)),
            return_exceptions=True)
        errors = [r for r in results if isinstance(r, BaseException)]
        if errors:
            raise _primary(errors)
        return [r for r in results if isinstance(r, hal.SensorReading)]

    async def _read_range_darks(self, wanted: Sequence[tuple[str, int]]
                                ) -> dict[tuple[str, int], tuple[float, ...]]:
        """Dark readings of (sensor, range) pairs with the lamps off (sensors in parallel)."""
        ex = self.plan.exposure
        by_sensor: dict[str, list[int]] = {}
        for name, k in wanted:
            by_sensor.setdefault(name, []).append(k)

        async def one(name: str, ks: Sequence[int]) -> dict[tuple[str, int], tuple[float, ...]]:
            got = {}
            for k in ks:
                rd = await self.rig.sensors[name].read_in_range(ex.exposure_s, ex.averages, k)
                got[(name, k)] = tuple(float(v) for v in rd.values)
            return got

        results = await asyncio.gather(*(one(n, ks) for n, ks in by_sensor.items()),
                                       return_exceptions=True)
        errors = [r for r in results if isinstance(r, BaseException)]
        if errors:
            raise _primary(errors)
        merged: dict[tuple[str, int], tuple[float, ...]] = {}
        for r in results:
            assert isinstance(r, dict)
            merged.update(r)
        return merged

    async def _read_sensors(
        self, names: Sequence[str], lamp: str | None = None
    ) -> list[hal.SensorReading]:
        """Read sensors in parallel; wait for all, then raise the first fault (no orphan reads).

        With ``lamp``, that light's output is checked (:meth:`gonio.hal.Light.check_output`)
        while its sensors integrate: devices on a shared link are idle during the exposure, so
        the check adds no time, and the output that matters is the one during the exposure. It
        is also the switch-on check (the engine switches lights on with ``check=False``), so a
        lamp out of band at switch-on fails here with the driver's switch-on message. The check
        is started after the reads, so it queues behind their triggers. A lamp out of band wins
        over sensor faults: its readings are discarded and the angle repeated after recovery.
        """
        ex = self.plan.exposure
        calls: list[Awaitable[object]] = [
            self.rig.sensors[n].read(ex.exposure_s, ex.averages) for n in names
        ]
        if lamp is not None:
            calls.append(self.rig.lights[lamp].check_output())
        results = await asyncio.gather(*calls, return_exceptions=True)
        if lamp is not None:
            st = results.pop()
            if isinstance(st, BaseException):
                raise _primary([st, *(r for r in results if isinstance(r, BaseException))])
        errors = [r for r in results if isinstance(r, BaseException)]
        if errors:
            raise _primary(errors)
        readings: list[hal.SensorReading] = []
        for r in results:
            assert isinstance(r, hal.SensorReading)
            readings.append(r)
        return readings

    async def _read_dark(self) -> dict[str, tuple[float, ...]]:
        names = sorted({p.sensor for p in self.pairs})
        readings = await self._read_sensors(names)
        return {n: tuple(float(v) for v in r.values) for n, r in zip(names, readings, strict=True)}

    # ------------------------------------------------------------------ faults
    async def _suspend(self, fault: hal.DeviceFault, retries: int, trouble: Trouble,
                       recover: Callable[[], Awaitable[None]] | None = None) -> None:
        """Suspend on ``fault``, recover, and return when the angle may be retried.

        ``recover`` replaces the recovery that matches the fault (:meth:`_recover`): while
        the rig is being connected, the recovery is connecting it. ``retries`` counts the
        consecutive failures at this angle; ``trouble`` is the first of them (reported with
        the last one when they differ, so a reason never loses the cause that started it).
        Whether the job waits or fails is the plan's fault policy
        (:class:`gonio.plans.faults.Suspender`).
        """
        await self._committed()
        rules = self.suspender
        refused = rules.refusal(fault, retries, trouble)
        if refused is not None:
            raise JobFailed(refused)
        self._set_state(
            JobState.SUSPENDED, reason=str(fault), device=fault.device, code=fault.code,
            retry=retries,
        )
        await self._lights_off()
        announced = False
        while True:
            await self._sleep(rules.policy.retry_delay_s)
            await self._gate_in_suspension()
            try:
                await (self._recover(fault) if recover is None else recover())
                # A device back after an outage may have been powered off: the stage's
                # zero must still be the job's (a JobFailed ends the job from here).
                if self._rig is not None:
                    self._check_stage_reference(await self.rig.stage.status())
                break
            except hal.DeviceFault as again:
                retries += 1
                then = rules.after_failed_recovery(again, fault, retries, trouble, announced)
                if then.failure is not None:
                    raise JobFailed(then.failure) from None
                if then.event is not None:
                    self.store.append_event(self.job_id, "fault", then.event)
                announced = then.announced
                fault = again
        await self._sleep(rules.policy.resume_settle_s)
        self.store.append_event(self.job_id, "recovered", {
            "device": fault.device, "code": fault.code})

    async def _gate_in_suspension(self) -> None:
        if self._halt:
            raise _Halt()
        if self._abort:
            raise _Abort()
        if self._pause:
            await self._gate()  # suspended -> paused; returns after resume (-> running)
            self._set_state(JobState.SUSPENDED, reason="recovering after resume")

    async def _recover(self, fault: hal.DeviceFault) -> None:
        """Try the recovery that matches ``fault``; raise a DeviceFault if it did not clear."""
        rig = self.rig
        if isinstance(fault, SensorSaturated):
            return  # transient glare or a lamp flash: simply measure again
        if isinstance(fault, hal.LampOutOfBand) and fault.device in rig.lights:
            light = rig.lights[fault.device]
            await light.set_on(True)
            try:
                await asyncio.sleep(self.plan.exposure.light_settle_s)
                st = await light.status()
            finally:
                await _quietly(light.set_on(False))
            if not st.in_band:
                raise hal.LampOutOfBand(fault.device, "output still outside its band",
                                        code="out_of_band")
            return
        if isinstance(fault, hal.DeviceUnavailable):
            dev = _device_named(rig, fault.device)
            if dev is not None:
                await _quietly(dev.close())
                await dev.connect()
            if dev is rig.stage or dev is None:
                await rig.stage.clear_faults()
            return
        # Stage faults, and unknown faults from the stage: clear and confirm.
        await rig.stage.clear_faults()
        stage_st = await rig.stage.status()
        if stage_st.faults:
            raise hal.StageFault(fault.device, f"faults persist: {', '.join(stage_st.faults)}",
                                 code=stage_st.faults[0])

    # ------------------------------------------------------------------ adaptive rounds
    async def _plan_next_round(self, steps: Sequence[StepRow]) -> bool:
        """Plan the next round as the plan's rounds say (:mod:`gonio.plans.rounds`); False
        when the job is measured."""
        await self._committed()  # the round's last checkpoint, before its events
        rnd = max(s.round for s in steps)
        angles, values = self.measured_values(steps)
        nxt = await self.rounds.next_round(angles, values, len(steps), rnd)
        for type_, data in nxt.events:
            self.store.append_event(self.job_id, type_, data)
            if type_ == ARC_TEST_EVENT:
                self._arc_chosen(data)
        if not nxt.angles_deg:
            return False
        here = await self._stage_position()
        try:
            route = order_for_travel(nxt.angles_deg, here, self.desc, self.plan.backlash_deg)
        except PlanError as exc:
            # Submission checks the rounds it can foresee; a round the travel cannot reach
            # (a rig config edited since) is the lab's to fix, not an internal error.
            raise JobFailed(f"round {rnd + 1} cannot be measured: {exc}") from None
        self._add_steps(max(s.angle_index for s in steps) + 1, rnd + 1, route)
        return True

    def _arc_chosen(self, test: dict[str, Any]) -> None:
        """Tell ``on_arc`` the verdict; its failure costs the scan nothing (finishing gets
        the basis itself), so it is logged, not raised."""
        if self._on_arc is None:
            return
        try:
            self._on_arc(test)
        except Exception:
            log.exception("job %d: acting on the arc test's verdict failed", self.job_id)

    def measured_values(self, steps: Sequence[StepRow]) -> tuple[list[float], np.ndarray]:
        """Specimen angles (deg) and dark-subtracted values (n_pairs, r, C) of done steps,
        from the readings the engine holds (no store read)."""
        done = [s for s in steps if s.done]
        rows = [r for s in done for r in self._readings.get(s.angle_index, ())]
        nch = max((len(r.raw) for r in rows), default=1)
        vals = readings_array(rows, self.pairs, [s.angle_index for s in done], nch)
        return [s.specimen_deg for s in done], vals

    # ------------------------------------------------------------------ cleanup
    async def _lights_off(self) -> None:
        await self._lamp_off_done()
        if self._rig is None:
            return  # never connected: no light was switched on
        for light in self._rig.lights.values():
            await _quietly(light.set_on(False))

    async def _cleanup(self) -> None:
        """Lights off and stage stopped; best effort, every step tried even if one fails."""
        with contextlib.suppress(Exception):
            # Normally stored already; under way only when the engine itself is cancelled.
            # A commit that failed has failed the job already (or resumes it on restart).
            await self._committed()
        await self._lights_off()
        if self._rig is not None:
            await _quietly(self._rig.stage.stop())


def _primary(errors: Sequence[BaseException]) -> BaseException:
    """The error to report when several calls failed together.

    Anything but a device fault (a bug, a cancellation) first; then a fault that is a cause
    rather than a consequence of another device's fault (``secondary``); then the first.
    """
    for e in errors:
        if not isinstance(e, hal.DeviceFault):
            return e
    for e in errors:
        if not getattr(e, "secondary", False):
            return e
    return errors[0]


class _Halt(Exception):
    pass


class _Abort(Exception):
    pass


async def _quietly(aw: Awaitable[object]) -> None:
    """Await a device call during cleanup, ignoring device faults (the rest must still run)."""
    with contextlib.suppress(hal.DeviceFault, OSError, TimeoutError, ValueError):
        await aw


def _device_named(rig: hal.Rig, name: str) -> hal.Device | None:
    for d in rig.devices():
        if getattr(d, "name", None) == name:
            return d
    return None
