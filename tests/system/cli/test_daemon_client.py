"""The command line's client of a daemon, against a small app on a real loopback server:
JSON and binary answers, every kind of refusal worded for the user, an unreachable daemon, and
the key taken from the environment. Against a real daemon: tests/system/api/test_stage.py and
test_cli_daemon.py."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
from fastapi import FastAPI, Header, HTTPException
from fastapi.responses import PlainTextResponse, Response

from gonio.cli import UsageError
from gonio.cli.daemon_client import API_KEY_ENV, DaemonClient, DaemonRefused
from tests.system.api.live_server import live_server


def _app() -> FastAPI:
    app = FastAPI()

    @app.get("/key")
    def key(x_api_key: str | None = Header(None)) -> dict[str, str | None]:
        return {"key": x_api_key}

    @app.get("/png")
    def png() -> Response:
        return Response(b"\x89PNG\r\n", media_type="image/png")

    @app.post("/locked")
    def locked() -> None:
        raise HTTPException(401, "this request needs an API key in the X-API-Key header")

    @app.post("/typed")
    def typed(n: int) -> dict[str, int]:
        return {"n": n}

    @app.get("/broken")
    def broken() -> PlainTextResponse:
        return PlainTextResponse("proxy error", status_code=502)

    return app


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    with live_server(_app()) as u:
        yield u + "/"  # a trailing slash as a user may type it


def test_json_and_binary_answers(url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(API_KEY_ENV, raising=False)
    with DaemonClient(url) as c:
        assert c.url == url.rstrip("/")
        assert c.request("GET", "/key") == {"key": None}
        assert c.request("GET", "/png").content == b"\x89PNG\r\n"


def test_the_key_comes_from_the_option_or_the_environment(
        url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(API_KEY_ENV, "from-env-" + "x" * 16)
    with DaemonClient(url) as c:
        assert c.request("GET", "/key") == {"key": "from-env-" + "x" * 16}
    with DaemonClient(url, api_key="given-" + "y" * 16) as c:
        assert c.request("GET", "/key") == {"key": "given-" + "y" * 16}


def test_a_refusal_carries_the_status_and_says_how_to_give_a_key(url: str) -> None:
    with DaemonClient(url) as c, pytest.raises(DaemonRefused) as exc:
        c.request("POST", "/locked")
    assert exc.value.status == 401
    assert str(exc.value) == (
        f"the daemon at {c.url} refused: this request needs an API key in the X-API-Key "
        f"header (give a key with --api-key or ${API_KEY_ENV})")


def test_a_validation_refusal_lists_its_messages(url: str) -> None:
    with DaemonClient(url) as c, pytest.raises(DaemonRefused) as exc:
        c.request("POST", "/typed", params={"n": "many"})
    assert exc.value.status == 422
    assert "refused: Input should be a valid integer" in str(exc.value)


def test_a_non_json_error_is_shown_as_text(url: str) -> None:
    with DaemonClient(url) as c, pytest.raises(DaemonRefused, match=r"refused: proxy error$"):
        c.request("GET", "/broken")


def test_an_unreachable_daemon_says_what_to_check() -> None:
    with socket.socket() as s:  # a port nothing listens on once closed
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with DaemonClient(f"http://127.0.0.1:{port}", timeout_s=5) as c, \
            pytest.raises(UsageError, match=r"cannot reach the daemon at http://127\.0\.0\.1:"
                                            r"\d+ .*is it running \(gonio serve\)"):
        c.request("GET", "/health")


@pytest.mark.parametrize("bad", ["127.0.0.1:8600", "localhost", "ftp://x"])
def test_an_address_without_its_scheme_is_refused(bad: str) -> None:
    with pytest.raises(UsageError, match=r"give the daemon's address, e\.g\. http://"):
        DaemonClient(bad)
