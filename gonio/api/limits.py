"""The daemon's limits on requests: body size (plain ASGI middleware) and what a request may ask.

Bodies are buffered here up to the limit, and a request whose body is larger is answered with 413
before the application sees a byte of it. Checking only ``Content-Length`` is not enough: a
chunked upload has none. Buffering is fine because every gonio request body is a small JSON
document (a scan request, a design run); the limit is what keeps it small.
"""

from __future__ import annotations

import json

from starlette.types import ASGIApp, Message, Receive, Scope, Send

DEFAULT_MAX_BODY_BYTES = 1 << 20
"""1 MiB: a scan plan with thousands of explicit angles is still well under 100 kB."""

DRAIN_FACTOR = 8
"""An oversize body up to this many times the limit is read and discarded before the 413, so
the client (still sending) receives the answer instead of a connection reset. Beyond that
the 413 goes out at once and the connection is closed: reading more would be the attack."""


class LimitExceeded(ValueError):
    """A request asks for more than this daemon's ``[limits]`` allow (for example a design
    time limit above ``design_time_limit_s``); the message names the limit and how to raise it."""


class BodySizeLimit:
    """Refuse request bodies larger than ``max_bytes`` with 413 Payload Too Large.

    Parameters
    ----------
    app : ASGI application
    max_bytes : int
        Largest accepted body, bytes.
    """

    def __init__(self, app: ASGIApp, max_bytes: int = DEFAULT_MAX_BODY_BYTES) -> None:
        if max_bytes < 1:
            raise ValueError(f"max_body_bytes must be at least 1, got {max_bytes}")
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = _content_length(scope)
        if declared is not None and declared > self.max_bytes:
            if declared <= DRAIN_FACTOR * self.max_bytes:
                await self._drain(receive, 0)
            await self._refuse(send, declared)
            return
        if scope["method"] in ("GET", "HEAD", "OPTIONS") and not declared:
            # No body to bound; leave ``receive`` alone so disconnects still reach streaming
            # responses (the event stream relies on them).
            await self.app(scope, receive, send)
            return

        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_bytes:
                if message.get("more_body", False):
                    size = await self._drain(receive, size)
                await self._refuse(send, size)
                return
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)

    async def _drain(self, receive: Receive, size: int) -> int:
        """Read and drop the rest of the body, up to the drain cap; return the bytes seen."""
        cap = DRAIN_FACTOR * self.max_bytes
        while size <= cap:
            message = await receive()
            if message["type"] == "http.disconnect":
                break
            size += len(message.get("body", b""))
            if not message.get("more_body", False):
                break
        return size

    async def _refuse(self, send: Send, size: int) -> None:
        detail = (
            f"request body is larger than this daemon accepts ({size} > {self.max_bytes} bytes); "
            "send a smaller request (scan plans are small JSON documents) or raise "
            "[limits] max_body_bytes in the daemon config"
        )
        payload = json.dumps({"detail": detail}).encode()
        await send(
            {
                "type": "http.response.start",
                "status": 413,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(payload)).encode()),
                    # The rest of the body was not read; the connection cannot be reused.
                    (b"connection", b"close"),
                ],
            }
        )
        await send({"type": "http.response.body", "body": payload})


def _content_length(scope: Scope) -> int | None:
    headers: list[tuple[bytes, bytes]] = scope.get("headers", [])
    for name, value in headers:
        if name.lower() == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None

