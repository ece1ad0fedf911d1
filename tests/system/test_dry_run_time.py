"""Dry-run estimates against the simulated run: the simulator's own motion model times every
move the drivers really commanded, so the comparison does not depend on CPU load."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from gonio.drivers.factory import build_rig
from gonio.engine import ScanEngine
from gonio.jobstates import JobState
from gonio.plans.dryrun import dry_run
from gonio.plans.models import ExposureSettings, UniformPlan
from gonio.rigdescription import RigDescription
from gonio.sim.motion import plan_phases
from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from gonio.store import JobStore

pytestmark = pytest.mark.system
FAST = ExposureSettings(exposure_s=0.02, light_settle_s=0.0, dark="once")


def _record_moves(sim: SimRig) -> list[float]:
    """Wrap the stage physics so every commanded move logs its profile's duration (sim s)."""
    motion = sim.motion
    durations: list[float] = []
    original = motion.move_to

    def move_to(deg: float) -> None:
        with motion._lock:  # the same state the move starts from
            p, v = motion._state(motion.now())
            durations.append(sum(d for d, _a in plan_phases(p, v, float(deg), motion.speed_dps,
                                                             motion.accel_dps2)))
        original(deg)

    motion.move_to = move_to  # type: ignore[method-assign]
    return durations


async def _run(sim: SimRig, plan: UniformPlan, park_deg: float, config: Any
               ) -> tuple[float, float, JobState]:
    rig = build_rig(config)
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = store.create_job(kind=plan.kind, specimen="sim", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    async with rig:
        here = await rig.stage.move_to(park_deg)  # where the previous job left the stage
        durations = _record_moves(sim)
        estimate = dry_run(plan, desc, here)
        state = await ScanEngine(rig, store, job.id, plan, desc).run()
    return estimate.motion_s, sum(durations), state


@pytest.mark.parametrize(("stage", "approach", "plan_backlash", "park"), [
    ("dynamixel", "none", 0.0, 650.0),      # the return from a high park position
    ("zaber", "positive", 3.0, 400.0),      # driver overshoots on the way down
    ("dynamixel", "none", 4.0, 130.0),      # the engine's own backlash overshoot
])
def test_uniform_dry_run_is_within_ten_percent_of_the_simulated_motion(
        stage: str, approach: str, plan_backlash: float, park: float) -> None:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=8.0, seed=1,
                                     speed_dps=90.0, accel_dps2=360.0)) as sim:
        cfg = sim.config.model_copy(update={"stage": sim.config.stage.model_copy(
            update={"approach": approach, "backlash_deg": 3.0 if approach != "none" else 0.0})})
        plan = UniformPlan(rotations=6, exposure=FAST, backlash_deg=plan_backlash)
        estimated, simulated, state = asyncio.run(_run(sim, plan, park, cfg))
    assert state is JobState.RUNNING  # every angle measured (the caller would reconstruct)
    assert simulated > 0
    assert abs(estimated - simulated) <= 0.10 * simulated, (estimated, simulated)
