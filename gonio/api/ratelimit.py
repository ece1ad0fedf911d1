"""Per-client request rate limit for callers without an API key, as plain ASGI middleware.

Reads are open by default, so anyone who can reach the daemon can poll it. Each request costs
the daemon's interpreter some CPU time, and a scan's device round trips run in the same
process: a few clients polling back to back would take time from the scan. A client without a
valid key (counted by its address) therefore gets a token bucket: ``rate_per_s`` requests per
second on average, up to ``burst`` at once. Beyond it the answer is **429** with a
``Retry-After`` header (whole seconds, RFC 9110) and a message saying how to get more, before
any routing, dependency or handler runs, so a refused request is cheap; it is held back
:data:`TARPIT_S` first, which slows a client that ignores ``Retry-After`` to one request a
second per connection.

Requests with a valid key are not limited: key holders are known by name and can already stop
the rig. The emergency halt needs a key, so no limit ever stands between a user and the halt
button. A wrong key counts as no key here (the route answers 403 when it gets to run).

The lab page makes about two requests a second while a job runs (docs/api.md), far below the
default of 20 per second.
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from collections.abc import Callable

from starlette.types import ASGIApp, Receive, Scope, Send

from gonio.api.auth import API_KEY_HEADER, AccessPolicy

DEFAULT_RATE_PER_S = 20.0
"""Average requests per second one address may make without a key."""
DEFAULT_BURST = 40
"""Requests one address may make at once without a key (the page's start-up burst is ~10)."""
TARPIT_S = 1.0
"""How long a 429 is held back before it is sent (see :meth:`AnonymousRateLimit.__call__`)."""
MAX_CLIENTS = 4096
"""Buckets kept at most; beyond it full (idle) buckets are dropped, then the oldest."""

_KEY_HEADER = API_KEY_HEADER.lower().encode("latin-1")


class TokenBuckets:
    """One token bucket per client name.

    Parameters
    ----------
    rate_per_s : float
        Tokens added per second (> 0).
    burst : int
        Bucket size (>= 1): requests allowed at once after a quiet period.
    clock : callable, optional
        Monotonic time in seconds (tests pass their own).
    """

    def __init__(self, rate_per_s: float, burst: int,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(rate_per_s) and rate_per_s > 0):
            raise ValueError(f"rate_per_s must be a positive number, got {rate_per_s}")
        if burst < 1:
            raise ValueError(f"burst must be at least 1, got {burst}")
        self.rate_per_s = float(rate_per_s)
        self.burst = int(burst)
        self._clock = clock
        self._buckets: dict[str, tuple[float, float]] = {}  # name -> (tokens, last update)

    def take(self, name: str) -> float:
        """Take one token for ``name``; returns 0 if granted, else seconds until one is free."""
        now = self._clock()
        tokens, last = self._buckets.get(name, (float(self.burst), now))
        tokens = min(float(self.burst), tokens + (now - last) * self.rate_per_s)
        if tokens >= 1.0:
            self._store(name, tokens - 1.0, now)
            return 0.0
        self._store(name, tokens, now)
        return (1.0 - tokens) / self.rate_per_s

    def _store(self, name: str, tokens: float, now: float) -> None:
        if name not in self._buckets and len(self._buckets) >= MAX_CLIENTS:
            self._prune(now)
        self._buckets[name] = (tokens, now)

    def _prune(self, now: float) -> None:
        full = [n for n, (t, last) in self._buckets.items()
                if t + (now - last) * self.rate_per_s >= self.burst]
        for n in full:
            del self._buckets[n]
        while len(self._buckets) >= MAX_CLIENTS:  # all busy: forget the oldest
            del self._buckets[next(iter(self._buckets))]


class AnonymousRateLimit:
    """ASGI middleware: 429 + ``Retry-After`` for clients without a valid key beyond the rate.

    Parameters
    ----------
    app : ASGI application
    access : AccessPolicy
        Its keyring decides which requests carry a valid key (those are not limited).
    rate_per_s, burst : float, int
        The bucket of each address (:class:`TokenBuckets`). ``rate_per_s = 0`` turns the
        limit off.
    """

    def __init__(self, app: ASGIApp, access: AccessPolicy, rate_per_s: float = DEFAULT_RATE_PER_S,
                 burst: int = DEFAULT_BURST) -> None:
        self.app = app
        self.access = access
        self.buckets = TokenBuckets(rate_per_s, burst) if rate_per_s > 0 else None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if self.buckets is None or scope["type"] != "http" or self._keyed(scope):
            await self.app(scope, receive, send)
            return
        client = scope.get("client")
        who = str(client[0]) if client else "unknown"
        wait_s = self.buckets.take(who)
        if wait_s <= 0:
            await self.app(scope, receive, send)
            return
        # Held back TARPIT_S before it is sent: HTTP/1.1 answers one request at a time per
        # connection, so a client that ignores Retry-After and asks again at once still makes
        # at most one request per TARPIT_S per connection. Waiting costs this loop nothing;
        # answering a flood of 429s as fast as they come would cost the scan CPU time.
        await asyncio.sleep(TARPIT_S)
        retry = max(1, math.ceil(wait_s - TARPIT_S))
        detail = (
            f"too many requests from {who} without an API key (at most "
            f"{self.buckets.rate_per_s:g} per second, {self.buckets.burst} at once); retry "
            f"after {retry} s, poll less often (GET /api/v1/events pushes every change), or "
            f"send a key in the {API_KEY_HEADER} header"
        )
        payload = json.dumps({"detail": detail}).encode()
        await send({
            "type": "http.response.start",
            "status": 429,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(payload)).encode()),
                (b"retry-after", str(retry).encode()),
            ],
        })
        await send({"type": "http.response.body", "body": payload})

    def _keyed(self, scope: Scope) -> bool:
        for name, value in scope.get("headers", ()):
            if name.lower() == _KEY_HEADER:
                try:
                    presented = value.decode("latin-1")
                except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes any byte
                    return False
                return self.access.keyring.identify(presented) is not None
        return False
