"""The engine on the simulated rig over the real protocols (Dynamixel and Zaber stages)."""

from __future__ import annotations

import asyncio
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gonio.calibration import Calibration, PairCalibration, calibrated_samples
from gonio.drivers.factory import build_rig
from gonio.engine import ScanEngine
from gonio.jobstates import JobState
from gonio.plans.models import (
    AdaptivePlan,
    AnyPlan,
    ExposureSettings,
    FaultPolicy,
    PlanError,
    UniformPlan,
)
from gonio.plans.validation import plan_pairs, validate_plan
from gonio.rigdescription import RigDescription
from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from gonio.store import JobStore
from tests.system._scan_child import kill_when_frozen, start_child

pytestmark = pytest.mark.system
FAST = ExposureSettings(exposure_s=0.02, light_settle_s=0.0, dark="every_angle")
QUICK = FaultPolicy(max_retries=3, retry_delay_s=0.05, resume_settle_s=0.05, wait_for_device_s=0)


def _true_calibration(sim: SimRig, desc: RigDescription, exposure_s: float) -> Calibration:
    """What a perfect white-reference calibration would give (from the sim's ground truth)."""
    pairs = []
    for p in desc.pairs:
        k = sim.expected_counts_per_brdf(p.light, p.sensor, exposure_s)
        n = len(desc.sensor(p.sensor).channels)
        pairs.append(PairCalibration(light=p.light, sensor=p.sensor, factor=(1.0 / k,) * n))
    return Calibration(pairs=tuple(pairs), source="sim ground truth")


async def _scan(sim: SimRig, plan: AnyPlan, fault: str | None = None,
                on_store: Callable[[JobStore], None] | None = None,
                ) -> tuple[JobStore, ScanEngine, JobState]:
    rig = build_rig(sim.config)
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    if on_store is not None:
        on_store(store)
    job = store.create_job(kind=plan.kind, specimen="sim", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    async with rig:
        if fault is not None:  # armed after connecting, so it hits the scan
            sim.apply_fault(fault)
        eng = ScanEngine(rig, store, job.id, plan, desc)
        state = await eng.run()
    return store, eng, state


def _check_samples(sim: SimRig, store: JobStore, eng: ScanEngine) -> float:
    desc = eng.desc
    pairs = plan_pairs(eng.plan, desc)
    cal = _true_calibration(sim, desc, eng.plan.exposure.exposure_s)
    channels = desc.sensor(pairs[0].sensor).channels
    s = calibrated_samples(store.readings(1), pairs, np.zeros((len(pairs), 3)),
                           np.zeros((len(pairs), 3)), channels, cal)
    truth = np.stack([[sim.true_brdf(p.light, p.sensor, a) for a in s.stage_angles_deg]
                      for p in pairs])
    big = truth > 0.05 * truth.max()
    return float(np.median(np.abs(s.values[big] - truth[big]) / truth[big]))


@pytest.mark.parametrize("stage", ["dynamixel", "zaber"])
def test_uniform_scan_measures_the_specimen(stage: str) -> None:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=10.0, seed=3)) as sim:
        store, eng, state = asyncio.run(_scan(sim, UniformPlan(rotations=6, exposure=FAST)))
        assert state is JobState.RUNNING
        assert store.reading_count(1) == 6 * len(eng.pairs)
        # Calibrated samples match the simulated specimen's BRDF within 5 % (noise + quantisation).
        assert _check_samples(sim, store, eng) < 0.05
        assert all(abs(r.actual_deg - r.commanded_deg) < 0.2 for r in store.readings(1))


def test_adaptive_scan_refines_on_the_sim() -> None:
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, seed=4)) as sim:
        plan = AdaptivePlan(initial_rotations=6, threshold=0.1, max_rounds=2, exposure=FAST)
        store, eng, state = asyncio.run(_scan(sim, plan))
        assert state is JobState.RUNNING
        steps = store.steps(1)
        assert {s.round for s in steps} == {0, 1}  # the anisotropic lobe needs refinement
        assert _check_samples(sim, store, eng) < 0.05


def test_stage_overload_suspends_and_resumes() -> None:
    with start_sim_rig(SimRigOptions(stage="dynamixel", time_scale=10.0, seed=5)) as sim:
        sim.apply_fault("stage-overload")
        # start_deg 30: the first move has a distance, so the armed overload trips in it.
        store, _, state = asyncio.run(_scan(sim, UniformPlan(rotations=3, start_deg=30,
                                                             exposure=FAST, faults=QUICK)))
        assert state is JobState.RUNNING, store.get_job(1).reason
        states = [e.data["state"] for e in store.events_after(0) if e.type == "state"]
        assert "suspended" in states


def test_silent_sensor_fails_the_job_with_lights_off() -> None:
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, seed=6)) as sim:
        store, _, state = asyncio.run(_scan(sim, UniformPlan(rotations=3, exposure=FAST,
                                                             faults=QUICK), "silence:S1:1000"))
        assert state is JobState.FAILED
        assert "S1" in (store.get_job(1).reason or "")
        assert sim.modbus is not None
        assert not any(on for on, _, _ in sim.modbus.snapshot()["lamps"].values())


def test_bad_plan_refused_before_anything_moves() -> None:
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0)) as sim:
        desc = RigDescription.from_rig(build_rig(sim.config))
        with pytest.raises(PlanError, match="exposure"):
            validate_plan(UniformPlan(exposure=ExposureSettings(exposure_s=1e6)), desc)


def _child(db: Path, seed: int, freeze_after: int = 0) -> subprocess.Popen[str]:
    return start_child(db, seed, freeze_after)


def test_sigkill_mid_scan_then_restart_resumes(tmp_path: Path) -> None:
    killed, clean = tmp_path / "killed.sqlite", tmp_path / "clean.sqlite"
    # The child freezes itself after its 3rd checkpoint: the kill lands mid-scan on any
    # machine, instead of racing a busy test process against the scan.
    proc = _child(killed, 7, freeze_after=3)
    kill_when_frozen(proc)
    store = JobStore(killed)
    done_before = store.get_job(1).done_angles
    assert done_before == 3
    assert store.get_job(1).state is JobState.RUNNING
    assert _child(killed, 7).communicate(timeout=120)[0].strip() == "running"
    assert _child(clean, 7).communicate(timeout=120)[0].strip() == "running"
    a, b = JobStore(killed).readings(1), JobStore(clean).readings(1)
    keys = [(r.angle_index, r.light, r.sensor) for r in a]
    assert len(keys) == len(set(keys)) == len(b)  # nothing lost, nothing duplicated
    assert keys == [(r.angle_index, r.light, r.sensor) for r in b]
    va = np.array([np.subtract(r.raw, r.dark) for r in a])
    vb = np.array([np.subtract(r.raw, r.dark) for r in b])
    # Same readings as the uninterrupted run up to sensor noise (a repeated angle draws new
    # noise).
    assert np.allclose(va, vb, rtol=0.05, atol=50)
