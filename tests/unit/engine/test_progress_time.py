"""Live time: the ETA from measured angle times, its bound for adaptive plans, the service's
last known stage position for dry runs, and what a reconstructing job waits for."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from gonio.basis_supply import BasisSupply
from gonio.engine import Progress, ScanEngine
from gonio.plans.dryrun import dry_run
from gonio.plans.models import AdaptivePlan, ExposureSettings, UniformPlan
from gonio.service import GonioService, JobRequest
from gonio.sim.memrig import MemRig
from gonio.store import JobStore, StepRow
from gonio.worker import Worker

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0)


def test_eta_counts_down_from_the_last_checkpoint_and_never_below_zero() -> None:
    p = Progress(done=2, total=8, eta_s=12.0, at=1000.0)
    assert p.eta_now(1003.0) == pytest.approx(9.0)
    assert p.eta_now(1020.0) == 0.0
    assert Progress(0, 8, None).eta_now(5.0) is None


def _engine(plan: UniformPlan | AdaptivePlan) -> ScanEngine:
    from gonio.rigdescription import RigDescription

    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = store.create_job(kind=plan.kind, specimen="x", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    return ScanEngine(rig, store, job.id, plan, desc)


def _steps(n: int, done: int) -> list[StepRow]:
    return [StepRow(k, 0, 45.0 * k, 45.0 * k, k < done, None) for k in range(n)]


def test_eta_is_the_median_measured_angle_time_times_the_angles_left() -> None:
    eng = _engine(UniformPlan(rotations=8, exposure=FAST))
    # The slow first angle (the long move from where the stage was parked) is left out.
    eng._angle_times = [9.0, 1.0, 1.2, 0.8]
    p = eng._next_progress(_steps(8, 4))
    assert p.eta_s == pytest.approx(1.0 * 4)  # median of the last three, times four left
    assert p.eta_max_s is None and p.at == pytest.approx(time.time(), abs=5)


def test_after_the_first_angle_alone_the_eta_is_the_rigs_physical_estimate() -> None:
    """The first angle's time includes the travel from where the stage was: with it alone the
    ETA of a page scan read 13 s where 5 s were left. Until a second angle is done, the rig's
    physical time per angle (the dry run's) stands in."""
    eng = _engine(UniformPlan(rotations=8, exposure=FAST))
    per = eng.checked.per_angle_s
    eng._angle_times = [20 * per]  # a long first move
    p = eng._next_progress(_steps(8, 1))
    assert p.eta_s == pytest.approx(per * 7)
    eng._angle_times = [20 * per, 1.5 * per]  # the second angle: measured from here on
    assert eng._next_progress(_steps(8, 2)).eta_s == pytest.approx(1.5 * per * 6)


def test_adaptive_eta_has_a_bound_over_the_worst_case_angles() -> None:
    plan = AdaptivePlan(initial_rotations=8, max_rounds=3, max_rotations=None, exposure=FAST)
    eng = _engine(plan)
    eng._angle_times = [5.0, 2.0]  # the first (with its travel) left out
    p = eng._next_progress(_steps(8, 8))
    assert p.eta_s == 0.0  # the first round is done; nothing more is planned yet
    # ... but up to 8 + 16 more angles may come (dry run: max_angles = 32).
    assert dry_run(plan, eng.desc).max_angles == 32
    assert p.eta_max_s == pytest.approx(2.0 * 24)
    # With the default cap of 16 angles, only 8 more.
    capped = plan.model_copy(update={"max_rotations": 16})
    eng = _engine(capped)
    eng._angle_times = [5.0, 2.0]
    assert eng._next_progress(_steps(8, 8)).eta_max_s == pytest.approx(2.0 * 8)


def _no_basis() -> None:
    raise RuntimeError("this test measures only; no reconstruction")


def test_dry_run_starts_where_the_last_job_left_the_stage(tmp_path: Path) -> None:
    rig = MemRig()
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), rig, data_dir=tmp_path / "d",
                       basis=BasisSupply(_no_basis))
    plan = UniformPlan(rotations=4, exposure=FAST)
    before = svc.dry_run(plan)
    assert not before.from_known and before.from_deg == 0.0

    async def go() -> None:
        await svc.start()
        info = svc.submit(JobRequest(plan=UniformPlan(rotations=3, start_deg=100, exposure=FAST)))
        async for ev in svc.subscribe(0):
            if ev.type == "state" and ev.data["state"] in ("reconstructing", "failed"):
                break
        await svc.stop()
        assert info.id == 1

    asyncio.run(go())
    after = svc.dry_run(plan)
    assert after.from_known and after.from_deg == pytest.approx(rig.mstage.pos)
    assert after.from_deg != 0.0


def test_a_job_waiting_for_the_first_basis_build_says_so(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from gonio.brdf.materials import library
    from gonio.brdf.reconstruction import shipped

    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))  # no default basis cached
    w = Worker(JobStore(":memory:"), lambda: None, None, tmp_path,  # type: ignore[arg-type]
               BasisSupply())
    assert w.activity_report() is None
    w._set_activity("basis")
    assert w.activity_report() == ("loading the reconstruction basis", None)  # a moment only
    w._activity_since -= 5.0
    # With the shipped synthetic basis current, the default one is a fold-in: a load.
    assert shipped.is_current()
    assert w.activity_report() == ("loading the reconstruction basis", None)
    monkeypatch.setattr(shipped, "is_current", lambda: False)  # stale: the library is built
    monkeypatch.setattr(library, "build_progress", lambda: (57, 175))
    text, frac = w.activity_report()  # type: ignore[misc]
    assert "57 of 175 materials" in text and "first scan" in text
    assert frac == pytest.approx(57 / 175)
    monkeypatch.setattr(library, "build_progress", lambda: (175, 175))
    text, frac = w.activity_report()  # type: ignore[misc]
    assert "learning the reconstruction basis" in text and frac is None
    w._set_activity("reconstructing")
    assert w.activity_report() == ("reconstructing the BRDF from the readings", None)


def test_a_job_found_asymmetric_counts_the_asymmetric_basis_build_in_its_time(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Its finishing will build the basis for specimens without twofold symmetry (not built in
    this cache): the job's basis_build_s (which its time left adds, gonio.timeleft) includes
    it once the test has said so, and the worker's activity names it while it is built."""
    from gonio.jobstates import JobState
    from gonio.plans.arc import ARC_TEST_EVENT
    from gonio.plans.dryrun import ASYMMETRIC_BASIS_BUILD_S, BASIS_BUILD_S

    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))  # nothing cached
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(), data_dir=tmp_path / "d")
    plan = UniformPlan(rotations=4, arc="auto", exposure=FAST)
    job = svc.store.create_job(kind=plan.kind, specimen="x", plan=plan.model_dump(mode="json"),
                               rig=svc.desc.model_dump(mode="json")).id
    svc.store.set_state(job, JobState.RUNNING)
    assert svc.get_job(job).basis_build_s is None  # not tested yet
    svc.store.append_event(job, ARC_TEST_EVENT, {"symmetric": True, "statistic": 3.0,
                                                 "arc_deg": 180.0})
    assert svc.get_job(job).basis_build_s is None  # symmetric: the default basis
    svc.store.append_event(job, ARC_TEST_EVENT, {"symmetric": False, "statistic": 900.0,
                                                 "arc_deg": 360.0})
    detail = svc.get_job(job)
    # Neither library is tabulated in this cache: the default one's build comes first.
    assert detail.basis_build_s == ASYMMETRIC_BASIS_BUILD_S + BASIS_BUILD_S
    svc.worker._set_activity("asymmetric_basis")
    svc.worker._activity_since -= 5.0
    text, _ = svc.worker.activity_report()  # type: ignore[misc]
    assert "building" in text and "not twofold symmetric" in text
