"""The app's wiring, without a server: the routes are those docs/api.md lists, typed service
errors map to the statuses of its table, and every answer is JSON that renders. Requests over
loopback against a daemon: tests/system/api/."""

from __future__ import annotations

import asyncio
import json
import math
import re
from pathlib import Path
from typing import Any, cast

import pytest

from gonio.api.app import SafeJSONResponse, create_app
from gonio.service import GonioService

ROOT = Path(__file__).resolve().parents[3]


def _app() -> Any:
    # As gonio.api.schema builds it: routes are inspected, never called
    return create_app(cast(GonioService, object()), manage_service=False)


def _documented_routes() -> set[tuple[str, str]]:
    """(method, path) of each row of docs/api.md's endpoint table, path parameters as {}."""
    page = (ROOT / "docs" / "api.md").read_text()
    table = page.split("## Endpoints", 1)[1]
    out: set[tuple[str, str]] = set()
    for line in table.splitlines():
        m = re.match(r"\| `(GET|POST|PUT|DELETE|PATCH) ([^`]+)`((?:, `[A-Z]+`)*) \|", line)
        if not m:
            continue
        path = re.sub(r"\{[^}]*\}", "{}", m.group(2).split("[")[0].split("?")[0])
        for method in [m.group(1), *re.findall(r"`([A-Z]+)`", m.group(3))]:
            out.add((method, path))
    return out


def test_the_app_serves_exactly_the_routes_docs_api_lists() -> None:
    served = {
        (method.upper(), re.sub(r"\{[^}]*\}", "{}", path))
        for path, ops in _app().openapi()["paths"].items() for method in ops
    }
    documented = _documented_routes()
    assert len(documented) > 30
    assert served - documented == set(), "routes the docs do not list"
    assert documented - served == set(), "documented routes the app does not serve"


def test_the_page_and_its_files_are_served() -> None:
    app = _app()
    paths = {getattr(r, "path", None) for r in app.routes}
    assert "/" in paths and "/static" in paths
    assert (ROOT / "gonio" / "api" / "static" / "index.html").is_file()


# The table of gonio/api/app.py's docstring, written out: error type -> status.
MAPPED = {
    "NotFound": 404, "UnknownPresetError": 404, "Conflict": 409, "IllegalTransition": 409,
    "CalibrationError": 409, "PlanError": 422, "StageMoveError": 422, "LimitExceeded": 422,
    "OffGridAngle": 422, "DesignError": 422, "FeasibilityError": 422, "ColourError": 422,
    "DeviceError": 503, "ResultFileError": 500,
}


def _answer(app: Any, exc: Exception) -> tuple[int, dict[str, Any]]:
    handler = None
    for cls in type(exc).__mro__:  # as Starlette looks a handler up
        handler = app.exception_handlers.get(cls)
        if handler is not None:
            break
    assert handler is not None
    scope = {"type": "http", "method": "GET", "path": "/x", "headers": [], "query_string": b""}
    from starlette.requests import Request

    response = asyncio.run(handler(Request(scope), exc))
    return response.status_code, json.loads(response.body)


def test_typed_errors_answer_with_the_documented_status_and_their_message() -> None:
    app = _app()
    by_name = {cls.__name__: cls for cls in app.exception_handlers if isinstance(cls, type)}
    assert set(MAPPED) <= set(by_name)
    for name, status in MAPPED.items():
        cls = by_name[name]
        try:
            exc = cls("what went wrong; what to do")
        except TypeError:  # errors with more fields
            exc = cls.__new__(cls)
            Exception.__init__(exc, "what went wrong; what to do")
        got, body = _answer(app, exc)
        assert got == status, name
        assert "what went wrong; what to do" in body["detail"], name


def test_an_unexpected_error_is_500_without_its_insides(caplog: pytest.LogCaptureFixture) -> None:
    status, body = _answer(_app(), KeyError("secret internals"))
    assert status == 500
    assert body == {"detail": "internal error (KeyError); the daemon's log has the details"}
    assert "GET /x failed" in caplog.text


def test_a_full_disk_is_507_saying_what_to_do() -> None:
    import errno

    app = create_app(cast(GonioService, type("S", (), {"data_dir": Path("data")})()),
                     manage_service=False)
    status, body = _answer(app, OSError(errno.ENOSPC, "No space left on device"))
    assert status == 507
    assert body["detail"] == ("disk full: this request's data could not be written; free space "
                              "on the file system of data (nothing already stored was lost)")


def test_json_answers_render_nan_as_null_and_text_as_ascii() -> None:
    body = SafeJSONResponse({"a": math.nan, "b": [1.5, math.inf], "c": "é\ud800"}).body
    assert body == b'{"a":null,"b":[1.5,null],"c":"\\u00e9\\ud800"}'
