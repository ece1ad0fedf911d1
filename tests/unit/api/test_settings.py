"""The HTTP layer's own middleware (timing per route template, security headers) and what
install puts on an app; the whole stack over loopback: tests/system/api/test_guards.py."""

from __future__ import annotations

import asyncio
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from fastapi import FastAPI

from gonio.api.auth import AccessPolicy, RefuseKeysInUrl
from gonio.api.limits import BodySizeLimit
from gonio.api.maintenance import LOCK_FILE_NAME
from gonio.api.prometheus import RequestStats
from gonio.api.ratelimit import AnonymousRateLimit
from gonio.api.settings import (
    PAGE_CSP,
    ApiSettings,
    RequestTimer,
    SecurityHeaders,
    install,
)


def answer(status: int, headers: list[tuple[bytes, bytes]] | None = None) -> Any:
    async def app(scope: Any, receive: Any, send: Any) -> None:
        scope["route"] = SimpleNamespace(path="/api/v1/jobs/{job_id}") if status != 404 else None
        await send({"type": "http.response.start", "status": status, "headers": headers or []})
        await send({"type": "http.response.body", "body": b""})
    return app


def drive(mw: Any, path: str = "/api/v1/jobs/7", method: str = "GET") -> list[dict[str, Any]]:
    sent: list[dict[str, Any]] = []

    async def send(m: dict[str, Any]) -> None:
        sent.append(m)

    asyncio.run(mw({"type": "http", "path": path, "method": method}, None, send))
    return sent


def test_the_timer_counts_by_route_template_not_by_path() -> None:
    stats = RequestStats()
    drive(RequestTimer(answer(200), stats))
    drive(RequestTimer(answer(200), stats), path="/api/v1/jobs/8")
    drive(RequestTimer(answer(404), stats), path="/no/such/../thing")
    lines = stats.render()
    assert ('gonio_http_requests_total{method="GET",route="/api/v1/jobs/{job_id}",status="200"} 2'
            in lines)
    assert 'gonio_http_requests_total{method="GET",route="(unmatched)",status="404"} 1' in lines


def test_every_answer_gets_nosniff_no_framing_and_no_referrer() -> None:
    start = drive(SecurityHeaders(answer(200)))[0]
    headers = dict(start["headers"])
    assert headers[b"x-content-type-options"] == b"nosniff"
    assert headers[b"x-frame-options"] == b"DENY"
    assert headers[b"referrer-policy"] == b"no-referrer"
    assert b"content-security-policy" not in headers  # the API docs page loads a CDN script


def test_the_page_and_its_files_get_the_csp() -> None:
    for path in ("/", "/static/app.js"):
        headers = dict(drive(SecurityHeaders(answer(200)), path=path)[0]["headers"])
        assert headers[b"content-security-policy"] == PAGE_CSP.encode()
    assert "script-src 'self';" in PAGE_CSP and "frame-ancestors 'none'" in PAGE_CSP


def test_a_header_the_app_set_is_kept() -> None:
    start = drive(SecurityHeaders(answer(200, [(b"X-Frame-Options", b"SAMEORIGIN")])))[0]
    assert [v for k, v in start["headers"] if k.lower() == b"x-frame-options"] == [b"SAMEORIGIN"]


def test_install_puts_the_settings_and_the_middleware_on_the_app(tmp_path: Path) -> None:
    app = FastAPI()
    access = AccessPolicy(read_requires_key=True)
    install(app, ApiSettings(access=access, data_dir=tmp_path, max_body_bytes=123,
                             design_time_limit_s=5.0))
    assert app.state.access_policy is access
    assert app.state.maintenance.path == tmp_path / LOCK_FILE_NAME
    assert app.state.design_time_limit_s == 5.0
    # outermost first: timing sees every answer, the body limit is innermost
    order = [m.cls for m in app.user_middleware]
    assert order == [RequestTimer, SecurityHeaders, RefuseKeysInUrl, AnonymousRateLimit,
                     BodySizeLimit]
    assert app.user_middleware[-1].kwargs == {"max_bytes": 123}
