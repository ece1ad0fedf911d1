"""A minimal server-sent-events reader for tests (httpx streaming)."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from typing import Any

import httpx


class EventCollector:
    """Reads ``/api/v1/events`` in a background thread and keeps every event it receives.

    Parameters
    ----------
    base_url : str
    since : int or None
        Sent as ``?since=``; None starts from "now".
    headers : dict
        Extra headers (``Last-Event-ID``, ``X-API-Key``).
    """

    def __init__(self, base_url: str, since: int | None = None,
                 headers: dict[str, str] | None = None) -> None:
        self.events: list[dict[str, Any]] = []
        self.ids: list[int] = []
        self.connected = threading.Event()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        params = {} if since is None else {"since": since}
        self._thread = threading.Thread(
            target=self._run, args=(base_url, params, headers or {}), daemon=True
        )
        self._thread.start()

    def _run(self, base_url: str, params: dict[str, int], headers: dict[str, str]) -> None:
        with httpx.Client(base_url=base_url, timeout=httpx.Timeout(5, read=60)) as client, \
                client.stream("GET", "/api/v1/events", params=params, headers=headers) as resp:
            resp.raise_for_status()
            self.connected.set()
            block: list[str] = []
            for line in resp.iter_lines():
                if self._stop.is_set():
                    return
                if line:
                    block.append(line)
                    continue
                data = [x[5:].strip() for x in block if x.startswith("data:")]
                ids = [int(x[3:].strip()) for x in block if x.startswith("id:")]
                block = []
                if data:
                    with self._lock:
                        self.events.append(json.loads("".join(data)))
                        self.ids.extend(ids)

    def wait_for(
        self, pred: Callable[[dict[str, Any]], bool], timeout: float = 120
    ) -> dict[str, Any]:
        """The first event matching ``pred``, waiting up to ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                for ev in self.events:
                    if pred(ev):
                        return ev
            time.sleep(0.05)
        with self._lock:
            seen = [(e["seq"], e["type"], e["job_id"]) for e in self.events[-10:]]
        raise TimeoutError(f"no matching event within {timeout} s; last events: {seen}")

    def snapshot(self) -> list[dict[str, Any]]:
        with self._lock:
            return list(self.events)

    def close(self) -> None:
        self._stop.set()
