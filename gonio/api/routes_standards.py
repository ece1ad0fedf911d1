"""Colour standard routes: the stored standards a job's colour is compared with by name.

A stored standard is a colour CSV (``GET /api/v1/jobs/{id}/colour?format=csv``, ``gonio colour
--csv``, or one edited in a spreadsheet) kept in the data directory's ``standards/`` folder;
``GET /api/v1/jobs/{id}/colour?against=NAME`` compares with it (docs/colour.md); ``PUT`` stores
one, ``DELETE`` removes one. The name is a file name of that folder only, never a path.
"""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Response
from pydantic import BaseModel, Field

from gonio.api.deps import READ, WRITE, Service

router = APIRouter(prefix="/api/v1/colour-standards", tags=["colour"])

StandardName = Annotated[str, Path(min_length=1, max_length=104, description=(
    "the standard's name: letters, digits, '.', '_', '-' and spaces, no folders (a trailing "
    ".csv is dropped)"))]


class Standards(BaseModel):
    standards: list[str] = Field(description="the stored standards' names, sorted")


class StoredStandard(BaseModel):
    name: str
    replaced: bool = Field(description="a standard of that name was stored before and is "
                           "replaced")
    illuminant: str
    observer: str
    geometries: int = Field(description="the geometries (rows) it holds")
    warnings: list[str] = Field(description="its warnings column's sentences, which travel "
                                "with every comparison against it")


@router.get("", dependencies=READ, summary="The stored colour standards")
def list_standards(service: Service) -> Standards:
    return Standards(standards=service.colour_standard_names())


@router.put(
    "/{name}", dependencies=WRITE,
    responses={422: {"description": "a name that cannot be a standard's, or a text that is not "
                     "a colour CSV (the message says what is wrong); nothing is written"}},
    summary="Store a colour CSV as a standard (replacing one of that name)")
async def store_standard(
    name: StandardName, service: Service,
    csv: Annotated[str, Body(media_type="text/csv", description=(
        "the colour CSV: columns illuminant, observer, instrument, incidence_deg, "
        "aspecular_deg, azimuth_deg, L, a, b (as GET /api/v1/jobs/{id}/colour?format=csv "
        "writes them; a spreadsheet's semicolons and decimal commas are read too)"))] = "",
) -> Any:
    # An empty body is read as an empty CSV, so the refusal says what a standard needs.
    return StoredStandard(**await asyncio.to_thread(service.store_colour_standard, name, csv))


@router.delete(
    "/{name}", dependencies=WRITE, status_code=204,
    responses={404: {"description": "no stored standard of that name (the message lists the "
                     "stored ones); nothing is removed"}},
    summary="Remove a stored colour standard")
async def delete_standard(name: StandardName, service: Service) -> Response:
    await asyncio.to_thread(service.delete_colour_standard, name)
    return Response(status_code=204)
