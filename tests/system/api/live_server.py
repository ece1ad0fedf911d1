"""A real uvicorn server on a free loopback port, run in a background thread.

Tests talk to it over real TCP with httpx (and a real browser), so the whole stack is exercised:
HTTP parsing, the ASGI middleware, streaming responses and the app's lifespan.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import uvicorn
from starlette.types import ASGIApp


@contextmanager
def live_server(
    app: ASGIApp, *, log_level: str = "warning", startup_timeout_s: float = 60.0,
    port: int = 0,
) -> Iterator[str]:
    """Serve ``app`` on ``127.0.0.1:<free port>``; yield its base URL (``http://127.0.0.1:N``).

    The socket is bound here (port 0) and handed to uvicorn, so there is no race between
    picking a port and binding it. The server stops (and the app's lifespan shuts down) when
    the context exits. ``port``: serve on that port instead, e.g. the one a stopped server
    used, as a restarted daemon does.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", port))
    port = sock.getsockname()[1]
    config = uvicorn.Config(
        app,
        log_level=log_level,
        # No logging config of uvicorn's own: records propagate to the root logger, where pytest
        # captures them (a test checks that API keys never show up in them).
        log_config=None,
        lifespan="on",
        # Event streams never end by themselves; give them a moment, then cancel them.
        timeout_graceful_shutdown=2,
    )
    server = uvicorn.Server(config)
    errors: list[BaseException] = []

    def run() -> None:
        try:
            server.run(sockets=[sock])
        except BaseException as exc:  # surfaced in the test thread below
            errors.append(exc)

    thread = threading.Thread(target=run, name=f"uvicorn-{port}", daemon=True)
    thread.start()
    deadline = time.monotonic() + startup_timeout_s
    while not server.started:
        if errors or not thread.is_alive():
            sock.close()
            raise RuntimeError(f"test server did not start: {errors or 'thread exited'}")
        if time.monotonic() > deadline:
            server.should_exit = True
            raise TimeoutError(f"test server did not start within {startup_timeout_s} s")
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=30)
        sock.close()
        if thread.is_alive():
            logging.getLogger(__name__).warning("uvicorn thread still alive after shutdown")
