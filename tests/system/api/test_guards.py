"""Keys, the maintenance lock and the body limit, on a tiny app behind a real uvicorn server."""

from __future__ import annotations

import logging
import secrets
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated

import httpx
import pytest
from fastapi import Depends, FastAPI

from gonio.api.auth import (
    AccessPolicy,
    Caller,
    require_key_when_configured,
    require_read_access,
    require_write_key,
)
from gonio.api.maintenance import refuse_while_locked
from gonio.api.settings import ApiSettings, install
from gonio.apikeys import ApiKeyring, KeyringError
from tests.system.api.live_server import live_server

pytestmark = pytest.mark.system

KEY = secrets.token_urlsafe(24)
OTHER_KEY = secrets.token_urlsafe(24)
LIMIT = 4096


def tiny_app(
    tmp: Path, read_requires_key: bool = False, keys: dict[str, str] | None = None
) -> FastAPI:
    app = FastAPI()
    keyring = ApiKeyring({"alice": KEY} if keys is None else keys)
    install(
        app,
        ApiSettings(
            access=AccessPolicy(keyring, read_requires_key=read_requires_key),
            data_dir=tmp,
            max_body_bytes=LIMIT,
        ),
    )

    @app.get("/read")
    async def read(
        caller: Annotated[Caller, Depends(require_read_access)],
    ) -> dict[str, str | None]:
        return {"who": caller.key_name}

    @app.post("/write", dependencies=[Depends(refuse_while_locked)])
    async def write(
        body: dict[str, object], caller: Annotated[Caller, Depends(require_write_key)]
    ) -> dict[str, object]:
        return {"who": caller.key_name, "n": len(body)}

    @app.post("/compute")
    async def compute(
        caller: Annotated[Caller, Depends(require_key_when_configured)],
    ) -> dict[str, str | None]:
        return {"who": caller.key_name}

    return app


@pytest.fixture
def server(tmp_path: Path) -> Iterator[tuple[str, FastAPI]]:
    app = tiny_app(tmp_path)
    with live_server(app) as url:
        yield url, app


def test_write_needs_key_missing_401_wrong_403_right_200(server: tuple[str, FastAPI]) -> None:
    url, _ = server
    r = httpx.post(f"{url}/write", json={"a": 1})
    assert r.status_code == 401
    assert "X-API-Key" in r.json()["detail"]
    r = httpx.post(f"{url}/write", json={"a": 1}, headers={"X-API-Key": OTHER_KEY})
    assert r.status_code == 403
    # A key differing only in its last character is refused too.
    r = httpx.post(f"{url}/write", json={"a": 1}, headers={"X-API-Key": KEY[:-1] + "!"})
    assert r.status_code == 403
    r = httpx.post(f"{url}/write", json={"a": 1}, headers={"X-API-Key": KEY})
    assert r.status_code == 200
    assert r.json() == {"who": "alice", "n": 1}


def test_reads_open_by_default_but_wrong_key_still_refused(server: tuple[str, FastAPI]) -> None:
    url, _ = server
    assert httpx.get(f"{url}/read").json() == {"who": None}
    assert httpx.get(f"{url}/read", headers={"X-API-Key": KEY}).json() == {"who": "alice"}
    assert httpx.get(f"{url}/read", headers={"X-API-Key": OTHER_KEY}).status_code == 403


def test_reads_keyed_when_configured(tmp_path: Path) -> None:
    with live_server(tiny_app(tmp_path, read_requires_key=True)) as url:
        assert httpx.get(f"{url}/read").status_code == 401
        assert httpx.get(f"{url}/read", headers={"X-API-Key": KEY}).status_code == 200


def test_no_keys_configured_means_read_only_with_a_clear_message(tmp_path: Path) -> None:
    with live_server(tiny_app(tmp_path, keys={})) as url:
        r = httpx.post(f"{url}/write", json={})
        assert r.status_code == 403
        assert "no API keys configured" in r.json()["detail"]
        assert httpx.get(f"{url}/read").status_code == 200


def test_maintenance_lock_refuses_writes_with_423(server: tuple[str, FastAPI]) -> None:
    url, app = server
    app.state.maintenance.lock("replacing lamp L2", by="alice")
    r = httpx.post(f"{url}/write", json={}, headers={"X-API-Key": KEY})
    assert r.status_code == 423
    assert "replacing lamp L2" in r.json()["detail"]
    assert httpx.get(f"{url}/read").status_code == 200  # reads stay available
    app.state.maintenance.unlock()
    assert httpx.post(f"{url}/write", json={}, headers={"X-API-Key": KEY}).status_code == 200


def test_hand_made_lock_file_locks_too(server: tuple[str, FastAPI], tmp_path: Path) -> None:
    url, _ = server
    (tmp_path / "MAINTENANCE").write_text("realigning the stage\n")
    r = httpx.post(f"{url}/write", json={}, headers={"X-API-Key": KEY})
    assert r.status_code == 423
    assert "realigning the stage" in r.json()["detail"]


def test_oversize_body_413_with_and_without_content_length(server: tuple[str, FastAPI]) -> None:
    url, _ = server
    big = b'{"a": "' + b"x" * (LIMIT + 10) + b'"}'
    headers = {"X-API-Key": KEY, "content-type": "application/json"}
    r = httpx.post(f"{url}/write", content=big, headers=headers)
    assert r.status_code == 413
    assert "max_body_bytes" in r.json()["detail"]

    def chunks() -> Iterator[bytes]:  # chunked transfer: no Content-Length to look at
        for i in range(0, len(big), 1000):
            yield big[i : i + 1000]

    r = httpx.post(f"{url}/write", content=chunks(), headers=headers)
    assert r.status_code == 413
    # Just under the limit still works, so the limit is not off by a lot.
    ok = b'{"a": "' + b"x" * (LIMIT - 20) + b'"}'
    r = httpx.post(f"{url}/write", content=ok, headers=headers)
    assert r.status_code == 200


def test_lying_content_length_is_refused_before_reading(server: tuple[str, FastAPI]) -> None:
    url, _ = server
    host, port = url.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=5) as s:
        s.sendall(
            b"POST /write HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            + f"X-API-Key: {KEY}\r\nContent-Length: {10 * LIMIT}\r\n\r\n".encode()
        )
        reply = s.recv(4096).decode()
    assert reply.startswith("HTTP/1.1 413")


def test_keys_never_appear_in_logs(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    with live_server(tiny_app(tmp_path), log_level="debug") as url:
        httpx.post(f"{url}/write", json={}, headers={"X-API-Key": KEY})
        httpx.post(f"{url}/write", json={}, headers={"X-API-Key": OTHER_KEY})
        httpx.get(f"{url}/read", headers={"X-API-Key": OTHER_KEY})
    text = "\n".join(r.getMessage() for r in caplog.records)
    assert "POST /write" in text  # the access log was captured, so the check below means something
    assert KEY not in text
    assert OTHER_KEY not in text


def test_keyring_refuses_short_keys_and_matches_only_exact_keys() -> None:
    with pytest.raises(KeyringError, match="at least 16"):
        ApiKeyring({"bob": "short"})
    ring = ApiKeyring({"alice": KEY, "bob": OTHER_KEY})
    assert ring.identify(KEY) == "alice"
    assert ring.identify(OTHER_KEY) == "bob"
    assert ring.identify(KEY + "x") is None
    assert ring.identify("") is None
    assert ring.identify(None) is None


def test_computing_reads_need_a_key_when_the_daemon_has_keys(
    server: tuple[str, FastAPI], tmp_path: Path
) -> None:
    # The dry run changes nothing but computes: with keys configured, anonymous callers get 401.
    url, app = server
    assert httpx.post(f"{url}/compute").status_code == 401
    assert httpx.post(f"{url}/compute", headers={"X-API-Key": OTHER_KEY}).status_code == 403
    assert httpx.post(f"{url}/compute", headers={"X-API-Key": KEY}).json() == {"who": "alice"}
    # Not a change: the maintenance lock does not stop it.
    app.state.maintenance.lock("replacing lamp L2", by="alice")
    assert httpx.post(f"{url}/compute", headers={"X-API-Key": KEY}).status_code == 200
    app.state.maintenance.unlock()
    # A read-only daemon (no keys at all) keeps it open: nobody can fill its queue anyway.
    with live_server(tiny_app(tmp_path / "ro", keys={})) as ro:
        assert httpx.post(f"{ro}/compute").json() == {"who": None}
