"""The limit on clients without a key (429 + Retry-After) and the refusal of keys in URLs, on a
tiny app behind a real uvicorn server (the token bucket itself: tests/unit/api/test_ratelimit.py).
"""

from __future__ import annotations

import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated

import httpx
import pytest
from fastapi import Depends, FastAPI

from gonio.api.auth import AccessPolicy, ApiKeyring, Caller, require_read_access, require_write_key
from gonio.api.settings import ApiSettings, install
from tests.system.api.live_server import live_server

pytestmark = pytest.mark.system

KEY = secrets.token_urlsafe(24)
BURST = 3
RATE = 0.01
"""One request per 100 s after the burst: no token comes back while a test runs, however
slowly a busy machine runs it, so the 429 is certain and Retry-After is large."""


def tiny_app(tmp: Path, rate: float = RATE) -> FastAPI:
    app = FastAPI()
    install(app, ApiSettings(access=AccessPolicy(ApiKeyring({"alice": KEY})), data_dir=tmp,
                             anonymous_rate_per_s=rate, anonymous_burst=BURST))

    @app.get("/read")
    async def read(
        caller: Annotated[Caller, Depends(require_read_access)],
    ) -> dict[str, str | None]:
        return {"who": caller.key_name}

    @app.post("/halt")
    async def halt(caller: Annotated[Caller, Depends(require_write_key)]) -> dict[str, str | None]:
        return {"who": caller.key_name}

    return app


@pytest.fixture
def url(tmp_path: Path) -> Iterator[str]:
    with live_server(tiny_app(tmp_path)) as u:
        yield u


def test_anonymous_client_beyond_its_burst_gets_429_with_retry_after(url: str) -> None:
    with httpx.Client(base_url=url, timeout=30) as c:
        assert [c.get("/read").status_code for _ in range(BURST)] == [200] * BURST
        r = c.get("/read")
        assert r.status_code == 429
        # One token per 1/RATE = 100 s; the bucket is empty, so close to 100 s are left.
        assert 90 <= int(r.headers["retry-after"]) <= 100
        assert r.headers["content-type"] == "application/json"
        assert r.headers["x-content-type-options"] == "nosniff"  # security headers still on
        detail = r.json()["detail"]
        assert "without an API key" in detail and "X-API-Key" in detail
        assert "retry after" in detail


def test_key_holders_are_not_limited_and_a_wrong_key_counts_as_none(url: str) -> None:
    with httpx.Client(base_url=url, timeout=30) as c:
        for _ in range(BURST):
            assert c.get("/read").status_code == 200
        # The address is out of tokens; with the key, reads and the halt still go through.
        keyed = {"X-API-Key": KEY}
        assert [c.get("/read", headers=keyed).status_code for _ in range(2 * BURST)] == [
            200] * (2 * BURST)
        assert c.post("/halt", headers=keyed).json() == {"who": "alice"}
        assert c.get("/read", headers={"X-API-Key": "x" * 32}).status_code == 429


def test_rate_zero_turns_the_limit_off(tmp_path: Path) -> None:
    with live_server(tiny_app(tmp_path, rate=0)) as u, httpx.Client(base_url=u) as c:
        assert {c.get("/read").status_code for _ in range(4 * BURST)} == {200}


# TokenBuckets and the middleware's answer on their own: tests/unit/api/test_ratelimit.py.


@pytest.mark.parametrize("param", ["api_key", "X-API-Key", "key", "token", "access_token"])
def test_a_key_in_the_query_string_is_refused_on_reads_and_writes(url: str, param: str) -> None:
    # That the daemon's access log shows such a request without the key is checked on a real
    # `gonio serve` in test_shutdown_and_logs.py.
    with httpx.Client(base_url=url, timeout=30) as c:
        # A valid key, on an open read and on a write: refused both times, not ignored.
        r = c.get("/read", params={param: KEY, "since": 3})
        assert r.status_code == 400
        detail = r.json()["detail"]
        assert "not accepted in the URL" in detail and "X-API-Key header" in detail
        assert repr(param) in detail and KEY not in detail
        r = c.post("/halt", params={param: KEY}, headers={"X-API-Key": KEY})
        assert r.status_code == 400
        # Other parameters are untouched.
        assert c.get("/read", params={"since": 3}).status_code == 200
