"""Simulated scan wall time against its physical lower bound, with a per-angle breakdown.

The lower bound (motion + exposure) is the plan's dry-run estimate
(:func:`gonio.plans.dryrun.dry_run`: trapezoidal stage moves, the configured stage settle time,
one exposure per light and angle, plus the dark) with the stage's speed and acceleration as the
device really runs them (:attr:`gonio.hal.Stage.profile_dps`: the configured values rounded to
the device's profile units; a Dynamixel at 60 deg/s and 240 deg/s^2 runs 60.46 deg/s and
236 deg/s^2). The dry run with the configured values is shown beside it (``dry s``). The
overhead is everything else: protocol round trips, light switching, move-completion polling,
store commits.

The simulated stage also rings for ``SimRigOptions.settle_s`` (20 ms) after each move and
reports itself busy meanwhile. That time is physical (a stage that needs settling needs it on
every move), but the rig config the simulator writes says ``settle_s = 0``, so the dry run does
not know it: the table shows it in its own column and gives the overhead both against the
bound (motion + exposure) and against the bound with the settling (motion + settle +
exposure).

The job store is a file in a temporary directory, opened as the daemon and ``gonio scan``
open theirs (durable: each checkpoint is synced to the disk); ``--store memory`` uses an
in-memory store instead, which leaves out the disk (the numbers of rounds before this option
were measured that way).

With ``--profile`` the scan is instrumented (device calls and store commits are timed by
wrapping the rig's objects; the engine and drivers are unchanged) and one table per stage kind
splits the mean wall time of an angle into stage, lights, exposures, store and the rest, each
next to its physical part, plus the Modbus requests per angle counted by the simulator.

Run: ``.venv/bin/python bench/bench_engine.py [--rotations 8] [--exposure 0.05] [--runs 3]
[--profile] [--store file|memory]``. The machine load (1-minute load average) is printed
with each run.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gonio import hal
from gonio.drivers.factory import build_rig
from gonio.engine import ScanEngine
from gonio.motion import move_time
from gonio.plans.dryrun import dry_run
from gonio.plans.models import ExposureSettings, UniformPlan
from gonio.rigdescription import RigDescription
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobStore

STAGES = ("dynamixel", "zaber")


@dataclass
class Timeline:
    """Wall time spent in each kind of call during one scan, seconds."""

    spent: dict[str, float] = field(default_factory=dict)
    calls: dict[str, int] = field(default_factory=dict)
    moves_deg: list[float] = field(default_factory=list)
    last_deg: float = 0.0  # where the stage was after the previous move, degrees
    lit: int = 0  # lights currently on (exposures while 0 are darks)
    # [start, end] of each stage move (end: infinity while it runs)
    moves: list[list[float]] = field(default_factory=list)

    def add(self, key: str, seconds: float) -> None:
        self.spent[key] = self.spent.get(key, 0.0) + seconds
        self.calls[key] = self.calls.get(key, 0) + 1

    def add_span(self, key: str, start: float, end: float) -> None:
        """Add the part of ``start..end`` that no stage move covers (a lamp switched while
        the stage moves costs no time of its own)."""
        covered = sum(max(0.0, min(end, b) - max(start, a)) for a, b in self.moves)
        self.add(key, end - start - covered)


def instrument(rig: hal.Rig, store: JobStore, tl: Timeline) -> None:
    """Replace the rig's device methods and the store's commit with timed wrappers.

    Light periods (switch on to switch off) are timed as one span, so sensor reads inside
    them are not counted twice; darks are the sensor reads while every light is off.
    """
    stage = rig.stage
    move, position = stage.move_to, stage.position
    in_move = False

    async def timed_move(angle_deg: float, timeout_s: float | None = None) -> float:
        nonlocal in_move
        t0 = time.perf_counter()
        in_move = True
        span = [t0, float("inf")]
        tl.moves.append(span)
        try:
            actual = await move(angle_deg, timeout_s)
        finally:
            in_move = False
            span[1] = time.perf_counter()
        span[1] = time.perf_counter()
        tl.add("stage move", span[1] - t0)
        tl.moves_deg.append(abs(actual - tl.last_deg))
        tl.last_deg = actual
        return actual

    async def timed_position() -> float:
        if in_move:  # the driver's own read, already inside the move's time
            return await position()
        t0 = time.perf_counter()
        try:
            return await position()
        finally:
            tl.add("stage position", time.perf_counter() - t0)

    stage.move_to = timed_move  # type: ignore[method-assign]
    stage.position = timed_position  # type: ignore[method-assign]
    for light in rig.lights.values():
        _time_light_periods(light, tl)
    for sensor in rig.sensors.values():
        sensor.read = _timed_dark_read(  # type: ignore[method-assign,assignment]
            sensor.read, tl)
    commit = store.commit_angle

    def timed_commit(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return commit(*args, **kwargs)
        finally:
            # A commit in a worker thread runs beside the next move: no wall time of its own.
            on_loop = threading.current_thread() is threading.main_thread()
            tl.add("store commit" if on_loop else "store commit beside",
                   time.perf_counter() - t0)

    store.commit_angle = timed_commit  # type: ignore[method-assign]


def _time_light_periods(light: hal.Light, tl: Timeline) -> None:
    """Replace ``light.switch_on`` and ``light.set_on`` with wrappers that time the span from
    switching the light on (either way) to switching it off."""
    since: list[float] = []
    switch_on, set_on = light.switch_on, light.set_on

    def started() -> None:
        since.append(time.perf_counter())
        tl.lit += 1

    async def timed_switch_on(*, check: bool = True) -> None:
        started()
        await switch_on(check=check)

    async def timed_set_on(on: bool) -> None:
        if on:
            started()
        try:
            await set_on(on)
        finally:
            if not on and since:
                tl.lit -= 1
                tl.add_span("light period", since.pop(), time.perf_counter())

    light.switch_on = timed_switch_on  # type: ignore[method-assign]
    light.set_on = timed_set_on  # type: ignore[method-assign]


def _timed_dark_read(read: Callable[..., Awaitable[hal.SensorReading]],
                     tl: Timeline) -> Callable[..., Awaitable[hal.SensorReading]]:
    """``read`` that times reads made while every light is off (darks read in parallel, so
    the longest one is the dark's duration)."""

    async def wrapper(exposure_s: float, averages: int = 1) -> hal.SensorReading:
        dark = tl.lit == 0
        t0 = time.perf_counter()
        out = await read(exposure_s, averages)
        if dark:
            tl.spent["dark"] = max(tl.spent.get("dark", 0.0), time.perf_counter() - t0)
        return out

    return wrapper


@dataclass
class RunResult:
    wall: float
    bound: float
    dry: float  # the dry run with the configured speed and acceleration, seconds
    profile: tuple[float, float]  # speed deg/s, acceleration deg/s^2 the stage runs
    ringing: float
    readings: int
    angles: int
    requests: int
    timeline: Timeline | None
    motion_s: float
    exposure_s: float


async def one(stage: str, rotations: int, exposure: float, profile: bool,
              store_kind: str = "file") -> RunResult:
    options = SimRigOptions(stage=stage, time_scale=1.0)
    with start_sim_rig(options) as sim, tempfile.TemporaryDirectory() as tmp:
        rig = build_rig(sim.config)
        desc = RigDescription.from_rig(rig)
        plan = UniformPlan(rotations=rotations, exposure=ExposureSettings(
            exposure_s=exposure, light_settle_s=0.0, dark="once"))
        # The daemon's store: a file, durable (gonio.daemon, gonio scan).
        store = JobStore(Path(tmp) / "jobs.db" if store_kind == "file" else ":memory:")
        job = store.create_job(kind="uniform", specimen="bench",
                               plan=plan.model_dump(mode="json"), rig=desc.model_dump(mode="json"))
        async with rig:
            here = await rig.stage.position()
            dry = dry_run(plan, desc, current_deg=here).estimated_s
            speed, accel = rig.stage.profile_dps
            dr = dry_run(plan, desc.model_copy(update={"speed_dps": speed, "accel_dps2": accel}),
                         current_deg=here)
            # The simulated stage rings after every move that goes somewhere.
            here_now, moves = here, 0
            for p in dr.positions_deg:
                moves += abs(p - here_now) > 1e-9
                here_now = p
            ringing = moves * options.settle_s
            tl = Timeline(last_deg=here) if profile else None
            if tl is not None:
                instrument(rig, store, tl)
            assert sim.modbus is not None
            req0 = sum(sim.modbus.request_counts().values())
            t0 = time.perf_counter()
            await ScanEngine(rig, store, job.id, plan, desc).run()
            wall = time.perf_counter() - t0
            requests = sum(sim.modbus.request_counts().values()) - req0
        readings = store.reading_count(job.id)
        store.close()
        return RunResult(wall, dr.estimated_s, dry, (speed, accel), ringing, readings,
                         len(dr.positions_deg), requests, tl, dr.motion_s, dr.exposure_s)


def print_profile(stage: str, res: RunResult, n_lights: int, exposure: float) -> None:
    tl = res.timeline
    assert tl is not None
    n = res.angles
    physical_move = sum(move_time(d, *res.profile) for d in tl.moves_deg)
    rows = [
        ("stage move", tl.spent.get("stage move", 0.0), physical_move + res.ringing,
         f"trapezoid + {res.ringing * 1e3 / max(n, 1):.0f} ms/angle ringing"),
        ("stage position (engine)", tl.spent.get("stage position", 0.0), 0.0, ""),
        ("light periods", tl.spent.get("light period", 0.0), n * n_lights * exposure,
         "on, settle, exposures, status, off; not while the stage moves"),
        ("dark (once)", tl.spent.get("dark", 0.0), exposure, ""),
        ("store commit", tl.spent.get("store commit", 0.0), 0.0,
         f"+ {1e3 * tl.spent.get('store commit beside', 0.0) / max(n, 1):.2f} ms/angle in a "
         "thread beside the move"),
    ]
    accounted = sum(r[1] for r in rows)
    rows.append(("rest (engine, loop)", res.wall - accounted, 0.0, ""))
    print(f"\n{stage}: per angle (mean of {n}), ms; {res.requests / n:.1f} Modbus requests/angle")
    print(f"  {'part':<24} {'wall':>8} {'physical':>9} {'overhead':>9}  note")
    for name, wall, phys, note in rows:
        print(f"  {name:<24} {1e3 * wall / n:>8.2f} {1e3 * phys / n:>9.2f} "
              f"{1e3 * (wall - phys) / n:>9.2f}  {note}")
    total_phys = sum(r[2] for r in rows)
    print(f"  {'total':<24} {1e3 * res.wall / n:>8.2f} {1e3 * total_phys / n:>9.2f} "
          f"{1e3 * (res.wall - total_phys) / n:>9.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rotations", type=int, default=8)
    ap.add_argument("--exposure", type=float, default=0.05)
    ap.add_argument("--runs", type=int, default=1, help="repeat the table this many times")
    ap.add_argument("--profile", action="store_true", help="per-angle breakdown per stage")
    ap.add_argument("--store", choices=("file", "memory"), default="file",
                    help="job store: a durable file as the daemon's (default) or in memory")
    args = ap.parse_args()
    print(f"{'run':>3} {'load':>5} {'stage':<10} {'readings':>8} {'dry s':>6} {'bound s':>8} "
          f"{'ring s':>7} {'wall s':>7} {'vs bound':>9} {'vs b+ring':>9}")
    overheads: dict[str, list[float]] = {s: [] for s in STAGES}
    overheads_ring: dict[str, list[float]] = {s: [] for s in STAGES}
    for run in range(1, args.runs + 1):
        for stage in STAGES:
            load = os.getloadavg()[0]
            res = asyncio.run(one(stage, args.rotations, args.exposure, args.profile,
                                  args.store))
            over = 100 * (res.wall / res.bound - 1)
            over_ring = 100 * (res.wall / (res.bound + res.ringing) - 1)
            overheads[stage].append(over)
            overheads_ring[stage].append(over_ring)
            print(f"{run:>3} {load:>5.2f} {stage:<10} {res.readings:>8} {res.dry:>6.3f} "
                  f"{res.bound:>8.3f} "
                  f"{res.ringing:>7.2f} {res.wall:>7.2f} {over:>8.1f}% {over_ring:>8.1f}%")
            if args.profile:
                print_profile(stage, res, len(SimRigOptions().lights), args.exposure)
    if args.runs > 1:
        for stage in STAGES:
            for what, values in (("motion+exposure", overheads[stage]),
                                 ("motion+settle+exposure", overheads_ring[stage])):
                print(f"{stage}: over {what} median {statistics.median(values):.1f}% "
                      f"(min {min(values):.1f}%, max {max(values):.1f}%) over "
                      f"{len(values)} runs")


if __name__ == "__main__":
    main()
