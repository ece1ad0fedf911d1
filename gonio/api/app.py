"""The FastAPI application: a thin HTTP layer over one :class:`gonio.service.GonioService`.

:func:`create_app` wires routes, guards (keys, maintenance lock, body limit), error mapping and
the lab page. The service's typed errors become HTTP statuses in one place here:

====================================================  ======
:class:`gonio.service.NotFound` (store's)             404
:class:`gonio.brdf.design.presets.UnknownPresetError` 404
:class:`gonio.service.Conflict`                       409
:class:`gonio.jobstates.IllegalTransition`            409
:class:`gonio.calibration.CalibrationError`           409
:class:`gonio.plans.models.PlanError`                 422
:class:`gonio.motion.StageMoveError`                  422
:class:`gonio.api.limits.LimitExceeded`               422
:class:`gonio.results.OffGridAngle`                   422
:class:`gonio.brdf.design.errors.DesignError`         422
:class:`gonio.brdf.design.errors.FeasibilityError`    422
:class:`gonio.export.ExportError`                     422
:class:`gonio.service.DeviceError`                    503
:class:`gonio.results.ResultFileError`                500
a full disk (:func:`gonio.diskspace.is_disk_full`)    507
any other unexpected error                            500
====================================================  ======

Every error, the unexpected ones too, answers with the JSON error body (``{"detail": ...}``).
"""

from __future__ import annotations

import json
import logging
import math
import sqlite3
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from gonio import __version__
from gonio.api import (
    routes_design,
    routes_jobs,
    routes_results,
    routes_rig,
    routes_standards,
    routes_system,
)
from gonio.api.errors import document_errors
from gonio.api.events import HEARTBEAT_S, StreamCloser
from gonio.api.limits import LimitExceeded
from gonio.api.settings import ApiSettings, install
from gonio.brdf.colour.errors import ColourError
from gonio.brdf.design.errors import DesignError, FeasibilityError
from gonio.brdf.design.presets import UnknownPresetError
from gonio.calibration import CalibrationError
from gonio.diskspace import DiskFull, disk_full_message, is_disk_full
from gonio.export import ExportError
from gonio.jobstates import IllegalTransition
from gonio.motion import StageMoveError
from gonio.plans.models import PlanError
from gonio.results import OffGridAngle, ResultFileError
from gonio.service import Conflict, DeviceError, GonioService
from gonio.store import NotFound

log = logging.getLogger("gonio.api")

STATIC_DIR = Path(__file__).with_name("static")

DESCRIPTION = """\
REST API of the gonio acquisition daemon. Changes need an API key in the `X-API-Key` header;
reads are open unless the daemon is configured otherwise. Live events: `GET /api/v1/events`
(server-sent events; resume with `Last-Event-ID` or `?since=`). See docs/api.md.
"""


class SafeJSONResponse(JSONResponse):
    """JSON that always renders: ASCII-escaped (a lone surrogate echoed from a request cannot
    break the UTF-8 encoding) and non-finite floats as null (JSON has no NaN)."""

    def render(self, content: Any) -> bytes:
        try:
            text = json.dumps(content, ensure_ascii=True, allow_nan=False, separators=(",", ":"))
        except ValueError:
            text = json.dumps(_finite(content), ensure_ascii=True, separators=(",", ":"))
        return text.encode("ascii")


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _error(status: int, exc: Exception, headers: dict[str, str] | None = None) -> JSONResponse:
    return SafeJSONResponse({"detail": str(exc)}, status_code=status, headers=headers)


def _loc_item(part: Any) -> str | int:
    return part if isinstance(part, int) else str(part)


async def _validation_error(_request: Request, exc: Exception) -> JSONResponse:
    """422 for a request that does not parse: ``{"detail": [{"loc", "msg", "type"}, ...]}``.

    The offending input is not echoed back (FastAPI's default does): it may be NaN, huge or
    not valid text, and echoing it is what used to make the error response itself fail.
    """
    assert isinstance(exc, RequestValidationError)
    detail = [
        {
            "loc": [_loc_item(p) for p in err.get("loc", ())],
            "msg": _validation_message(err),
            "type": str(err.get("type", "value_error")),
        }
        for err in exc.errors()
    ]
    return SafeJSONResponse({"detail": detail}, status_code=422)


def _validation_message(err: Any) -> str:
    """A validation error's message; a body that is not JSON, or not a JSON object, says
    what was wrong and what to send (it said "JSON decode error", or "Input should be a
    valid dictionary" for a body sent without its JSON content type)."""
    msg = str(err.get("msg", "invalid value"))
    kind, loc = err.get("type"), tuple(err.get("loc", ()))
    if kind == "json_invalid":
        why = str((err.get("ctx") or {}).get("error", "")).strip()
        return (f"the request body is not valid JSON{f' ({why})' if why else ''}: send a JSON "
                "object with the header Content-Type: application/json")
    if loc == ("body",) and kind in ("model_attributes_type", "dict_type"):
        return (f"{msg}: the request body must be a JSON object, sent with the header "
                "Content-Type: application/json")
    return msg


async def _http_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    return SafeJSONResponse({"detail": str(exc.detail)}, status_code=exc.status_code,
                            headers=exc.headers)


def _mapped(status: int) -> Callable[[Request, Exception], Awaitable[JSONResponse]]:
    """An exception handler answering ``status`` with the exception's (user-facing) message."""

    async def handler(_request: Request, exc: Exception) -> JSONResponse:
        return _error(status, exc)

    return handler


def create_app(
    service: GonioService,
    settings: ApiSettings | None = None,
    *,
    manage_service: bool = True,
    sse_heartbeat_s: float = HEARTBEAT_S,
) -> FastAPI:
    """Build the HTTP app over ``service``.

    Parameters
    ----------
    service : GonioService
    settings : ApiSettings, optional
        Keys, data directory (maintenance lock), body limit. Default: no keys (read-only).
    manage_service : bool
        Start the service with the app's lifespan and stop it on shutdown. False when the
        caller runs the service itself.
    sse_heartbeat_s : float
        Seconds between keep-alive comments on idle event streams.
    """
    settings = settings or ApiSettings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        if manage_service:
            await service.start()
        try:
            yield
        finally:
            app.state.stream_closer.close()
            if manage_service:
                await service.stop()

    app = FastAPI(
        title="gonio",
        version=__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url="/api/docs",
        redoc_url=None,
        openapi_url="/api/openapi.json",
    )
    app.state.service = service
    app.state.started_at = time.monotonic()
    app.state.sse_subscribers = 0
    app.state.sse_heartbeat_s = sse_heartbeat_s
    app.state.stream_closer = StreamCloser()
    install(app, settings)

    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    for exc_type, status in (
        (NotFound, 404),
        (Conflict, 409),
        (IllegalTransition, 409),
        (CalibrationError, 409),
        (PlanError, 422),
        (StageMoveError, 422),
        (LimitExceeded, 422),
        (OffGridAngle, 422),
        (DesignError, 422),
        (FeasibilityError, 422),
        (UnknownPresetError, 404),
        (ColourError, 422),
        (ExportError, 422),
        (DeviceError, 503),
    ):
        app.add_exception_handler(exc_type, _mapped(status))

    async def result_file_error(request: Request, exc: Exception) -> JSONResponse:
        # A job's result file that cannot be read is a server-side problem worth a log line,
        # but the client gets a message, not a stack trace.
        log.error("%s %s: %s", request.method, request.url.path, exc)
        return _error(500, exc)

    app.add_exception_handler(ResultFileError, result_file_error)

    async def unexpected_error(request: Request, exc: Exception) -> JSONResponse:
        # A full disk (a write to the store, a result, an export) is the user's to fix:
        # 507 with what to do. Anything else is a bug: logged with its traceback, and the
        # client still gets the JSON error body, not a plain-text page.
        if is_disk_full(exc):
            log.error("%s %s: %s", request.method, request.url.path, exc)
            return _error(507, DiskFull(disk_full_message(
                "this request's data", service.data_dir)))
        log.error("%s %s failed", request.method, request.url.path, exc_info=exc)
        return SafeJSONResponse({"detail": f"internal error ({type(exc).__name__}); the "
                                 "daemon's log has the details"}, status_code=500)

    for unexpected in (OSError, sqlite3.Error, Exception):
        app.add_exception_handler(unexpected, unexpected_error)

    for module in (routes_system, routes_rig, routes_jobs, routes_results, routes_standards,
                   routes_design):
        document_errors(module.router.routes)
        app.include_router(module.router)

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    return app
