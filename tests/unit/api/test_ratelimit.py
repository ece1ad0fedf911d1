"""The anonymous rate limit: token buckets against a clock of the test's own, and the
middleware's 429 driven with ASGI messages (over loopback: tests/system/api/test_rate_limit.py)."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest

from gonio.api import ratelimit
from gonio.api.auth import AccessPolicy, ApiKeyring
from gonio.api.ratelimit import AnonymousRateLimit, TokenBuckets


def test_token_bucket_refills_at_its_rate() -> None:
    now = [100.0]
    buckets = TokenBuckets(rate_per_s=2.0, burst=2, clock=lambda: now[0])
    assert buckets.take("a") == 0 and buckets.take("a") == 0
    assert buckets.take("a") == pytest.approx(0.5)  # one token every 1/2 s
    assert buckets.take("b") == 0  # per client
    now[0] += 0.25
    assert buckets.take("a") == pytest.approx(0.25)
    now[0] += 0.25
    assert buckets.take("a") == 0
    now[0] += 60  # a long pause fills the bucket to its size, not beyond
    assert [buckets.take("a") for _ in range(3)] == [0, 0, pytest.approx(0.5)]


@pytest.mark.parametrize(("rate", "burst", "message"), [
    (float("nan"), 1, "rate_per_s must be a positive number, got nan"),
    (float("inf"), 1, "rate_per_s must be a positive number, got inf"),
    (0.0, 1, "rate_per_s must be a positive number, got 0.0"),
    (1.0, 0, "burst must be at least 1, got 0"),
])
def test_an_impossible_bucket_is_refused(rate: float, burst: int, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TokenBuckets(rate_per_s=rate, burst=burst)


def test_idle_clients_are_forgotten_first_when_the_table_is_full(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ratelimit, "MAX_CLIENTS", 3)
    now = [0.0]
    buckets = TokenBuckets(rate_per_s=1.0, burst=2, clock=lambda: now[0])
    for name in ("idle", "busy1", "busy2"):
        buckets.take(name)
    buckets.take("busy1")
    buckets.take("busy2")
    now[0] += 1.0  # "idle" is full again (1 + 1 token); the busy ones hold 1
    buckets.take("new")
    assert set(buckets._buckets) == {"busy1", "busy2", "new"}
    buckets.take("newer")  # nobody full: the oldest goes
    assert set(buckets._buckets) == {"busy2", "new", "newer"}


KEY = "k" * 32


def hit(mw: AnonymousRateLimit, key: str | None = None,
        client: tuple[str, int] | None = ("10.0.0.7", 5)) -> tuple[int, dict[bytes, bytes], str]:
    sent: list[dict[str, Any]] = []

    async def send(m: dict[str, Any]) -> None:
        sent.append(m)

    headers = [(b"x-api-key", key.encode())] if key else []
    asyncio.run(mw({"type": "http", "headers": headers, "client": client}, None, send))
    body = sent[1]["body"]
    return sent[0]["status"], dict(sent[0]["headers"]), json.loads(body)["detail"] if body else ""


async def ok(scope: Any, receive: Any, send: Any) -> None:
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b""})


@pytest.fixture
def no_tarpit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ratelimit, "TARPIT_S", 0.0)


@pytest.mark.usefixtures("no_tarpit")
def test_beyond_the_burst_an_anonymous_client_gets_429_with_retry_after() -> None:
    mw = AnonymousRateLimit(ok, AccessPolicy(ApiKeyring({"lab": KEY})), rate_per_s=0.1, burst=2)
    assert [hit(mw)[0] for _ in range(2)] == [200, 200]
    status, headers, detail = hit(mw)
    assert status == 429
    assert headers[b"retry-after"] == b"10"  # one token per 10 s, none left
    assert "too many requests from 10.0.0.7 without an API key (at most 0.1 per second, " \
           "2 at once)" in detail and "X-API-Key" in detail
    assert hit(mw, client=("10.0.0.8", 5))[0] == 200  # another address has its own bucket
    assert hit(mw, key=KEY)[0] == 200  # a key holder is not limited
    assert hit(mw, key="w" * 32)[0] == 429  # a wrong key counts as none


@pytest.mark.usefixtures("no_tarpit")
def test_clients_without_an_address_share_one_bucket() -> None:
    mw = AnonymousRateLimit(ok, AccessPolicy(), rate_per_s=0.1, burst=1)
    assert hit(mw, client=None)[0] == 200
    assert "from unknown" in hit(mw, client=None)[2]


def test_rate_zero_turns_the_limit_off() -> None:
    mw = AnonymousRateLimit(ok, AccessPolicy(), rate_per_s=0, burst=1)
    assert mw.buckets is None
    assert {hit(mw)[0] for _ in range(5)} == {200}
