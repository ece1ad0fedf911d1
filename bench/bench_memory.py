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
import time
from pathlib import Path

import httpx
from simdaemon import scan, sim_daemon

TARGET = 0.10
"""Allowed growth of the resident set after the first scan (fraction of its size then)."""


def rss_mb(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of ``pid`` in MB (Linux ``/proc``)."""
    fields: dict[str, float] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            fields[key] = float(value.split()[0]) / 1024.0  # kB
    return fields["VmRSS"], fields["VmHWM"]


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

    rows: list[tuple[str, float, float, float]] = []
    with sim_daemon(time_scale=args.time_scale, timeout=120) as (proc, c):
        rows.append(("calibrated", *rss_mb(proc.pid), 0.0))
        for i in range(1, args.scans + 1):
            t0 = time.monotonic()
            job = scan(c, args.rotations, f"scan-{i}")
            look_at(c, job)
            rows.append((f"scan {i}", *rss_mb(proc.pid), time.monotonic() - t0))

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
