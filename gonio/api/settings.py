"""What the API layer needs to know from the daemon config, and how it is installed on an app."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from fastapi import FastAPI
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from gonio.api.auth import AccessPolicy, RefuseKeysInUrl
from gonio.api.limits import DEFAULT_MAX_BODY_BYTES, BodySizeLimit
from gonio.api.maintenance import LOCK_FILE_NAME, MaintenanceLock
from gonio.api.prometheus import RequestStats
from gonio.api.ratelimit import DEFAULT_BURST, DEFAULT_RATE_PER_S, AnonymousRateLimit

log = logging.getLogger("gonio.api")

DEFAULT_DESIGN_TIME_LIMIT_S = 60.0


@dataclass(frozen=True)
class ApiSettings:
    """Settings of the HTTP layer.

    Parameters
    ----------
    access : AccessPolicy
        API keys and whether reads need one.
    data_dir : Path
        The daemon's data directory; holds the maintenance lock file.
    max_body_bytes : int
        Largest accepted request body, bytes (larger gets 413).
    design_time_limit_s : float
        Longest search a design request may ask for, seconds (longer gets 422).
    anonymous_rate_per_s : float
        Requests per second one address may make without a valid key, on average (more get
        429 with ``Retry-After``; :mod:`gonio.api.ratelimit`); 0 = no limit.
    anonymous_burst : int
        Requests one address may make at once without a key.
    """

    access: AccessPolicy = field(default_factory=AccessPolicy)
    data_dir: Path = Path("gonio-data")
    max_body_bytes: int = DEFAULT_MAX_BODY_BYTES
    design_time_limit_s: float = DEFAULT_DESIGN_TIME_LIMIT_S
    anonymous_rate_per_s: float = DEFAULT_RATE_PER_S
    anonymous_burst: int = DEFAULT_BURST


class RequestTimer:
    """ASGI middleware recording count and latency per route template for ``/metrics``.

    The route *template* (``/api/v1/jobs/{job_id}``), not the raw path, is the label, so the
    number of series stays bounded whatever clients send.
    """

    def __init__(self, app: ASGIApp, stats: RequestStats) -> None:
        self.app = app
        self.stats = stats

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()
        status = 500

        async def timed_send(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
                route = scope.get("route")
                template = getattr(route, "path", None) or "(unmatched)"
                self.stats.observe(scope["method"], template, status, time.perf_counter() - t0)
            await send(message)

        await self.app(scope, receive, timed_send)


PAGE_CSP = (
    "default-src 'self'; script-src 'self'; connect-src 'self'; img-src 'self' data: blob:; "
    # Inline style attributes (plots set SVG styles) are allowed; inline scripts are not.
    "style-src 'self' 'unsafe-inline'; object-src 'none'; base-uri 'none'; "
    "form-action 'self'; frame-ancestors 'none'"
)
"""Content-Security-Policy of the lab page: only its own scripts, only its own API."""


class SecurityHeaders:
    """ASGI middleware: ``nosniff`` and no framing on every response; the page's CSP.

    The CSP goes on HTML answers of the page and its static files, not on ``/api/docs``
    (FastAPI's interactive view loads its scripts from a CDN and inlines one).
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        path = str(scope.get("path", ""))
        page = path == "/" or path.startswith("/static/")

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {k.lower() for k, _ in headers}
                extra = [(b"x-content-type-options", b"nosniff"), (b"x-frame-options", b"DENY"),
                         (b"referrer-policy", b"no-referrer")]
                if page:
                    extra.append((b"content-security-policy", PAGE_CSP.encode()))
                headers.extend((k, v) for k, v in extra if k not in present)
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def install(app: FastAPI, settings: ApiSettings) -> None:
    """Attach the access policy, maintenance lock, body limit, rate limit and request timing to
    ``app``."""
    app.state.access_policy = settings.access
    app.state.maintenance = MaintenanceLock(settings.data_dir / LOCK_FILE_NAME)
    app.state.request_stats = RequestStats()
    app.state.design_time_limit_s = settings.design_time_limit_s
    # The middleware added last is the outermost: the timer wraps the body limit, so 413s are
    # counted too; the rate limit answers before a body is buffered, with the security headers.
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    app.add_middleware(AnonymousRateLimit, access=settings.access,
                       rate_per_s=settings.anonymous_rate_per_s, burst=settings.anonymous_burst)
    app.add_middleware(RefuseKeysInUrl)
    app.add_middleware(SecurityHeaders)
    app.add_middleware(RequestTimer, stats=app.state.request_stats)
