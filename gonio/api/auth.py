"""API keys: who may change the rig, and who may look at it.

Every mutating endpoint needs a valid key in the ``X-API-Key`` header. Read-only endpoints are
open unless the daemon is configured with ``read_requires_key``. A missing key is answered with
401, a wrong one with 403.

How keys are stored and compared (digests only, in constant time) is :mod:`gonio.apikeys`;
this module applies them to requests. A key is known to the rest of the daemon (logs, events)
only by its name, never by its value.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qsl

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import APIKeyHeader

from gonio.apikeys import ApiKeyring

API_KEY_HEADER = "X-API-Key"

# auto_error=False: we answer 401 ourselves with a message that says what to do.
_api_key_scheme = APIKeyHeader(
    name=API_KEY_HEADER,
    auto_error=False,
    description="API key of the daemon (see docs/api.md, 'Keys'). Required for every change.",
)


@dataclass(frozen=True)
class AccessPolicy:
    """Which requests need a key.

    Parameters
    ----------
    keyring : ApiKeyring
        Accepted keys. With no keys every mutation is refused (the daemon is read-only).
    read_requires_key : bool
        When True, read-only endpoints need a key too.
    """

    keyring: ApiKeyring = field(default_factory=lambda: ApiKeyring({}))
    read_requires_key: bool = False


@dataclass(frozen=True)
class Caller:
    """Who made a request: the key's name, or None for an anonymous read."""

    key_name: str | None


def _policy(request: Request) -> AccessPolicy:
    policy: AccessPolicy = request.app.state.access_policy
    return policy


def _check(request: Request, presented: str | None, required: bool) -> Caller:
    policy = _policy(request)
    if presented is None or presented == "":
        if not required:
            return Caller(None)
        if len(policy.keyring) == 0:
            # Say plainly that no key can work, instead of sending the user hunting for one.
            raise HTTPException(
                status.HTTP_403_FORBIDDEN,
                "this daemon has no API keys configured, so it is read-only; add a key to its "
                "keys file (see docs/install.md) and restart it",
            )
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            f"this request needs an API key in the {API_KEY_HEADER} header",
        )
    name = policy.keyring.identify(presented)
    if name is None:
        raise HTTPException(
            status.HTTP_403_FORBIDDEN,
            f"the API key in the {API_KEY_HEADER} header is not valid for this daemon",
        )
    request.state.key_name = name
    return Caller(name)


async def require_write_key(
    request: Request, presented: str | None = Depends(_api_key_scheme)
) -> Caller:
    """FastAPI dependency for mutating endpoints: a valid key, always."""
    return _check(request, presented, required=True)


async def require_read_access(
    request: Request, presented: str | None = Depends(_api_key_scheme)
) -> Caller:
    """FastAPI dependency for read-only endpoints: a valid key only when configured so.

    A key that is present but wrong is refused even where none is needed, so a client with a
    typo in its key learns about it on its first read rather than on its first write.
    """
    return _check(request, presented, required=_policy(request).read_requires_key)


async def require_key_when_configured(
    request: Request, presented: str | None = Depends(_api_key_scheme)
) -> Caller:
    """FastAPI dependency for reads that cost the daemon real work (the dry run).

    A dry run changes nothing, but it computes; an anonymous caller could repeat it to slow the
    scan. So it needs a key whenever the daemon has keys. A read-only daemon (no keys at all)
    keeps it open: there is nothing to protect a queue from that nobody can fill.
    """
    required = len(_policy(request).keyring) > 0 or _policy(request).read_requires_key
    return _check(request, presented, required=required)



class RefuseKeysInUrl:
    """ASGI middleware: **400** for any request with a key-like parameter in its query string.

    Keys travel in the ``X-API-Key`` header only. A key in the URL ends up in access logs,
    proxy logs and browser history, so such a request is refused on every route (open reads
    included, where it used to be ignored), whether or not the value is a valid key, and the
    message says where the key goes instead. The parameter names are those the access log
    redacts (:data:`gonio.logfilters.SECRET_PARAM`: ``key``, ``token``, ``secret``, ``passw``,
    ``auth``), so what is refused is also never written down.
    """

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] == "http" and scope.get("query_string"):
            name = _secret_query_param(scope["query_string"])
            if name is not None:
                detail = (
                    f"API keys are not accepted in the URL (query parameter {name!r}): URLs end "
                    f"up in logs. Send the key in the {API_KEY_HEADER} header instead, and "
                    "treat a key that was sent in a URL as exposed (replace it: gonio keys new)"
                )
                payload = json.dumps({"detail": detail}).encode()
                await send({"type": "http.response.start", "status": 400, "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(payload)).encode()),
                ]})
                await send({"type": "http.response.body", "body": payload})
                return
        await self.app(scope, receive, send)


def _secret_query_param(query: bytes) -> str | None:
    """The first query parameter whose name looks like a key, or None."""
    from gonio.logfilters import SECRET_PARAM

    text = query.decode("latin-1")
    for name, _value in parse_qsl(text, keep_blank_values=True):
        if SECRET_PARAM.search(name):
            return name[:40]
    return None
