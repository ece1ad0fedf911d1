"""Rig routes: status (devices, positions, faults), its configuration, calibration, halt,
and the maintenance lock."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request
from pydantic import BaseModel, Field

from gonio.api.auth import Caller, require_write_key
from gonio.api.deps import READ, WRITE, Service
from gonio.api.maintenance import LockState, MaintenanceLock
from gonio.calibration import Calibration
from gonio.fields import FINITE, Text
from gonio.rigdescription import RigDescription
from gonio.service import GonioService, RigStatus, StageRequest, StageState

router = APIRouter(prefix="/api/v1", tags=["rig"])


class RigOverview(RigStatus):
    """Rig status plus its static description, in one call."""

    name: str = Field(description="rig name from the rig config")
    description: RigDescription


class MaintenanceState(BaseModel):
    locked: bool
    reason: str = ""
    by: str | None = Field(None, description="name of the API key that set the lock")
    since: float | None = Field(None, description="Unix time, seconds")


class LockRequest(BaseModel):
    model_config = FINITE

    reason: Text = Field(min_length=1, max_length=500, description="shown to every client")


def _state(st: LockState) -> MaintenanceState:
    return MaintenanceState(locked=st.locked, reason=st.reason, by=st.by, since=st.since)


def _lock(request: Request) -> MaintenanceLock:
    lock: MaintenanceLock = request.app.state.maintenance
    return lock


def _rig_name(service: Any) -> str:
    cfg = service.rig_config
    return str(getattr(getattr(cfg, "rig", None), "name", "rig"))


@router.get("/rig", dependencies=READ, summary="Rig status: devices, stage position, faults, queue")
async def rig_status(service: Service) -> RigOverview:
    st = await service.rig_status()
    return RigOverview(**st.model_dump(), name=_rig_name(service), description=service.desc)


@router.get("/rig/config", dependencies=READ, summary="The rig configuration the daemon runs with")
def rig_config(service: Service) -> dict[str, Any]:
    cfg = service.rig_config
    if cfg is None or not hasattr(cfg, "model_dump"):
        return {}
    data: dict[str, Any] = cfg.model_dump(mode="json", exclude_none=True)
    return data


@router.get("/calibration", dependencies=READ, summary="The calibration applied to scans")
def calibration(service: Service) -> Calibration:
    return service.calibration()


@router.post("/rig/halt", dependencies=[Depends(require_write_key)],
             summary="Emergency halt: stop the running job now, no cleanup, hold the queue")
def halt(service: Service) -> RigOverview | dict[str, str]:
    # Not refused by the maintenance lock: stopping the rig must always be possible.
    service.halt()
    return {"status": "halted; release the queue with POST /api/v1/rig/release (gonio jobs "
                      "--daemon URL release)"}


@router.get("/rig/stage", dependencies=READ, responses={503: {"description": "stage fault"}},
            summary="Stage state: position, moving, homed (zero set), faults")
async def stage_state(service: Service) -> StageState:
    return await service.stage_status()


@router.post("/rig/stage", dependencies=WRITE,
             responses={409: {"description": "a job is active: the stage is in use"},
                        503: {"description": "the stage reported a fault or did not answer"}},
             summary="Manual stage command: move, home (set zero here), stop, clear faults")
async def stage_command(body: StageRequest, service: Service) -> StageState:
    return await service.stage_command(body)


@router.post("/rig/release", dependencies=WRITE,
             summary="Let the queue run again after a halt or a stop-on-failure")
def release(service: Service) -> dict[str, str]:
    service.release_queue()
    return {"status": "queue released"}


@router.get("/maintenance", dependencies=READ, summary="Whether the rig is locked for maintenance")
def maintenance(request: Request) -> MaintenanceState:
    return _state(_lock(request).state())


@router.put("/maintenance", summary="Lock the rig for maintenance: every change gets 423")
def lock_maintenance(
    body: LockRequest, request: Request, caller: Annotated[Caller, Depends(require_write_key)]
) -> MaintenanceState:
    service: GonioService = request.app.state.service
    st = _lock(request).lock(body.reason, by=caller.key_name)
    service.record_event("maintenance", {"locked": True, "reason": body.reason,
                                         "by": caller.key_name})
    return _state(st)


@router.delete("/maintenance", summary="Release the maintenance lock")
def unlock_maintenance(
    request: Request, caller: Annotated[Caller, Depends(require_write_key)]
) -> MaintenanceState:
    service: GonioService = request.app.state.service
    st = _lock(request).unlock()
    service.record_event("maintenance", {"locked": False, "by": caller.key_name})
    return _state(st)
