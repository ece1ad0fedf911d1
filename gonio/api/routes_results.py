"""Result routes: the HDF5 file, a preview image, metrics and one slice of the reconstruction.

Files are found by job id only: the path comes from the job's record, never from the request,
so no request can name a file of its choosing (``JobId`` is an integer path parameter).
"""

from __future__ import annotations

import asyncio
import json
import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response
from fastapi.responses import FileResponse
from pydantic import BaseModel, Field

from gonio.api.deps import READ, JobId, Service
from gonio.brdf.colour.errors import ColourError
from gonio.brdf.tables import geometry as geo
from gonio.results import OffGridAngle
from gonio.service import NotFound

router = APIRouter(prefix="/api/v1/jobs", tags=["results"])

_NO_RESULT: dict[int | str, dict[str, Any]] = {
    404: {"description": "no such job, or it has no result yet"},
    500: {"description": "the job's result file is damaged; the message says how to rebuild "
                         "it from the stored readings (gonio jobs rebuild)"},
}
_GRID_STEP_DEG = 5


class Slice(BaseModel):
    """The reconstructed BRDF along phi_h at one (theta_h, theta_d, phi_d) grid cell."""

    theta_h_deg: float
    theta_d_deg: float
    phi_d_deg: float
    phi_h_deg: list[float] = Field(description="72 azimuths of the half vector, degrees")
    values: dict[str, list[float | None]] = Field(
        description="channel -> 72 BRDF values, 1/sr; null where the cell is invalid"
    )


@router.get(
    "/{job_id}/result",
    dependencies=READ,
    responses={**_NO_RESULT, 200: {"content": {"application/x-hdf5": {}}}},
    response_class=FileResponse,
    summary="Download the job's HDF5 result file (layout: docs/api.md)",
)
def result_file(job_id: JobId, service: Service) -> FileResponse:
    # Read whole first (and kept for the pictures): a truncated or damaged file is refused
    # with the job and how to rebuild it, never sent as if it were good.
    path = service.checked_result_path(job_id)
    return FileResponse(path, media_type="application/x-hdf5",
                        filename=service.result_file_name(job_id))


@router.get(
    "/{job_id}/metrics",
    dependencies=READ,
    responses=_NO_RESULT,
    summary="Result summary and error metrics (self-estimated error, samples, timing)",
)
def metrics(job_id: JobId, service: Service) -> dict[str, Any]:
    return service.metrics(job_id)


@router.get(
    "/{job_id}/preview.png",
    dependencies=READ,
    responses={**_NO_RESULT, 200: {"content": {"image/png": {}}}},
    response_class=Response,
    summary="PNG preview of the reconstructed BRDF (half/difference slices, log scale)",
)
async def preview(job_id: JobId, service: Service) -> Response:
    png = await asyncio.to_thread(service.preview_png, job_id)
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.get(
    "/{job_id}/render.png",
    dependencies=READ,
    responses={**_NO_RESULT, 200: {"content": {"image/png": {}}}},
    response_class=Response,
    summary="Rendering of the reconstruction: sphere and swatch under point lights and a "
            "studio environment, the true material beside it on the simulated rig",
)
async def render_png(
    job_id: JobId,
    service: Service,
    compare: int | None = Query(
        None, ge=1, le=2**53, description="another job id: its reconstruction is shown "
        "below this one for comparison"),
) -> Response:
    png = await asyncio.to_thread(service.render_png, job_id, compare)
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=3600"})


@router.get(
    "/{job_id}/fit",
    dependencies=READ,
    responses=_NO_RESULT,
    summary="Each pair's calibrated samples against stage angle and the reconstruction's "
            "curve through them (mean over channels)",
)
async def fit(job_id: JobId, service: Service) -> dict[str, Any]:
    return await asyncio.to_thread(service.fit_curves, job_id)


@router.get(
    "/{job_id}/polar",
    dependencies=READ,
    responses={**_NO_RESULT, 422: {"description": "incidence out of range"}},
    summary="In-plane and cross-plane BRDF at one incidence (reconstruction, and the true "
            "material on the simulated rig)",
)
async def polar(
    job_id: JobId,
    service: Service,
    theta_i: float = Query(30, ge=0, le=85, description="incidence from the normal, degrees"),
    phi_i: float = Query(0, ge=-360, le=360, description="incidence azimuth from the holder "
                         "mark (specimen x axis), degrees"),
) -> dict[str, Any]:
    return await asyncio.to_thread(service.polar_curves, job_id, theta_i, phi_i)


def _grid(value: float, name: str, upper: int) -> int:
    if value % _GRID_STEP_DEG != 0 or not 0 <= value <= upper:
        raise OffGridAngle(
            f"{name} = {value:g} deg is not on the 5 degree grid; use a multiple of 5 in "
            f"[0, {upper}]"
        )
    return int(value) // _GRID_STEP_DEG


@router.get(
    "/{job_id}/slice",
    dependencies=READ,
    responses={**_NO_RESULT, 422: {"description": "angle not on the 5 degree grid"}},
    summary="The reconstructed BRDF against phi_h at one (theta_h, theta_d, phi_d) cell",
)
async def slice_(
    job_id: JobId,
    service: Service,
    theta_h: float = Query(30, ge=0, le=85, description="degrees, multiple of 5"),
    theta_d: float = Query(30, ge=0, le=85, description="degrees, multiple of 5"),
    phi_d: float = Query(90, ge=0, le=175, description="degrees, multiple of 5"),
) -> Slice:
    i_th, i_td, i_pd = (
        _grid(theta_h, "theta_h", 85),
        _grid(theta_d, "theta_d", 85),
        _grid(phi_d, "phi_d", 175),
    )
    table = (await asyncio.to_thread(service.result, job_id)).table
    if table is None:
        raise NotFound(f"job {job_id} has no reconstructed BRDF (a calibration job has none)")
    column = table.values[:, :, i_th, i_td, i_pd]  # (C, 72)
    return Slice(
        theta_h_deg=theta_h,
        theta_d_deg=theta_d,
        phi_d_deg=phi_d,
        phi_h_deg=[float(math.degrees(p)) for p in geo.PH_GRID],
        values={
            ch: [None if not math.isfinite(float(v)) else float(v) for v in column[c]]
            for c, ch in enumerate(table.channels)
        },
    )


ExportFormat = Literal["factored", "mtlx", "gltf", "glb", "merl", "table"]
# The export's warnings, as `gonio export` prints them (a JSON list of sentences).
EXPORT_WARNINGS_HEADER = "X-Gonio-Export-Warnings"


@router.get(
    "/{job_id}/export",
    dependencies=READ,
    responses={**_NO_RESULT, 200: {"content": {"application/octet-stream": {}},
                                   "headers": {EXPORT_WARNINGS_HEADER: {
                                       "description": "the export's warnings, as gonio "
                                       "export prints them (e.g. a MERL file lost the "
                                       "result's anisotropy): a JSON list of sentences, "
                                       "ASCII (non-ASCII as \\u escapes); [] when none",
                                       "schema": {"type": "string"}}}},
               422: {"description": "with_mesh asked for a format other than gltf or glb, or part="
                                    "sidecar for a format other than merl"},
               507: {"description": "no room on the data directory's disk for the export"}},
    response_class=FileResponse,
    summary="The result as a renderer format: factored, mtlx, gltf, glb, merl or table "
            "(docs/file-formats.md)",
)
async def export(
    job_id: JobId,
    service: Service,
    format: Annotated[ExportFormat, Query(
        description="factored | mtlx | gltf | glb | merl | table (glb: the glTF document in "
        "the binary container, model/gltf-binary)")],
    with_mesh: bool = Query(False, description="gltf and glb only: add a preview sphere with "
                            "tangents, so that any glTF viewer shows the material "
                            "(gonio export --with-mesh)"),
    part: Annotated[Literal["file", "sidecar"], Query(
        description="merl only: 'sidecar' gives the JSON file gonio export writes beside the "
        "MERL file (provenance, colour space, warnings; MERL's layout has no room for them)")
    ] = "file",
) -> FileResponse:
    from gonio.export import MEDIA_TYPES, ExportError
    from gonio.export.merl import sidecar_path

    if part == "sidecar" and format != "merl":
        raise ExportError(f"part=sidecar applies to format merl only, not {format!r}; "
                          "the other formats carry their record inside the file")
    path, name = await asyncio.to_thread(service.export, job_id, format, with_mesh)
    warnings = await asyncio.to_thread(service.export_warnings, path)
    if part == "sidecar":
        # Named after the download, as gonio export names it beside its file.
        return FileResponse(sidecar_path(path), media_type="application/json",
                            filename=sidecar_path(name).name,
                            headers={EXPORT_WARNINGS_HEADER: json.dumps(warnings)})
    # A download carries no sentence the page could show: the warnings come in a header.
    return FileResponse(path, media_type=MEDIA_TYPES[format], filename=name,
                        headers={EXPORT_WARNINGS_HEADER: json.dumps(warnings)})


ColourFormat = Literal["json", "csv"]


@router.get(
    "/{job_id}/colour",
    dependencies=READ,
    responses={**_NO_RESULT, 422: {"description": "colour cannot be computed as asked "
                                                  "(conditions, instruments, standard)"},
               200: {"content": {"application/json": {}, "text/csv": {}}}},
    summary="CIELAB at instrument geometries, flop index, and CIEDE2000 against another job "
            "(docs/colour.md)",
)
async def colour(
    job_id: JobId,
    service: Service,
    illuminant: str = Query("D65", max_length=8, description="CIE illuminant: D65, D50, A, "
                            "C, D55, D75, FL2, FL11"),
    observer: Literal["10", "2"] = Query("10", description="CIE 1964 10 degree or CIE 1931 "
                                         "2 degree observer"),
    instrument: Annotated[list[str] | None, Query(
        max_length=4, description="MA68, MA98, BYK-mac, MultiFX10 (repeat; default MA98 and "
        "BYK-mac)")] = None,
    azimuth: Annotated[list[float] | None, Query(
        max_length=36, description="specimen azimuths of the plane of incidence, degrees "
        "(repeat; default 0)")] = None,
    against: str | None = Query(
        None, min_length=1, max_length=104, description="the standard: a job id, or the name "
        "of a stored standard (a colour CSV in the data directory's standards/ folder, named "
        "without .csv; docs/colour.md): CIEDE2000 of this job against it per geometry"),
    format: Annotated[ColourFormat, Query(description="json, or csv: the colour table (or "
                                          "with against, the differences)")] = "json",
) -> Any:
    from gonio.brdf.colour.conditions import ViewingConditions
    from gonio.brdf.colour.instruments import DEFAULT_INSTRUMENTS
    from gonio.brdf.colour.report import compare
    from gonio.result_colour import (
        colour_warnings,
        difference_csv,
        in_reflectance,
        near_specular_note,
        no_colour_reason,
        result_report,
        shared_table_note,
    )

    azimuths = azimuth or [0.0]
    if not all(math.isfinite(a) and -360 <= a <= 360 for a in azimuths):
        raise ColourError("azimuth must be within -360..360 degrees")
    instruments = instrument or list(DEFAULT_INSTRUMENTS)
    cond = ViewingConditions(illuminant, observer)
    res = await asyncio.to_thread(service.reconstruction, job_id)
    report = await asyncio.to_thread(result_report, res, cond, instruments, azimuths)
    warnings = colour_warnings(res)
    # Why there is no CIELAB (uncalibrated: which calibration is missing, what to do), said
    # rather than left to a missing ΔE00.
    no_colour = no_colour_reason(res)
    diff = None
    shared: str | None = None
    standard: int | str | None = against
    if against is not None and no_colour is not None:
        what = f"job {against}" if against.isascii() and against.isdigit() else repr(against)
        raise ColourError(f"no ΔE00 against {what}: {no_colour}")
    if against is not None and against.isascii() and against.isdigit():
        standard = int(against)
        if not 1 <= standard <= 2**53:
            raise ColourError(f"against={against}: a job id is 1 to 2^53")
        std = await asyncio.to_thread(service.reconstruction, standard)
        std_no_colour = no_colour_reason(std)
        if std_no_colour is not None:
            raise ColourError(f"no ΔE00 against job {standard}: {std_no_colour}")
        std_report = await asyncio.to_thread(result_report, std, cond, instruments, azimuths)
        diff = compare(report, std_report)
        # Another scan's result: near-specular values both read from tables.
        shared = shared_table_note(report, std_report)
        warnings += colour_warnings(std, f"standard (job {standard})")
    elif against is not None:
        std_report, said = await asyncio.to_thread(service.colour_standard, against)
        diff = compare(report, std_report)
        warnings += [f"standard ({std_report.name}): {w}" for w in said]
    if format == "csv":
        text = (difference_csv(diff, warnings) if diff is not None
                else report.csv(warnings))
        return Response(text, media_type="text/csv",
                        headers={"Content-Disposition": "attachment; filename="
                                 f'"{service.colour_csv_name(job_id)}"'})
    out: dict[str, Any] = {"job_id": job_id, "colour": report.as_dict()}
    if warnings:
        out["warnings"] = warnings
    if no_colour is not None:
        out["no_colour"] = no_colour
    # Whether the values are in 1/sr (reflectance factors) or sensor units: the page says which
    # "uncalibrated" a table without CIELAB is (the colour's, or the values' as well).
    out["calibrated"] = in_reflectance(res.samples.calibration)
    # Which near-specular geometries no pair read; which instruments' geometries were compared
    # by angle (an MA68 standard against an MA98 report).
    notes = [n for n in (near_specular_note(report), diff and diff.note, shared) if n]
    if notes:
        out["notes"] = notes
    if diff is not None:
        out["difference"] = {"against": standard, **diff.as_dict()}
    return out
