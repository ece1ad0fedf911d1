"""One export's fits in the daemon and in a plain process: CPU, kernel CPU, page faults.

Starts ``gonio serve --sim --throwaway --no-export-fits`` in a subprocess (so the export has to
fit), runs one scan through the API and asks for its export (``GET /jobs/{id}/export``); reads
the daemon's CPU from ``/proc/<pid>/stat`` and, for the thread that did the work, user and
kernel CPU and minor page faults from ``/proc/<pid>/task`` (Linux). Then downloads the result
file and runs the same fits (:func:`gonio.export.result_fits`) in a fresh interpreter, in a
thread as in the daemon: as a plain process, and with the daemon's heap settings
(:func:`gonio.heap.bound_heap`: glibc's mmap threshold fixed at 128 KiB, two arenas). Prints
one row each. Same result, same fits: the rows differ only in where they run
(docs/notes/2026-11-27-export-cpu.md).

    nice -n 10 .venv/bin/python bench/bench_export_daemon.py [--format gltf] [--rotations 8]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from simdaemon import scan, sim_daemon

TICK = os.sysconf("SC_CLK_TCK")

CHILD = """
import json, resource, sys, threading, time
if sys.argv[2] == "bound":
    from gonio.heap import bound_heap
    bound_heap()
from gonio.export import result_fits
import gonio.export.judge, scipy.linalg, scipy.optimize  # loaded, as in the daemon
out = {}
def run():
    r0, w0 = resource.getrusage(resource.RUSAGE_THREAD), time.perf_counter()
    result_fits(sys.argv[1])
    r1, w1 = resource.getrusage(resource.RUSAGE_THREAD), time.perf_counter()
    out.update(wall=w1 - w0, user=r1.ru_utime - r0.ru_utime, sys=r1.ru_stime - r0.ru_stime,
               minflt=r1.ru_minflt - r0.ru_minflt)
t = threading.Thread(target=run)
t.start()
t.join()
print(json.dumps(out))
"""


def threads(pid: int) -> dict[int, tuple[float, float, int]]:
    """Per thread of ``pid``: (user s, kernel s, minor faults)."""
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[int(task.name)] = (int(fields[11]) / TICK, int(fields[12]) / TICK, int(fields[7]))
    return out


def cpu_s(pid: int) -> float:
    return sum(process(pid)[:2])


def process(pid: int) -> tuple[float, float, int]:
    """``pid``'s user s, kernel s and minor faults, with those of its children it has waited
    for: the daemon's export fits run in a child interpreter of their own
    (gonio.export.child), which its pool joins before the answer is sent."""
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return ((int(f[11]) + int(f[13])) / TICK, (int(f[12]) + int(f[14])) / TICK,
            int(f[7]) + int(f[8]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--format", default="gltf")
    ap.add_argument("--rotations", type=int, default=8)
    ap.add_argument("--time-scale", type=float, default=20.0)
    args = ap.parse_args(argv)

    rows: list[tuple[str, float, float, float, float, int]] = []
    with tempfile.TemporaryDirectory(prefix="bench-export-") as tmp:
        result = Path(tmp) / "result.h5"
        with sim_daemon(["--no-export-fits"], args.time_scale) as (proc, c):
            job = scan(c, args.rotations)
            time.sleep(2)  # the job's end settles
            before, p0, t0 = threads(proc.pid), process(proc.pid), time.perf_counter()
            r = c.get(f"/api/v1/jobs/{job}/export", params={"format": args.format})
            wall, p1 = time.perf_counter() - t0, process(proc.pid)
            r.raise_for_status()
            after = threads(proc.pid)
            busy = max(after, key=lambda t: sum(after[t][:2]) - sum(before.get(t, (0, 0, 0))[:2]))
            b, a = before.get(busy, (0.0, 0.0, 0)), after[busy]
            rows.append(("daemon, HTTP export (working thread)", wall, sum(p1[:2]) - sum(p0[:2]),
                         a[0] - b[0], a[1] - b[1], a[2] - b[2]))
            rows.append(("daemon, HTTP export (daemon and its fits' child)", wall,
                         sum(p1[:2]) - sum(p0[:2]), p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]))
            res = c.get(f"/api/v1/jobs/{job}/result")
            res.raise_for_status()
            result.write_bytes(res.content)
        for mode, label in (("plain", "plain process"), ("bound", "plain, daemon's heap")):
            out = subprocess.run([sys.executable, "-c", CHILD, str(result), mode], check=True,
                                 capture_output=True, text=True).stdout
            m = json.loads(out.strip().splitlines()[-1])
            rows.append((label, m["wall"], m["user"] + m["sys"], m["user"], m["sys"],
                         m["minflt"]))
    print(f"export {args.format} of a {args.rotations}-angle scan; CPU of the whole daemon "
          "with its children; user/kernel/faults of the working thread, or of the daemon with "
          "its children")
    print("| where | wall s | CPU s | user s | kernel s | minor faults |")
    print("|---|---|---|---|---|---|")
    for label, wall, cpu, user, kern, flt in rows:
        print(f"| {label} | {wall:.2f} | {cpu:.2f} | {user:.2f} | {kern:.2f} | {flt} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
