"""Simulated scan wall time against its physical lower bound.

The lower bound is the plan's dry-run estimate: trapezoidal stage moves at the rig's speed and
acceleration, the stage settle time, and one exposure per light and angle (plus the dark). The
overhead is everything else: protocol round trips, light switching, store commits.

Run: ``.venv/bin/python bench/bench_engine.py [--rotations 8] [--exposure 0.05]``
Prints one table row per stage kind.
"""

from __future__ import annotations

import argparse
import asyncio
import time

from gonio.drivers.factory import build_rig
from gonio.sim.rig import SimRigOptions, start_sim_rig

from gonio.engine import ScanEngine
from gonio.plans import ExposureSettings, RigDescription, UniformPlan, dry_run
from gonio.store import JobStore


async def one(stage: str, rotations: int, exposure: float) -> tuple[float, float, int]:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=1.0)) as sim:  # type: ignore[arg-type]
        rig = build_rig(sim.config)
        desc = RigDescription.from_rig(rig)
        plan = UniformPlan(rotations=rotations, exposure=ExposureSettings(
            exposure_s=exposure, light_settle_s=0.0, dark="once"))
        store = JobStore(":memory:")
        job = store.create_job(kind="uniform", specimen="bench",
                               plan=plan.model_dump(mode="json"), rig=desc.model_dump(mode="json"))
        async with rig:
            here = await rig.stage.position()
            bound = dry_run(plan, desc, current_deg=here).estimated_s
            t0 = time.perf_counter()
            await ScanEngine(rig, store, job.id, plan, desc).run()
            wall = time.perf_counter() - t0
        return wall, bound, store.reading_count(job.id)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rotations", type=int, default=8)
    ap.add_argument("--exposure", type=float, default=0.05)
    args = ap.parse_args()
    print(f"{'stage':<10} {'readings':>8} {'bound s':>8} {'wall s':>8} {'overhead':>9}")
    for stage in ("dynamixel", "zaber"):
        wall, bound, n = asyncio.run(one(stage, args.rotations, args.exposure))
        print(f"{stage:<10} {n:>8} {bound:>8.2f} {wall:>8.2f} {100 * (wall / bound - 1):>8.1f}%")


if __name__ == "__main__":
    main()
