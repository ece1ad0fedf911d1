"""Child process for the kill-and-restart test: measure a job on a fresh simulated rig.

Usage: python _scan_child.py DB STAGE SEED ROTATIONS. Resumes the store's active job if there
is one (as the daemon does after a crash), otherwise creates it.
"""

from __future__ import annotations

import asyncio
import sys

from gonio.drivers.factory import build_rig
from gonio.engine import ScanEngine
from gonio.plans import ExposureSettings, RigDescription, UniformPlan, parse_plan
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobStore


async def main(db: str, stage: str, seed: int, rotations: int) -> int:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=10.0, seed=seed)) as sim:
        rig = build_rig(sim.config)
        desc = RigDescription.from_rig(rig)
        store = JobStore(db)
        active = store.active_jobs()
        if active:
            store.reconcile(lambda j: None)
            job = active[0]
            plan = parse_plan(job.plan)
        else:
            plan = UniformPlan(rotations=rotations, exposure=ExposureSettings(
                exposure_s=0.02, light_settle_s=0.0, dark="every_angle"))
            job = store.create_job(kind=plan.kind, specimen="sim",
                                   plan=plan.model_dump(mode="json"),
                                   rig=desc.model_dump(mode="json"))
        async with rig:
            state = await ScanEngine(rig, store, job.id, plan, desc).run()
        print(state.value, flush=True)
    return 0


if __name__ == "__main__":
    db, stage, seed, rotations = sys.argv[1:5]
    raise SystemExit(asyncio.run(main(db, stage, int(seed), int(rotations))))
