"""Benchmark: the first page scan on a fresh machine (issue 27, item 12).

Starts ``gonio serve --sim`` in a child process with an empty ``GONIO_CACHE_DIR`` (no library,
no basis cached), an empty ``GONIO_LIBRARY_DIR`` and data directory, submits the scan the lab
page's form submits by default (uniform, 8 stage angles over half a turn, 0.01 s exposure, one
average) and waits for the job to complete: measuring, reconstruction, the export fits and the
result file. Reports the wall time from the daemon's start to its health answer, from the
submission to ``reconstructing`` (measuring) and on to ``completed`` (finishing: the basis,
the reconstruction, the export fits, the result file), and all together. Target: under 30 s
with the default simulated timings (docs/library.md, "The shipped synthetic basis").

    nice -n 5 .venv/bin/python bench/bench_first_scan.py [--runs 1] [--keep-cache]

``--keep-cache`` reuses one cache folder across runs (the second run then shows a warm start).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import secrets
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_api import free_port, start_daemon, wait_up

#: What the page's form submits with its defaults (gonio/api/static/index.html, app.js readPlan).
PAGE_PLAN = {"kind": "uniform", "specimen": "specimen", "rotations": 8, "span_deg": 180,
             "exposure": {"exposure_s": 0.01, "averages": 1}}
DONE = ("completed", "failed", "aborted", "halted")


async def one_run(cache: Path, timeout: float,
                  material: str | None = None) -> dict[str, float | str]:
    """One daemon start and page scan; the timings and the job's final state."""
    with tempfile.TemporaryDirectory(prefix="gonio-first-") as tmp:
        lib, data = Path(tmp) / "lib", Path(tmp) / "data"
        lib.mkdir()
        os.environ["GONIO_CACHE_DIR"] = str(cache)
        os.environ["GONIO_LIBRARY_DIR"] = str(lib)
        # A fresh machine has no user data folder either: a calibration another run left for
        # the simulated rig there would otherwise refuse the page's scan (409, "not the one in
        # effect here").
        os.environ["XDG_DATA_HOME"] = str(Path(tmp) / "share")
        key, port = secrets.token_hex(16), free_port()
        url = f"http://127.0.0.1:{port}"
        t0 = time.perf_counter()
        proc = start_daemon(port, key, str(data), material=material)
        try:
            await wait_up(url, timeout=120)
            t_up = time.perf_counter()
            async with httpx.AsyncClient(base_url=url, headers={"X-API-Key": key},
                                         timeout=30) as c:
                r = await c.post("/api/v1/jobs", json={"plan": PAGE_PLAN})
                if r.is_error:
                    raise SystemExit(f"the page's scan was refused: {r.status_code} {r.text}")
                job_id = r.json()["id"]
                t_sub = time.perf_counter()
                state, t_rec = "queued", float("nan")
                while state not in DONE and time.perf_counter() - t_sub < timeout:
                    await asyncio.sleep(0.2)
                    state = (await c.get(f"/api/v1/jobs/{job_id}")).json()["state"]
                    if state == "reconstructing" and t_rec != t_rec:
                        t_rec = time.perf_counter()
                t_end = time.perf_counter()
                # What the status's finishing estimate rests on (gonio.timeleft): the time
                # finishing recorded in the job's summary, without this loop's polling.
                summary = (await c.get(f"/api/v1/jobs/{job_id}")).json().get("result") or {}
                recorded = float(summary.get("seconds", float("nan")))
        finally:
            proc.terminate()
            proc.wait(timeout=60)
    return {"state": state, "start_s": t_up - t0, "measure_s": t_rec - t_sub,
            "finish_s": t_end - t_rec, "recorded_s": recorded, "scan_s": t_end - t_sub,
            "total_s": t_end - t0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--keep-cache", action="store_true",
                    help="one cache folder for all runs (later runs start warm)")
    ap.add_argument("--timeout", type=float, default=600.0, help="give up on a scan after, s")
    ap.add_argument("--material", default=None,
                    help="the simulated specimen (gonio serve --sim --material; a spectral "
                    "one, e.g. metallic-blue-paint, gives 31-band sensors)")
    args = ap.parse_args()
    shared = Path(tempfile.mkdtemp(prefix="gonio-cache-")) if args.keep_cache else None
    print("run  state      daemon up, s  measuring, s  finishing, s  recorded, s  "
          "submit->completed, s  total, s")
    for i in range(args.runs):
        cache = shared or Path(tempfile.mkdtemp(prefix="gonio-cache-"))
        assert not any(cache.iterdir()) or args.keep_cache
        res = asyncio.run(one_run(cache, args.timeout, args.material))
        print(f"{i + 1:3d}  {res['state']:<9}  {res['start_s']:12.1f}  {res['measure_s']:12.1f}  "
              f"{res['finish_s']:12.1f}  {res['recorded_s']:11.1f}  {res['scan_s']:20.1f}  "
              f"{res['total_s']:8.1f}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
