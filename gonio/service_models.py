"""The service's request and response types, and the errors the API maps to a status.

Every request and response of :class:`gonio.service.GonioService` is a pydantic model here (they
become the API schema, ``gonio/api/openapi.json``). Errors are typed so the API can map them:
:class:`NotFound` -> 404, :class:`Conflict` (and :class:`gonio.jobstates.IllegalTransition`) ->
409, :class:`DeviceError` -> 503. :mod:`gonio.service` re-exports all of them: import from there.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, Field

from gonio.fields import FINITE, Count
from gonio.jobstates import JobState
from gonio.plans.models import Plan
from gonio.store import EventRow, JobRow, JobStore
from gonio.store import NotFound as StoreNotFound
from gonio.timeleft import FinishingEstimate, StartEstimate, time_left

if TYPE_CHECKING:
    from gonio.engine import Progress

__all__ = [
    "Conflict",
    "DeviceError",
    "DeviceState",
    "Event",
    "JobDetail",
    "JobInfo",
    "JobRequest",
    "NotFound",
    "ReorderRequest",
    "RigStatus",
    "RunningJob",
    "ServiceStatus",
    "StageRequest",
    "StageState",
    "job_row",
]


class NotFound(StoreNotFound):
    """No such job, or the job has no result yet (API: 404)."""


class Conflict(ValueError):
    """The request conflicts with the job's or the service's state (API: 409)."""


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
    max_angles: int | None = Field(
        default=None, description="adaptive plans: most stage angles the job can measure (the "
        "dry run's max_angles); total_angles grows round by round, so progress is done_angles "
        "of max_angles, which only rises. Null for other plans (total_angles is fixed)")
    reason: str | None
    waiting: str | None = Field(
        default=None, description="queued jobs: why no queued job starts now (the queue is "
        "held by a halt, a failed job or the maintenance lock, or a paused or suspended job "
        "holds the rig) and what lets it start; null when it starts once the rig is free "
        "(the queue_position says when). The lab page and gonio jobs list say the same")
    starts_in_s: float | None = Field(
        default=None, description="queued jobs: estimated seconds until the job starts, an "
        "estimate: the time left of the job holding the rig (its time_left_s; a calibration's "
        "eta_s) plus, for each queued job ahead, its dry run's estimated_s (an adaptive or "
        "auto-arc plan's max_estimated_s) and the reconstruction_s estimate (scans), and one "
        "basis build when one is due. Null when it is not known (starts_in_estimate says why: "
        "the queue is held or waits for a paused or suspended job, the job holding the rig or "
        "one ahead has no estimate yet) and for jobs that are not queued")
    starts_in_bound: bool = Field(
        default=False, description="true: starts_in_s counts an adaptive job (holding the "
        "rig or ahead) with every refinement round in full, an upper bound: the job may "
        "start sooner")
    starts_in_estimate: str | None = Field(
        default=None, description="queued jobs: what starts_in_s rests on, in words, or why "
        "it is not known; null for jobs that are not queued")
    start_refusal: str | None = Field(
        default=None, description="queued scans: why the worker will refuse it when it "
        "starts, as the queue stands now, and what to do: it would start under a calibration "
        "at another exposure than its own (the last calibration job to run before it, one "
        "under way, else the calibration in effect). Submission and reorder refuse what "
        "causes it; a calibration job cancelled, failed or queued at a higher priority, or a "
        "calibration file replaced, can still cause it. Null when nothing known refuses it "
        "(the worker judges again at the start) and for jobs that are not queued")

    @classmethod
    def from_row(cls, row: JobRow, max_angles: int | None = None,
                 waiting: str | None = None, *,
                 start: StartEstimate | None = None,
                 start_refusal: str | None = None) -> JobInfo:
        """One line of the job list from the stored row; ``waiting``, ``start`` (the
        service's :func:`gonio.timeleft.start_estimates`) and ``start_refusal`` (the
        service's ``start_refusals``) are kept for queued jobs only."""
        queued = row.state is JobState.QUEUED
        starts = start if queued and start is not None else None
        return cls(
            id=row.id, state=row.state, kind=row.kind, specimen=row.specimen,
            priority=row.priority, created=row.created, started=row.started,
            finished=row.finished, done_angles=row.done_angles, total_angles=row.total_angles,
            max_angles=max_angles, reason=row.reason,
            waiting=waiting if queued else None,
            starts_in_s=starts.seconds if starts is not None else None,
            starts_in_bound=starts.bound if starts is not None else False,
            starts_in_estimate=starts.source if starts is not None else None,
            start_refusal=start_refusal if queued else None,
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
    round: int | None = Field(default=None, description="adaptive plans: the round being "
                              "measured, 0 = the first angles (as the progress events' round)")
    basis_build_s: float | None = Field(
        default=None, description="active jobs whose finishing will build the default basis "
        "first (the shipped one is stale): about this many seconds more (the dry run's "
        "basis_build_s); null when the basis loads in seconds")
    reconstruction_s: float | None = Field(
        default=None, description="active jobs: estimated seconds of finishing (basis load, "
        "reconstruction, export fits, the result file), the median measured 'seconds' of the "
        "last 3 completed scans of this daemon with the rig's sensor channels, or before any "
        "7.5 s (the default scan's, measured) plus 0.1 s a sensor channel beyond three; see "
        "reconstruction_estimate")
    reconstruction_estimate: str | None = Field(
        default=None, description="what reconstruction_s rests on, in words")
    time_left_s: float | None = Field(
        default=None, description="active jobs: estimated seconds to the job's end, an "
        "estimate: eta_s + basis_build_s + reconstruction_s while measuring; while "
        "reconstructing, what is left of basis_build_s + reconstruction_s since finishing "
        "began; null once finishing runs past them (not done, and how much longer is not "
        "known)")
    queue_position: int | None = Field(description="0 = next to run; null unless queued")
    result_path: str | None
    result: dict[str, Any] | None = Field(description="summary: metrics, readings, paths")
    rig: dict[str, Any]

    @classmethod
    def from_row(cls, row: JobRow, max_angles: int | None = None,
                 waiting: str | None = None, *, queue_position: int | None = None,
                 progress: Progress | None = None,
                 activity: tuple[str, float | None] | None = None,
                 finishing: FinishingEstimate | None = None,
                 basis_build_s: float | None = None,
                 finishing_for_s: float | None = None,
                 start: StartEstimate | None = None,
                 start_refusal: str | None = None) -> JobDetail:
        """One job's status from its stored row and what is known of it live: the one
        assembly of ``GET /api/v1/jobs/{id}`` (:meth:`gonio.service.GonioService.get_job`)
        and ``gonio jobs show`` (which has no live parts when no daemon runs the store).

        Parameters
        ----------
        row : the stored job.
        max_angles, waiting : as :meth:`JobInfo.from_row` (``waiting`` is kept for queued
            jobs only).
        queue_position : the store's queue position of a queued job (None otherwise).
        progress : the engine's progress while this job measures, or None.
        activity : what the job does beyond measuring and the fraction done, or None.
        finishing : the store's finishing estimate (:func:`gonio.timeleft.finishing_estimate`);
            None leaves the time fields of an active job null.
        basis_build_s : the basis build the job's finishing waits for, seconds, or None.
        finishing_for_s : while the job reconstructs, how long it has finished so far.
        start, start_refusal : a queued job's estimated start and why its start would be
            refused (as :meth:`JobInfo.from_row`), or None.
        """
        eta = eta_max = None
        if progress is not None:
            # Counted down while measuring; frozen while paused or suspended.
            eta = progress.eta_now() if row.state is JobState.RUNNING else progress.eta_s
            if progress.eta_max_s is not None:
                eta_max = max(progress.eta_max_s - (progress.eta_s or 0.0) + (eta or 0.0),
                              eta or 0.0)
        base = JobInfo.from_row(row, max_angles, waiting, start=start,
                                start_refusal=start_refusal).model_dump()
        times: dict[str, Any] = {}
        measuring = row.state in (JobState.RUNNING, JobState.PAUSED, JobState.SUSPENDED)
        if (finishing is not None and row.kind != "calibration"
                and (measuring or row.state is JobState.RECONSTRUCTING)):
            # The whole job's time, not only the measuring's (docs/api.md "Time"). Counted
            # from the finishing's start, not from its latest activity.
            elapsed = ((finishing_for_s or 0.0) if row.state is JobState.RECONSTRUCTING
                       else None)
            times = {"basis_build_s": basis_build_s, "reconstruction_s": finishing.seconds,
                     "reconstruction_estimate": finishing.source,
                     "time_left_s": time_left(eta, basis_build_s, finishing.seconds, elapsed)}
        act, fraction = activity if activity is not None else (None, None)
        return cls(**base, plan=row.plan, eta_s=eta, eta_max_s=eta_max,
                   activity=act, activity_fraction=fraction,
                   round=progress.round if progress is not None else None, **times,
                   queue_position=queue_position if row.state is JobState.QUEUED else None,
                   result_path=row.result_path, result=row.summary, rig=row.rig)


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
    note: str | None = Field(
        default=None,
        description="what became of the command when it did not end as asked (a move or "
                    "home cut short by a stop command); None otherwise")


class DeviceError(RuntimeError):
    """A device fault while serving a manual command (the API answers 503 with the reason)."""


def job_row(store: JobStore, job_id: int) -> JobRow:
    """Job ``job_id``'s row; raises :class:`NotFound` ("no job with id ...") for an unknown job."""
    try:
        return store.get_job(job_id)
    except StoreNotFound:
        raise NotFound(f"no job with id {job_id}") from None
