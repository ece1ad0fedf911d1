"""A throwaway ``gonio serve --sim`` daemon on loopback for the benches that drive the API.

Shared by ``bench_memory.py`` and ``bench_result_views.py``: start the daemon with a fresh API
key on a free port, wait for it to answer and for its start-up calibration (job 1), and stop
it afterwards; run a uniform scan and wait for a job's state.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence

import httpx

GONIO = [sys.executable, "-c", "from gonio.cli import main; raise SystemExit(main())"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for(c: httpx.Client, job_id: int, states: set[str], timeout: float = 900) -> str:
    """Poll job ``job_id`` until its state is one of ``states``; that state."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r = c.get(f"/api/v1/jobs/{job_id}")
        if r.status_code == 200 and r.json()["state"] in states:
            return str(r.json()["state"])
        time.sleep(0.5)
    raise TimeoutError(f"job {job_id} not in {states} after {timeout} s")


def scan(c: httpx.Client, rotations: int, specimen: str = "bench") -> int:
    """Run one uniform scan through the API; its job id once it has completed."""
    r = c.post("/api/v1/jobs", json={"plan": {
        "kind": "uniform", "specimen": specimen, "rotations": rotations}})
    r.raise_for_status()
    job = int(r.json()["id"])
    if wait_for(c, job, {"completed", "failed", "aborted"}) != "completed":
        raise RuntimeError(f"the scan (job {job}) did not complete")
    return job


@contextlib.contextmanager
def sim_daemon(extra: Sequence[str] = (), time_scale: float = 20.0, timeout: float = 300
               ) -> Iterator[tuple[subprocess.Popen[bytes], httpx.Client]]:
    """``gonio serve --sim --throwaway`` with ``extra`` arguments: (process, client), the
    client holding the key, once the start-up calibration has completed."""
    key = secrets.token_hex(16)
    port = free_port()
    env = {**os.environ, "GONIO_API_KEYS": f"bench:{key}"}
    proc = subprocess.Popen([*GONIO, "serve", "--sim", "--throwaway", "--port", str(port),
                             "--time-scale", str(time_scale), *extra], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", headers={"X-API-Key": key},
                          timeout=timeout) as c:
            deadline = time.monotonic() + 120
            while True:
                try:
                    if c.get("/health").status_code == 200:
                        break
                except httpx.TransportError:
                    if time.monotonic() > deadline:
                        raise
                time.sleep(0.2)
            wait_for(c, 1, {"completed"})  # the start-up calibration
            yield proc, c
    finally:
        proc.terminate()
        proc.wait(60)
