"""What a finished result's views cost the daemon, asked for twice: wall and CPU per request.

Starts ``gonio serve --sim --throwaway --no-export-fits`` in a subprocess (its own interpreter,
so the CPU read from ``/proc/<pid>/stat`` is the daemon's alone, Linux), runs one scan through
the API, then asks for each view the lab page shows of it twice in a row: the fit plot's
curves (``/fit``), the polar plot's (``/polar``), the rendering and the preview. The first
request of a view reads and computes; the second is what every later look at the same job
costs (the result views' cache, gonio/result_cache.py). Then a second scan's views are asked
for all at once, from four threads (fit, polar, preview, slice; the lab page asks for several
views of a job together): the row ``together`` is their wall time and the daemon's CPU for all
four.
Prints one row per request.

    .venv/bin/python bench/bench_result_views.py [--material NAME] [--rotations 8]

``--material yellow-plastic`` scans a spectral specimen: 31-band sensors, so the result's
table is 31 channels (the largest result a lab's views read).
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from simdaemon import scan, sim_daemon


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid``, all its threads (``/proc/<pid>/stat``)."""
    # The command name (field 2) is in parentheses and may hold spaces: split after it.
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--material", default=None, help="simulated material (gonio serve --sim)")
    ap.add_argument("--rotations", type=int, default=8)
    ap.add_argument("--time-scale", type=float, default=20.0)
    args = ap.parse_args(argv)

    extra = ["--no-export-fits", *(["--material", args.material] if args.material else [])]
    rows: list[tuple[str, int, float, float, int]] = []
    with sim_daemon(extra, args.time_scale) as (proc, c):
        job = scan(c, args.rotations)
        base = f"/api/v1/jobs/{job}"
        views = ((f"{base}/fit", {}), (f"{base}/polar", {"theta_i": 30, "phi_i": 0}),
                 (f"{base}/render.png", {}), (f"{base}/preview.png", {}))
        for path, params in views:
            for n in (1, 2):
                cpu0, t0 = cpu_s(proc.pid), time.perf_counter()
                r = c.get(path, params=params)
                wall, cpu = time.perf_counter() - t0, cpu_s(proc.pid) - cpu0
                if r.status_code != 200:
                    raise RuntimeError(f"GET {path}: {r.status_code} {r.text[:200]}")
                rows.append((path.rsplit("/", 1)[1], n, wall, cpu, len(r.content)))
        base = f"/api/v1/jobs/{scan(c, args.rotations)}"
        page = ((f"{base}/fit", {}), (f"{base}/polar", {"theta_i": 30, "phi_i": 0}),
                (f"{base}/preview.png", {}),
                (f"{base}/slice", {"theta_h": 30, "theta_d": 30, "phi_d": 90}))
        with ThreadPoolExecutor(len(page)) as pool:
            cpu0, t0 = cpu_s(proc.pid), time.perf_counter()
            got = list(pool.map(lambda v: c.get(v[0], params=v[1]), page))
            wall, cpu = time.perf_counter() - t0, cpu_s(proc.pid) - cpu0
        if any(r.status_code != 200 for r in got):
            raise RuntimeError(f"a view failed: {[r.status_code for r in got]}")
        rows.append(("together", 1, wall, cpu, sum(len(r.content) for r in got)))

    print(f"{'view':<12} {'request':>7} {'wall s':>8} {'CPU s':>7} {'bytes':>9}")
    for view, n, wall, cpu, size in rows:
        print(f"{view:<12} {n:>7} {wall:8.3f} {cpu:7.2f} {size:>9}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
