"""Job routes: create (validated plan), list, one job's full status, control, queue order."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Query, Response, status
from pydantic import BaseModel, Field

from gonio.api.deps import COMPUTE, READ, WRITE, JobId, Service
from gonio.calibration import counts
from gonio.fields import FINITE
from gonio.jobstates import JobState
from gonio.plans.dryrun import DryRun
from gonio.plans.models import Plan
from gonio.service import Conflict, JobDetail, JobInfo, JobRequest, ReorderRequest

router = APIRouter(prefix="/api/v1/jobs", tags=["jobs"])


class DryRunRequest(BaseModel):
    """A plan to check and time without queueing it."""

    # As a job request: a misspelt key is refused, not checked as if it were absent.
    model_config = FINITE

    plan: Plan
    priority: int = Field(
        default=0, ge=-1000, le=1000,
        description="the priority the scan would be queued at (as POST /api/v1/jobs's): it "
        "decides whether a queued calibration job runs before it")


class Reading(BaseModel):
    """One stored reading of a job, dark-subtracted, for live plots."""

    angle_index: int
    specimen_deg: float = Field(description="specimen rotation, degrees in [0, 360)")
    actual_deg: float = Field(description="stage position the encoder reported, degrees")
    light: str
    sensor: str
    values: list[float] = Field(
        description="(raw - dark) / range_scale per channel: sensor units of the nominal range")
    saturated: bool
    t_read: float = Field(description="Unix time, seconds")
    range_index: int = Field(
        default=0, description="sensor range it was taken in (0: nominal gain; auto-ranging)")


@router.get("", dependencies=READ, summary="List jobs (oldest first)")
def list_jobs(service: Service, state: JobState | None = None) -> list[JobInfo]:
    return service.list_jobs(state.value if state is not None else None)


@router.post(
    "",
    dependencies=WRITE,
    status_code=status.HTTP_201_CREATED,
    summary="Queue a scan (the plan is validated against the rig first)",
    responses={
        422: {"description": "the plan cannot run on this rig; the detail says why"},
        409: {"description": "the scan would be uncalibrated on a rig that has a calibration "
                           "elsewhere; send accept_uncalibrated=true to run it all the same"},
    },
)
def create_job(
    request: JobRequest,
    service: Service,
    response: Response,
    accept_uncalibrated: bool = Query(
        False, description="run a scan that no calibration covers on a rig that was calibrated "
        "(otherwise 409: most likely the daemon runs on another data directory)"),
) -> JobInfo:
    if not accept_uncalibrated:
        refusal = service.uncalibrated_refusal(request.plan, request.priority)
        if refusal is not None:
            raise Conflict(refusal)
    info = service.submit(request, accept_uncalibrated=accept_uncalibrated)
    response.headers["Location"] = f"/api/v1/jobs/{info.id}"
    return info


@router.post(
    "/dry-run",
    dependencies=COMPUTE,
    summary="Check and time a plan without queueing it",
    responses={422: {"description": "the plan cannot run on this rig"}},
)
def dry_run(request: DryRunRequest, service: Service) -> DryRun:
    result = service.dry_run(request.plan)
    if request.plan.kind != "calibration":
        # The calibration's refusals and warnings, judged as submission at this priority
        # judges them (GonioService.calibration_warnings: one decision).
        more = service.calibration_warnings(result.pairs, request.plan.exposure.exposure_s,
                                            request.priority)
        if more:
            result = result.model_copy(update={"warnings": [*result.warnings, *more]})
    return result


@router.get(
    "/{job_id}",
    dependencies=READ,
    summary="Everything about one job: state, progress, ETA, plan, reason, result summary",
    responses={404: {"description": "no such job"}},
)
async def get_job(job_id: JobId, service: Service) -> JobDetail:
    # The hot path of every polling client: one primary-key read on this thread's own store
    # connection (never blocked by the writer), so it runs on the event loop instead of paying
    # a thread-pool hop per request.
    return service.get_job(job_id)


@router.get(
    "/{job_id}/readings",
    dependencies=READ,
    summary="The readings stored so far (one per stage angle, light and sensor)",
    responses={404: {"description": "no such job"}},
)
def readings(
    job_id: JobId,
    service: Service,
    after_angle: int = Query(-1, ge=-1, description="only angles with a larger index"),
) -> list[Reading]:
    return [
        Reading(
            angle_index=r.angle_index,
            specimen_deg=r.commanded_deg % 360.0,
            actual_deg=r.actual_deg,
            light=r.light,
            sensor=r.sensor,
            values=counts(r).tolist(),
            saturated=r.saturated,
            t_read=r.t_read,
            range_index=r.range_index,
        )
        for r in service.readings(job_id, after_angle)
    ]


_CONFLICT: dict[int | str, dict[str, Any]] = {
    404: {"description": "no such job"},
    409: {"description": "not allowed in the job's state"},
}


@router.post("/{job_id}/pause", dependencies=WRITE, responses=_CONFLICT,
             summary="Pause at the next checkpoint, or now (the angle in progress is repeated)")
def pause(
    job_id: JobId,
    service: Service,
    immediate: bool = Query(False, description="stop mid-angle instead of at the next checkpoint"),
) -> JobInfo:
    return service.pause(job_id, immediate=immediate)


@router.post("/{job_id}/resume", dependencies=WRITE, responses=_CONFLICT,
             summary="Resume a paused job from its last checkpoint")
def resume(job_id: JobId, service: Service) -> JobInfo:
    return service.resume(job_id)


@router.post("/{job_id}/abort", dependencies=WRITE, responses=_CONFLICT,
             summary="Abort a job (lights off, stage stopped); its readings are kept")
def abort(job_id: JobId, service: Service) -> JobInfo:
    return service.abort(job_id)


@router.post("/{job_id}/cancel", dependencies=WRITE, responses=_CONFLICT,
             summary="Take a queued job out of the queue before it starts")
def cancel(job_id: JobId, service: Service) -> JobInfo:
    return service.cancel(job_id)


@router.post("/{job_id}/reorder", dependencies=WRITE, responses=_CONFLICT,
             summary="Move a queued job: a new priority and/or position (0 = next)")
def reorder(
    job_id: JobId,
    request: ReorderRequest,
    service: Service,
    accept_uncalibrated: bool = Query(
        False, description="move a scan that no calibration covers ahead of the queued "
        "calibration it was queued behind (otherwise 409: it would run uncalibrated unasked)"),
) -> JobInfo:
    return service.reorder(job_id, request, accept_uncalibrated=accept_uncalibrated)


@router.delete("/{job_id}", dependencies=WRITE, responses=_CONFLICT,
               status_code=status.HTTP_204_NO_CONTENT,
               summary="Remove a queued or finished job and its readings (not its result file)")
def remove(job_id: JobId, service: Service) -> Response:
    service.remove(job_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
