"""API keys at the HTTP door: what each guard asks for, and keys in URLs refused (the keys
themselves, digests and the keyring: tests/unit/test_apikeys.py)."""

from __future__ import annotations

import asyncio
import json
from types import SimpleNamespace
from typing import Any

import pytest
from fastapi import HTTPException
from starlette.requests import Request

from gonio.api.auth import (
    AccessPolicy,
    Caller,
    RefuseKeysInUrl,
    require_key_when_configured,
    require_read_access,
    require_write_key,
)
from gonio.apikeys import ApiKeyring

ALICE = "a" * 16
BOB = "b0b-" + "x" * 28


def request(policy: AccessPolicy) -> Request:
    app = SimpleNamespace(state=SimpleNamespace(access_policy=policy))
    return Request({"type": "http", "app": app, "headers": [], "state": {}})


def call(guard: Any, policy: AccessPolicy, key: str | None) -> Caller | int:
    """The guard's caller, or the status it refuses with."""
    try:
        return asyncio.run(guard(request(policy), key))  # type: ignore[no-any-return]
    except HTTPException as exc:
        return exc.status_code


KEYED = AccessPolicy(ApiKeyring({"alice": ALICE}))
CLOSED = AccessPolicy(ApiKeyring({"alice": ALICE}), read_requires_key=True)
NO_KEYS = AccessPolicy()


@pytest.mark.parametrize(("guard", "policy", "key", "expected"), [
    # writes: a valid key, always
    (require_write_key, KEYED, ALICE, Caller("alice")),
    (require_write_key, KEYED, None, 401),
    (require_write_key, KEYED, "", 401),
    (require_write_key, KEYED, BOB, 403),
    (require_write_key, NO_KEYS, None, 403),  # read-only daemon: no key can work
    # reads: open unless configured, but a wrong key is refused anyway
    (require_read_access, KEYED, None, Caller(None)),
    (require_read_access, KEYED, BOB, 403),
    (require_read_access, CLOSED, None, 401),
    (require_read_access, CLOSED, ALICE, Caller("alice")),
    # reads that compute: keyed whenever the daemon has keys
    (require_key_when_configured, KEYED, None, 401),
    (require_key_when_configured, NO_KEYS, None, Caller(None)),
    (require_key_when_configured, KEYED, ALICE, Caller("alice")),
])
def test_each_guard_asks_for_what_docs_api_says(guard: Any, policy: AccessPolicy,
                                                key: str | None, expected: object) -> None:
    assert call(guard, policy, key) == expected


def test_the_refusals_say_what_to_do() -> None:
    with pytest.raises(HTTPException, match="needs an API key in the X-API-Key header"):
        asyncio.run(require_write_key(request(KEYED), None))
    with pytest.raises(HTTPException, match="is not valid for this daemon"):
        asyncio.run(require_write_key(request(KEYED), BOB))
    with pytest.raises(HTTPException, match="no API keys configured, so it is read-only"):
        asyncio.run(require_write_key(request(NO_KEYS), None))


def test_the_key_name_is_kept_on_the_request() -> None:
    req = request(KEYED)
    asyncio.run(require_write_key(req, ALICE))
    assert req.state.key_name == "alice"


def refuse(query: bytes) -> tuple[int, str]:
    sent: list[dict[str, Any]] = []

    async def app(scope: Any, receive: Any, send: Any) -> None:
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b""})

    async def send(m: dict[str, Any]) -> None:
        sent.append(m)

    asyncio.run(RefuseKeysInUrl(app)({"type": "http", "query_string": query}, None, send))
    body = sent[1]["body"]
    return sent[0]["status"], json.loads(body)["detail"] if body else ""


@pytest.mark.parametrize("query", [b"api_key=x", b"since=1&X-API-Key=x", b"token=",
                                   b"client_secret=s", b"password=p", b"Authorization=b"])
def test_a_key_in_the_url_is_refused(query: bytes) -> None:
    status, detail = refuse(query)
    assert status == 400
    assert "Send the key in the X-API-Key header instead" in detail
    assert "treat a key that was sent in a URL as exposed" in detail


@pytest.mark.parametrize("query", [b"", b"since=3", b"business=1", b"name=key"])
def test_other_queries_pass(query: bytes) -> None:
    assert refuse(query)[0] == 200
