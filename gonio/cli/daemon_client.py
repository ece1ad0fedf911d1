"""Talking to a running daemon from the command line (``--daemon URL``).

A rig has one owner at a time (:mod:`gonio.locks`): while a daemon owns it, ``gonio stage`` and
``gonio scan`` act on it only through that daemon's REST API. The API key comes from
``--api-key`` or the environment variable ``GONIO_API_KEY`` (the environment keeps it out of
the process list and shell history).
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from gonio.cli import UsageError

API_KEY_ENV = "GONIO_API_KEY"


class DaemonRefused(UsageError):
    """The daemon answered with an error; ``status`` is the HTTP status, the message its reason."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


class DaemonUnreachable(UsageError):
    """The daemon did not answer (not running, killed, wrong address)."""


def add_daemon_options(parser: argparse.ArgumentParser) -> None:
    """``--daemon URL`` (into a mutually exclusive group the caller made) and ``--api-key``."""
    parser.add_argument("--api-key", default=None, metavar="KEY",
                        help=f"API key for --daemon (default: ${API_KEY_ENV}); reads need none "
                             "unless the daemon says so")


class DaemonClient:
    """A small synchronous client of one daemon's API, with errors written for the user.

    Parameters
    ----------
    url : the daemon's address, e.g. ``http://127.0.0.1:8600``
    api_key : sent as ``X-API-Key``; None reads ``GONIO_API_KEY``
    timeout_s : per request, seconds
    """

    def __init__(self, url: str, api_key: str | None = None, timeout_s: float = 30.0) -> None:
        import httpx

        if not url.startswith(("http://", "https://")):
            raise UsageError(f"--daemon {url!r}: give the daemon's address, e.g. "
                             "http://127.0.0.1:8600")
        self.url = url.rstrip("/")
        key = api_key if api_key is not None else os.environ.get(API_KEY_ENV)
        headers = {"X-API-Key": key} if key else {}
        self._http = httpx.Client(base_url=self.url, headers=headers, timeout=timeout_s)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> DaemonClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def request(self, method: str, path: str, **kwargs: Any) -> Any:
        """The response of ``method path`` (JSON decoded, or the response for binary bodies).

        Raises
        ------
        DaemonUnreachable
            The daemon cannot be reached.
        DaemonRefused
            It answered 4xx/5xx; the message is its ``detail``, with what to do for a key.
        """
        import httpx

        try:
            r = self._http.request(method, path, **kwargs)
        except httpx.HTTPError as exc:
            raise DaemonUnreachable(f"cannot reach the daemon at {self.url} ({exc}); is it running "
                             "(gonio serve), and is the address right?") from None
        if r.status_code >= 400:
            try:
                detail = r.json().get("detail", r.text)
            except ValueError:
                detail = r.text
            if not isinstance(detail, str):
                detail = "; ".join(str(d.get("msg", d)) if isinstance(d, dict) else str(d)
                                   for d in detail)
            if r.status_code in (401, 403):
                detail += f" (give a key with --api-key or ${API_KEY_ENV})"
            raise DaemonRefused(r.status_code, f"the daemon at {self.url} refused: {detail}")
        if r.headers.get("content-type", "").startswith("application/json"):
            return r.json()
        return r
