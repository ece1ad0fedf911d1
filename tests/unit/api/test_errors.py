"""The error responses each route documents follow from its guards and inputs (the table in
gonio/api/errors.py's docstring and docs/api.md), on small routes made for each row."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path
from fastapi.responses import PlainTextResponse
from fastapi.routing import APIRoute
from pydantic import BaseModel

from gonio.api.auth import require_key_when_configured, require_read_access, require_write_key
from gonio.api.errors import ErrorBody, ValidationErrorBody, document_errors
from gonio.api.maintenance import refuse_while_locked

WRITE = [Depends(require_write_key), Depends(refuse_while_locked)]


class Body(BaseModel):
    name: str


def _router() -> APIRouter:
    r = APIRouter()

    @r.get("/open")
    async def open_read() -> dict[str, str]:
        return {}

    @r.get("/read", dependencies=[Depends(require_read_access)])
    async def read() -> dict[str, str]:
        return {}

    @r.get("/compute", dependencies=[Depends(require_key_when_configured)])
    async def compute(n: int = 1) -> dict[str, str]:
        return {}

    @r.post("/jobs/{job_id}/pause", dependencies=WRITE,
            responses={409: {"description": "not now"}, 202: {"description": "accepted"}})
    async def pause(job_id: Annotated[int, Path(ge=1)]) -> dict[str, str]:
        return {}

    @r.post("/things", dependencies=WRITE)
    async def create(body: Body) -> dict[str, str]:
        return {}

    @r.get("/text", response_class=PlainTextResponse)
    async def text(job_id: int) -> str:
        return ""

    return r


def _documented() -> dict[str, dict[int | str, dict[str, Any]]]:
    routes = [r for r in _router().routes if isinstance(r, APIRoute)]
    document_errors(routes)
    return {r.path: r.responses for r in routes}


def _errors(responses: dict[int | str, dict[str, Any]]) -> set[int]:
    return {int(k) for k in responses if int(k) >= 400}


def test_each_route_documents_what_its_guards_and_inputs_can_give() -> None:
    doc = _documented()
    assert _errors(doc["/open"]) == {400, 429}
    assert _errors(doc["/read"]) == {400, 401, 403, 429}
    assert _errors(doc["/compute"]) == {400, 401, 403, 422, 429}  # a query parameter
    # write key, lock, a job id in the path, its own 409
    assert _errors(doc["/jobs/{job_id}/pause"]) == {400, 401, 403, 404, 409, 422, 423, 429, 507}
    assert _errors(doc["/things"]) == {400, 401, 403, 413, 422, 423, 429, 507}  # a body
    assert _errors(doc["/text"]) == {400, 422, 429}  # a query named job_id is not a path id


def test_a_route_keeps_its_own_descriptions_and_success_responses() -> None:
    pause = _documented()["/jobs/{job_id}/pause"]
    assert pause[409]["description"] == "not now"
    assert pause[202] == {"description": "accepted"}
    assert "X-API-Key" in pause[401]["description"]


def test_error_bodies_name_their_schema() -> None:
    doc = _documented()
    assert doc["/things"][413]["model"] is ErrorBody
    assert doc["/things"][422]["model"] is ValidationErrorBody
    assert "Retry-After" in doc["/open"][429]["headers"]
    # a plain-text route still documents JSON errors, by reference
    assert doc["/text"][422]["content"] == {"application/json": {
        "schema": {"$ref": "#/components/schemas/ValidationErrorBody"}}}


def test_documenting_twice_changes_nothing() -> None:
    routes = [r for r in _router().routes if isinstance(r, APIRoute)]
    document_errors(routes)
    once = [dict(r.responses) for r in routes]
    document_errors([*routes, "not a route"])
    assert [dict(r.responses) for r in routes] == once
