"""BodySizeLimit as an ASGI middleware, driven with the messages of the ASGI HTTP spec.

Over loopback the same refusals are seen in tests/system/api/test_bad_input.py; here every
branch (declared or chunked, drained or closed at once, a client that hangs up) is reached
without a server.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest

from gonio.api.limits import DRAIN_FACTOR, BodySizeLimit

Message = dict[str, Any]


class Recorder:
    """The inner app: records the body it read, answers 200."""

    def __init__(self) -> None:
        self.body: bytes | None = None
        self.receive: Any = None

    async def __call__(self, scope: Message, receive: Any, send: Any) -> None:
        self.receive = receive
        if scope["type"] == "http" and scope["method"] not in ("GET", "HEAD"):
            parts = []
            while True:
                m = await receive()
                parts.append(m.get("body", b""))
                if not m.get("more_body", False):
                    break
            self.body = b"".join(parts)
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})


def run(mw: BodySizeLimit, messages: list[Message], method: str = "POST",
        length: int | None = None) -> tuple[list[Message], int]:
    """Call the middleware; returns what it sent and how many messages it received."""
    headers = [(b"content-length", str(length).encode())] if length is not None else []
    scope = {"type": "http", "method": method, "headers": headers}
    queue = list(messages)
    sent: list[Message] = []
    taken = 0

    async def receive() -> Message:
        nonlocal taken
        taken += 1
        return queue.pop(0) if queue else {"type": "http.disconnect"}

    async def send(m: Message) -> None:
        sent.append(m)

    asyncio.run(mw(scope, receive, send))
    return sent, taken


def chunks(*sizes: int) -> list[Message]:
    return [{"type": "http.request", "body": b"x" * n, "more_body": i < len(sizes) - 1}
            for i, n in enumerate(sizes)]


def refusal(sent: list[Message]) -> tuple[int, dict[bytes, bytes], str]:
    start, body = sent
    return start["status"], dict(start["headers"]), json.loads(body["body"])["detail"]


def test_a_body_within_the_limit_reaches_the_app_whole() -> None:
    app = Recorder()
    sent, _ = run(BodySizeLimit(app, max_bytes=10), chunks(4, 6), length=10)
    assert app.body == b"x" * 10
    assert sent[0]["status"] == 200


def test_a_declared_oversize_body_is_drained_then_refused() -> None:
    app = Recorder()
    sent, taken = run(BodySizeLimit(app, max_bytes=10), chunks(6, 6), length=12)
    status, headers, detail = refusal(sent)
    assert status == 413 and app.body is None
    assert taken == 2  # both chunks read (12 <= 8 x 10), so the client sees the answer
    assert headers[b"connection"] == b"close"
    assert "(12 > 10 bytes)" in detail and "[limits] max_body_bytes" in detail


def test_a_body_declared_far_over_the_limit_is_refused_unread() -> None:
    sent, taken = run(BodySizeLimit(Recorder(), max_bytes=10), chunks(100),
                      length=DRAIN_FACTOR * 10 + 1)
    assert refusal(sent)[0] == 413
    assert taken == 0


def test_a_chunked_body_without_a_length_is_counted() -> None:
    app = Recorder()
    sent, _ = run(BodySizeLimit(app, max_bytes=10), chunks(5, 5, 5))
    status, _, detail = refusal(sent)
    assert status == 413 and app.body is None
    assert "(15 > 10 bytes)" in detail


def test_a_client_that_hangs_up_mid_body_gets_nothing() -> None:
    app = Recorder()
    sent, _ = run(BodySizeLimit(app, max_bytes=10),
                  [{"type": "http.request", "body": b"xx", "more_body": True},
                   {"type": "http.disconnect"}])
    assert sent == [] and app.body is None


def test_a_read_without_a_body_keeps_its_receive() -> None:
    """The event stream needs the disconnect message: a GET is passed through untouched."""
    app = Recorder()
    sent, taken = run(BodySizeLimit(app, max_bytes=10), [], method="GET")
    assert sent[0]["status"] == 200 and taken == 0
    assert app.receive.__name__ == "receive"  # the server's own, not the middleware's replay


def test_other_scopes_pass_through() -> None:
    seen: list[str] = []

    async def app(scope: Message, receive: Any, send: Any) -> None:
        seen.append(scope["type"])

    asyncio.run(BodySizeLimit(app, 10)({"type": "lifespan"}, None, None))  # type: ignore[arg-type]
    assert seen == ["lifespan"]


def test_a_bad_content_length_is_ignored_and_the_body_counted() -> None:
    app = Recorder()
    mw = BodySizeLimit(app, max_bytes=10)
    scope = {"type": "http", "method": "POST", "headers": [(b"Content-Length", b"lots")]}
    sent: list[Message] = []
    queue = chunks(11)

    async def receive() -> Message:
        return queue.pop(0)

    async def send(m: Message) -> None:
        sent.append(m)

    asyncio.run(mw(scope, receive, send))
    assert refusal(sent)[0] == 413


@pytest.mark.parametrize("bad", [0, -5])
def test_a_limit_below_one_byte_is_refused(bad: int) -> None:
    with pytest.raises(ValueError, match=f"max_body_bytes must be at least 1, got {bad}"):
        BodySizeLimit(Recorder(), bad)
