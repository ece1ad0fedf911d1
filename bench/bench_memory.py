"""Daemon memory over consecutive scans: does the resident set level off after the first?

Starts ``gonio serve --sim --throwaway`` in a subprocess (its own interpreter: the RSS read is
the daemon's alone), waits for its start-up calibration, then runs ``--scans`` scans one after
the other through the API. After each scan it asks for what the lab page shows of a finished
job (metrics, preview, rendering, fit, polar plot, slice), then reads the daemon's resident set
(``VmRSS`` and its peak ``VmHWM`` from ``/proc/<pid>/status``, Linux). Prints one row per scan
and the growth after the first scan, against the target: within 10 % of the size after scan 1.

    .venv/bin/python bench/bench_memory.py [--scans 10] [--rotations 8] [--time-scale 20]
"""

from __future__ import annotations

import argparse
import os
import secrets
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

GONIO = [sys.executable, "-c", "from gonio.cli import main; raise SystemExit(main())"]
TARGET = 0.10
"""Allowed growth of the resident set after the first scan (fraction of its size then)."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def rss_mb(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of ``pid`` in MB (Linux ``/proc``)."""
    fields: dict[str, float] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            fields[key] = float(value.split()[0]) / 1024.0  # kB
    return fields["VmRSS"], fields["VmHWM"]


def wait_for(c: httpx.Client, job_id: int, states: set[str], timeout: float = 900) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r = c.get(f"/api/v1/jobs/{job_id}")
        if r.status_code == 200 and r.json()["state"] in states:
            return str(r.json()["state"])
        time.sleep(0.5)
    raise TimeoutError(f"job {job_id} not in {states} after {timeout} s")


def look_at(c: httpx.Client, job_id: int) -> None:
    """What the lab page asks for a finished job."""
    base = f"/api/v1/jobs/{job_id}"
    for path, params in ((f"{base}/metrics", {}), (f"{base}/preview.png", {}),
                         (f"{base}/render.png", {}), (f"{base}/fit", {}),
                         (f"{base}/polar", {"theta_i": 30, "phi_i": 0}),
                         (f"{base}/slice", {"theta_h": 30, "theta_d": 30, "phi_d": 90})):
        r = c.get(path, params=params)
        if r.status_code != 200:
            raise RuntimeError(f"GET {path}: {r.status_code} {r.text[:200]}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=10)
    ap.add_argument("--rotations", type=int, default=8)
    ap.add_argument("--time-scale", type=float, default=20.0)
    args = ap.parse_args(argv)

    key = secrets.token_hex(16)
    port = free_port()
    env = {**os.environ, "GONIO_API_KEYS": f"bench:{key}"}
    proc = subprocess.Popen([*GONIO, "serve", "--sim", "--throwaway", "--port", str(port),
                             "--time-scale", str(args.time_scale)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    rows: list[tuple[str, float, float, float]] = []
    try:
        with httpx.Client(base_url=url, headers={"X-API-Key": key}, timeout=120) as c:
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
            rows.append(("calibrated", *rss_mb(proc.pid), 0.0))
            for i in range(1, args.scans + 1):
                t0 = time.monotonic()
                plan: dict[str, Any] = {"kind": "uniform", "specimen": f"scan-{i}",
                                        "rotations": args.rotations}
                r = c.post("/api/v1/jobs", json={"plan": plan})
                r.raise_for_status()
                job = int(r.json()["id"])
                state = wait_for(c, job, {"completed", "failed", "aborted"})
                if state != "completed":
                    raise RuntimeError(f"scan {i} (job {job}) {state}")
                look_at(c, job)
                rows.append((f"scan {i}", *rss_mb(proc.pid), time.monotonic() - t0))
    finally:
        proc.terminate()
        proc.wait(60)

    first = rows[1][1]
    print(f"{'after':<12} {'RSS MB':>8} {'peak MB':>8} {'vs scan 1':>10} {'scan s':>7}")
    for name, rss, hwm, secs in rows:
        rel = f"{(rss - first) / first:+.1%}" if name.startswith("scan") else ""
        print(f"{name:<12} {rss:8.1f} {hwm:8.1f} {rel:>10} {secs:7.1f}")
    growth = (rows[-1][1] - first) / first
    ok = growth <= TARGET
    print(f"growth after scan 1: {growth:+.1%} (target <= {TARGET:.0%}): "
          f"{'met' if ok else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
