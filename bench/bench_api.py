"""API load benchmark: job-status latency and event delivery while a scan runs.

Starts ``gonio serve --sim`` in a subprocess (its own interpreter, so client load does not share
the server's GIL), then measures one scan twice: alone, and under load from N clients polling
the job's status in a loop plus M server-sent-event subscribers. Reports the status latency
(p50/p99/max), events lost per subscriber (expected 0: every seq of the scan must arrive, in
order), and the scan overhead (measuring phase, loaded vs alone). The reconstruction is not
part of the measurement: the load stops when the job reaches ``reconstructing``, and the next
scan starts only once the reconstruction has ended (aborting it instead would leave its thread
computing beside the next scan: a thread cannot be interrupted, and the daemon's worker starts
the next job at once).

    .venv/bin/python bench/bench_api.py [--pollers 50] [--subscribers 10] [--rotations 24]
                                        [--interval 0.5] [--dry-runners 0] [--sim-process]
                                        [--ignore-retry-after] [--no-rate-limit]

The worst load a client can make: ``--interval 0`` (every poller back to back) plus
``--dry-runners 4`` (clients asking for a dry run of a large plan back to back, with the key).
The daemon runs the engine on its own loop and thread (gonio/engine_loop.py) so that the scan's
timing does not depend on this load beyond the CPU time it takes from the machine.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import secrets
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any

import httpx


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


GONIO = [sys.executable, "-c", "from gonio.cli import main; raise SystemExit(main())"]


def start_daemon(port: int, key: str, data_dir: str, rig_toml: str | None = None,
                 config: str | None = None,
                 material: str | None = None) -> subprocess.Popen[bytes]:
    env = {**os.environ, "GONIO_API_KEYS": f"bench:{key}"}
    rig = ["--sim"] if rig_toml is None else ["--rig", rig_toml]
    if material is not None:  # the simulated rig's specimen (--sim only)
        rig += ["--material", material]
    cmd = [*GONIO, "serve", *rig, "--port", str(port), "--data-dir", data_dir]
    if config is not None:
        cmd += ["--config", config]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def start_sim_process(rig_toml: str) -> subprocess.Popen[bytes]:
    """``gonio sim`` in its own process, as devices are outside the daemon in a lab."""
    proc = subprocess.Popen([*GONIO, "sim", "-o", rig_toml], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL)
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith(b"simulated rig running"):
            return proc
    raise RuntimeError("gonio sim did not start")


async def wait_up(url: str, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    async with httpx.AsyncClient() as c:
        while time.monotonic() < deadline:
            try:
                if (await c.get(f"{url}/health")).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            await asyncio.sleep(0.2)
    raise TimeoutError("daemon did not come up")


async def subscriber(url: str, since: int, job_id_box: dict[str, int], got: list[int],
                     done: asyncio.Event) -> None:
    async with httpx.AsyncClient(timeout=httpx.Timeout(10, read=None)) as c, \
            c.stream("GET", f"{url}/api/v1/events", params={"since": since}) as r:
        async for line in r.aiter_lines():
            if not line.startswith("data:"):
                continue
            ev = json.loads(line[5:])
            got.append(ev["seq"])
            if (ev["type"] == "state" and ev["job_id"] == job_id_box.get("id")
                    and ev["data"]["state"] in ("aborted", "failed", "completed")):
                done.set()
                return


async def poller(c: httpx.AsyncClient, job_id: int, stop: asyncio.Event, lat: list[float],
                 interval: float, phase: float, refused: list[int], honour: bool) -> None:
    """Poll one job's status every ``interval`` s, starting ``phase`` s late.

    The client is created by the caller before any timing starts: building an
    ``httpx.AsyncClient`` loads a TLS context (about 25 ms of CPU on this loop), so clients
    created inside the timed loop stall every other client's requests and the benchmark would
    measure itself. Independent clients are not synchronised, hence the phase offset.

    The pollers have no key, so the daemon's rate limit applies to them (429 + Retry-After,
    counted in ``refused``); ``honour`` makes them wait as the header says, as a well-behaved
    client does, otherwise they ask again at once.
    """
    await asyncio.sleep(phase)
    while not stop.is_set():
        t0 = time.perf_counter()
        r = await c.get(f"/api/v1/jobs/{job_id}")
        dt = time.perf_counter() - t0
        if r.status_code == 429:
            refused[0] += 1
            if honour:
                await asyncio.sleep(float(r.headers["retry-after"]))
            continue
        lat.append(dt)
        r.raise_for_status()
        await asyncio.sleep(max(0.0, interval - dt))


async def dry_runner(c: httpx.AsyncClient, stop: asyncio.Event, count: list[int]) -> None:
    """Ask for a dry run of a 360-angle plan back to back (keyed: anonymous ones get 401)."""
    plan = {"kind": "uniform", "rotations": 360}
    while not stop.is_set():
        r = await c.post("/api/v1/jobs/dry-run", json={"plan": plan})
        r.raise_for_status()
        count[0] += 1


async def wait_idle(c: httpx.AsyncClient, timeout: float = 300) -> None:
    """Until no job is queued or active (the stage can only be moved then)."""
    deadline = time.monotonic() + timeout
    while any(j["state"] not in ("completed", "failed", "aborted", "halted")
              for j in (await c.get("/api/v1/jobs")).json()):
        if time.monotonic() > deadline:
            raise TimeoutError("the daemon's jobs did not finish")
        await asyncio.sleep(0.2)


async def one_scan(url: str, key: str, rotations: int, pollers: int, subs: int,
                   interval: float = 0.0, dry_runners: int = 0,
                   honour: bool = True) -> dict[str, Any]:
    h = {"X-API-Key": key}
    async with httpx.AsyncClient(base_url=url, headers=h, timeout=30) as c:
        seq0 = (await c.get("/health")).json()["seq"]
        box: dict[str, int] = {}
        received: list[list[int]] = [[] for _ in range(subs)]
        finished = [asyncio.Event() for _ in range(subs)]
        sub_tasks = [asyncio.create_task(subscriber(url, seq0, box, received[i], finished[i]))
                     for i in range(subs)]
        poll_clients = [httpx.AsyncClient(base_url=url, timeout=30) for _ in range(pollers)]
        await asyncio.sleep(0.5)  # subscribers connected before the job exists
        plan = {"kind": "uniform", "specimen": "bench", "rotations": rotations,
                "exposure": {"exposure_s": 0.01, "light_settle_s": 0.0}}
        await wait_idle(c)  # the start-up calibration of serve --sim, or the previous scan
        # Every scan starts from 0 deg: a scan leaves the stage high up, and the next one
        # would travel further (4 s more for the second of two 24-angle scans), which is not
        # load. The dry run from there gives the physical time of the scan.
        (await c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 0.0})
         ).raise_for_status()
        estimate = (await c.post("/api/v1/jobs/dry-run", json={"plan": plan})).json()
        job_id = (await c.post("/api/v1/jobs", json={"plan": plan})).json()["id"]
        box["id"] = job_id
        stop = asyncio.Event()
        lat: list[float] = []
        refused = [0]
        poll_tasks = [asyncio.create_task(poller(pc, job_id, stop, lat, interval,
                                                 k * interval / max(pollers, 1), refused,
                                                 honour))
                      for k, pc in enumerate(poll_clients)]
        dry_count = [0]
        poll_tasks += [asyncio.create_task(dry_runner(c, stop, dry_count))
                       for _ in range(dry_runners)]
        while (await c.get(f"/api/v1/jobs/{job_id}")).json()["state"] in ("queued", "running"):
            await asyncio.sleep(0.1)
        stop.set()
        await asyncio.gather(*poll_tasks)
        for pc in poll_clients:
            await pc.aclose()
        # The job completes (its reconstruction ends) before anything else is measured.
        await asyncio.wait_for(asyncio.gather(*(e.wait() for e in finished)), 300)
        for t in sub_tasks:
            t.cancel()
        # Events of the scan, as stored: running -> ... -> reconstructing gives the timing.
        events = []
        async with c.stream("GET", "/api/v1/events", params={"since": seq0}) as r:
            async for line in r.aiter_lines():
                if line.startswith("data:"):
                    ev = json.loads(line[5:])
                    events.append(ev)
                    if (ev["type"] == "state" and ev["job_id"] == job_id
                            and ev["data"]["state"] in ("aborted", "failed", "completed")):
                        break
    times = {ev["data"]["state"]: ev["time"] for ev in events
             if ev["type"] == "state" and ev["job_id"] == job_id}
    expected = [ev["seq"] for ev in events]
    lost = [len(set(expected) - set(got)) for got in received]
    in_order = all(got[: len(expected)] == expected for got in received)
    return {
        "measuring_s": times["reconstructing"] - times["running"],
        "lat": lat,
        "lost": lost,
        "in_order": in_order,
        "events": len(expected),
        "dry_runs": dry_count[0],
        "refused": refused[0],
        "estimated_s": estimate["estimated_s"],
    }


def pct(xs: list[float], q: float) -> float:
    return statistics.quantiles(xs, n=1000)[int(q * 10) - 1] if len(xs) > 1 else float("nan")


async def main_async(args: argparse.Namespace) -> int:
    key = secrets.token_urlsafe(24)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="gonio-bench-") as tmp:
        sim = None
        rig_toml = None
        if args.sim_process:
            rig_toml = os.path.join(tmp, "rig.toml")
            sim = start_sim_process(rig_toml)
        config = None
        if args.no_rate_limit:
            config = os.path.join(tmp, "daemon.toml")
            with open(config, "w") as f:
                f.write("[limits]\nanonymous_requests_per_s = 0\n")
        proc = start_daemon(port, key, os.path.join(tmp, "data"), rig_toml, config)
        try:
            await wait_up(url)
            alone = await one_scan(url, key, args.rotations, 0, 1)
            loaded = await one_scan(url, key, args.rotations, args.pollers, args.subscribers,
                                    args.interval, args.dry_runners,
                                    not args.ignore_retry_after)
        finally:
            proc.terminate()
            proc.wait(30)
            if sim is not None:
                sim.terminate()
                sim.wait(30)
    lat_ms = [x * 1000 for x in loaded["lat"]]
    overhead = loaded["measuring_s"] / alone["measuring_s"] - 1
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    where = ("in its own process (gonio sim)" if args.sim_process
             else "inside the daemon (serve --sim)")
    print(f"scan: uniform, {args.rotations} stage angles, simulated rig (12 pairs) {where}")
    every = f"every {args.interval:g} s" if args.interval > 0 else "back to back"
    manners = ("no rate limit" if args.no_rate_limit
               else "ignoring 429 Retry-After" if args.ignore_retry_after
               else "waiting as 429 Retry-After says")
    print(f"load: {args.pollers} clients without a key polling GET /api/v1/jobs/{{id}} {every} "
          f"each ({manners}), "
          f"{args.subscribers} SSE subscribers, {args.dry_runners} dry-run clients; clients and "
          "daemon share this machine's CPUs")
    print()
    print("| quantity | value |")
    print("|---|---|")
    print(f"| status requests answered | {len(lat_ms)} |")
    print(f"| status requests refused (429) | {loaded['refused']} |")
    print(f"| dry runs answered | {loaded['dry_runs']} |")
    print(f"| status latency p50 (answered) | {pct(lat_ms, 50):.1f} ms |")
    print(f"| status latency p99 (target < 100 ms) | {pct(lat_ms, 99):.1f} ms |")
    print(f"| status latency max | {max(lat_ms, default=float('nan')):.1f} ms |")
    print(f"| events in the scan | {loaded['events']} |")
    print(f"| events lost per subscriber (target 0) | {max(loaded['lost'])} "
          f"(in order: {loaded['in_order']}) |")
    print(f"| dry-run estimate of each scan (from 0 deg) | {alone['estimated_s']:.2f} s, "
          f"{loaded['estimated_s']:.2f} s |")
    print(f"| measuring phase alone | {alone['measuring_s']:.2f} s |")
    print(f"| measuring phase under load | {loaded['measuring_s']:.2f} s |")
    print(f"| scan overhead under load | {100 * overhead:+.1f} % |")
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--pollers", type=int, default=50)
    p.add_argument("--subscribers", type=int, default=10)
    p.add_argument("--rotations", type=int, default=24)
    p.add_argument("--interval", type=float, default=0.5,
                   help="seconds between one client's polls (0: back to back, a stress test)")
    p.add_argument("--sim-process", action="store_true",
                   help="run the simulated rig in its own process (gonio sim), not inside the "
                        "daemon: the devices then do not share the daemon's interpreter")
    p.add_argument("--no-rate-limit", action="store_true",
                   help="turn the daemon's limit for clients without a key off "
                        "([limits] anonymous_requests_per_s = 0)")
    p.add_argument("--ignore-retry-after", action="store_true",
                   help="pollers ask again at once after a 429 (an ill-behaved client)")
    p.add_argument("--dry-runners", type=int, default=0,
                   help="clients asking for dry runs back to back during the loaded scan")
    return asyncio.run(asyncio.wait_for(main_async(p.parse_args()), timeout=600))


if __name__ == "__main__":
    raise SystemExit(main())
