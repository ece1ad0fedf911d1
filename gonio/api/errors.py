"""Error bodies of the API and the responses every route documents in the OpenAPI schema.

Each route's possible error statuses follow from what guards it and what it takes, so they are
derived here from the route itself instead of being listed by hand at every decorator:

===========================================  ==========================================
the route ...                                documents
===========================================  ==========================================
needs a key (writes, the dry run)            401 (missing), 403 (wrong, or read-only)
is an open read                              401 (if reads need keys), 403 (wrong key)
is refused under the maintenance lock        423
takes a request body                         413
takes parameters or a body                   422 (``detail``: a list, or a message)
takes a job id                               404
needs a write key (it writes to the store)   507 (the data directory's disk is full)
any route (a client without a valid key      429 (with ``Retry-After``)
over its rate, :mod:`gonio.api.ratelimit`)
any route (a key in the query string,        400
:class:`gonio.api.auth.RefuseKeysInUrl`)
===========================================  ==========================================

A route's own ``responses`` (409, 503, ...) keep their descriptions and get the error body.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute
from pydantic import BaseModel, Field

from gonio.api.auth import require_key_when_configured, require_read_access, require_write_key
from gonio.api.maintenance import refuse_while_locked


class ErrorBody(BaseModel):
    """Every error but a request that does not parse: one message for the user."""

    detail: str = Field(description="what went wrong and what to do")


class ValidationItem(BaseModel):
    """One problem of a request that does not parse."""

    loc: list[str | int] = Field(description="where: 'body', 'query', 'path', then field names")
    msg: str
    type: str


class ValidationErrorBody(BaseModel):
    """422: a request that does not parse (a list of problems), or a plan or design the rig
    cannot run (one message)."""

    detail: list[ValidationItem] | str


_DESCRIPTIONS: dict[int, str] = {
    400: "an API key (or token, secret) in the query string: keys go in the X-API-Key header",
    401: "an API key is needed in the X-API-Key header",
    403: "the API key is wrong, or the daemon has no keys (read-only)",
    404: "no such job, or it has no result yet",
    409: "not allowed in the current state",
    413: "request body larger than [limits] max_body_bytes",
    422: "invalid request, or one this rig cannot run; the detail says why",
    423: "the rig is locked for maintenance; the detail gives the reason",
    429: "too many requests from this address without an API key; retry after Retry-After "
         "seconds",
    500: "a stored result file cannot be read",
    503: "a device did not do what was asked; the detail gives the fault",
    507: "the data directory's disk is full: nothing was written and nothing stored was lost; "
         "free space and repeat the request",
}


_RETRY_AFTER = {"Retry-After": {
    "description": "whole seconds until this address may make a request again",
    "schema": {"type": "integer", "minimum": 1},
}}


def _response(status: int, given: dict[str, Any] | None, json_route: bool) -> dict[str, Any]:
    out = dict(given or {})
    out.setdefault("description", _DESCRIPTIONS.get(status, "error"))
    if status == 429:
        out.setdefault("headers", _RETRY_AFTER)
    if "model" not in out and "content" not in out:
        model = ValidationErrorBody if status == 422 else ErrorBody
        if json_route:
            out["model"] = model
        else:
            # FastAPI would document a model under the route's own media type (text/plain,
            # image/png, ...), but errors are always JSON: name the schema explicitly (it is
            # registered by the JSON routes that use it).
            out["content"] = {"application/json": {
                "schema": {"$ref": f"#/components/schemas/{model.__name__}"}}}
    return out


def _is_json_route(route: APIRoute) -> bool:
    cls = getattr(route.response_class, "value", route.response_class)
    return getattr(cls, "media_type", "application/json") == "application/json"


def document_errors(routes: Iterable[Any]) -> None:
    """Add the error responses each route can give to its OpenAPI operation (see module doc).

    Call on a router's routes before it is included (idempotent).
    """
    for route in routes:
        if not isinstance(route, APIRoute):
            continue
        deps = list(_walk(route.dependant))
        calls = {d.call for d in deps}
        # Answered before routing, on every route: a key in the URL, the rate limit.
        statuses: set[int] = {400, 429}
        if calls & {require_write_key, require_key_when_configured, require_read_access}:
            statuses |= {401, 403}
        if require_write_key in calls:
            statuses.add(507)  # a change writes to the store (or a file)
        if refuse_while_locked in calls:
            statuses.add(423)
        path_params = [p for d in deps for p in d.path_params]
        params = [*path_params, *(p for d in deps for p in (*d.query_params, *d.header_params))]
        if route.body_field is not None:
            statuses |= {413, 422}
        if params:
            statuses.add(422)
        if any(p.name == "job_id" for p in path_params):
            statuses.add(404)
        statuses |= {int(s) for s in route.responses if str(s).isdigit() and int(s) >= 400}
        responses: dict[int | str, dict[str, Any]] = {
            k: v for k, v in route.responses.items() if not (str(k).isdigit() and int(k) >= 400)
        }
        for status in sorted(statuses):
            given = route.responses.get(status, route.responses.get(str(status)))
            responses[status] = _response(status, given, _is_json_route(route))
        route.responses = responses


def _walk(dependant: Dependant) -> Any:
    """The dependant and all its sub-dependencies, depth first."""
    yield dependant
    for sub in dependant.dependencies:
        yield from _walk(sub)
