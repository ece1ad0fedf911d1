"""Design routes: optimise a rig's light/sensor geometry, list and evaluate industrial presets.

A design runs in a worker thread against the basis the daemon reconstructs with, one at a time
(:meth:`gonio.service.GonioService.design`: it uses a whole CPU core for up to its time limit);
a second request while one runs gets 409.
Optimising needs a key (it is expensive); evaluating a preset is a cheap read.
"""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Path, Query, Request
from fastapi.exceptions import RequestValidationError

from gonio.api.deps import READ, WRITE, Service
from gonio.api.limits import LimitExceeded
from gonio.brdf.design.presets import get_preset, preset_names
from gonio.plans.models import SPANS_DEG
from gonio.sampling_design import DEFAULT_TIME_LIMIT_S, DesignRequest, DesignResult, PresetInfo

router = APIRouter(prefix="/api/v1/design", tags=["design"])

_ERRORS: dict[int | str, dict[str, Any]] = {
    409: {"description": "another design is running; try again when it has finished"},
    423: {"description": "the rig is locked for maintenance"},
    422: {"description": "invalid request, or constraints no design can satisfy"},
}

PresetName = Annotated[str, Path(min_length=1, max_length=64,
                                 description="preset name (case, spaces and dashes ignored)")]


@router.post("", dependencies=WRITE, responses=_ERRORS,
             summary="Optimise light/sensor directions for the daemon's basis (blocks up to the "
                     "time limit)")
async def design(body: DesignRequest, service: Service, request: Request) -> DesignResult:
    limit = float(request.app.state.design_time_limit_s)
    if body.time_limit_s is None:
        body = body.model_copy(update={"time_limit_s": min(DEFAULT_TIME_LIMIT_S, limit)})
    elif body.time_limit_s > limit:
        raise LimitExceeded(
            f"time_limit_s = {body.time_limit_s:g} s is more than this daemon allows "
            f"({limit:g} s); ask for at most {limit:g} s or raise [limits] design_time_limit_s "
            "in the daemon config"
        )
    # One design at a time: the service refuses a second one (409) while one runs.
    return await asyncio.to_thread(service.design, body)


@router.get("/presets", dependencies=READ,
            summary="Industrial multi-angle geometries (V&F Table 1)")
def presets() -> list[PresetInfo]:
    out = []
    for name in preset_names():
        p = get_preset(name)
        out.append(PresetInfo(name=p.name, description=p.description, n_pairs=p.n_pairs))
    return out


@router.get("/presets/{name}", dependencies=READ,
            responses={404: {"description": "no preset of that name"}},
            summary="Evaluate a preset like an optimised design: condition number, roughness "
                    "bound, rig-config fragment")
async def preset(
    name: PresetName,
    service: Service,
    rotations: int = Query(8, ge=1, le=360, description="uniform stage angles for the "
                                                        "roughness bound"),
    span_deg: float = Query(180.0, description="arc of those angles, degrees: 180 (half a "
                                               "turn, the scans' default) or 360"),
) -> DesignResult:
    get_preset(name)  # UnknownPresetError -> 404 listing the known names, before any basis load
    if span_deg not in SPANS_DEG:
        raise RequestValidationError([{
            "type": "value_error", "loc": ("query", "span_deg"), "input": span_deg,
            "msg": f"span_deg is the arc of the stage angles: 180 (half a turn) or 360 (a full "
                   f"turn); got {span_deg:g}"}])
    return await asyncio.to_thread(service.evaluate_preset, name, rotations, span_deg)
