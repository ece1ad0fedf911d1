"""Child process for the kill-and-restart test of an auto-arc scan: measure a job on a fresh
simulated rig holding a specimen without twofold symmetry (``tilted-facet-002``).

Usage: python _arc_child.py DB SEED [FREEZE_AFTER]. Resumes the store's active job if there
is one (as the daemon does after a crash), otherwise creates it (uniform, 8 angles, arc auto).
With FREEZE_AFTER the process stops dead right after committing that many angles, so the
test's SIGKILL lands there however busy the machine is.
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
from typing import Any

from gonio.drivers.factory import build_rig
from gonio.engine import ScanEngine
from gonio.plans.models import ExposureSettings, UniformPlan, parse_plan
from gonio.rigdescription import RigDescription
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobStore

MATERIAL = "tilted-facet-002"


async def main(db: str, seed: int, freeze_after: int = 0) -> int:
    with start_sim_rig(SimRigOptions(time_scale=10.0, seed=seed, material=MATERIAL)) as sim:
        rig = build_rig(sim.config)
        desc = RigDescription.from_rig(rig)
        store = JobStore(db)
        active = store.active_jobs()
        if active:
            store.reconcile(lambda j: None)
            job = active[0]
            plan = parse_plan(job.plan)
        else:
            plan = UniformPlan(rotations=8, arc="auto", exposure=ExposureSettings(
                exposure_s=0.02, light_settle_s=0.0, dark="every_angle"))
            job = store.create_job(kind=plan.kind, specimen="sim",
                                   plan=plan.model_dump(mode="json"),
                                   rig=desc.model_dump(mode="json"))
        if freeze_after > 0:
            def freeze(ev: Any) -> None:
                if ev.type == "progress" and ev.data.get("done", 0) >= freeze_after:
                    os.kill(os.getpid(), signal.SIGSTOP)  # the test kills it from here

            store.add_listener(freeze)
        async with rig:
            state = await ScanEngine(rig, store, job.id, plan, desc).run()
        print(state.value, flush=True)
    return 0


if __name__ == "__main__":
    db, seed = sys.argv[1:3]
    freeze_after = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    raise SystemExit(asyncio.run(main(db, int(seed), freeze_after)))
