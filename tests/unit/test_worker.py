"""The worker loads the basis of an adaptive job before its first reading, not mid-scan.

Through the real worker and engine on the in-memory rig: what is asserted is the order of
things (events in the store, what had been read when the basis was asked for), never times.
"""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path
from typing import Any

import pytest

from gonio.basis_supply import BasisSupply
from gonio.jobstates import JobState
from gonio.plans.dryrun import BASIS_BUILD_S, dry_run
from gonio.plans.models import AdaptivePlan, ExposureSettings, UniformPlan
from gonio.rigdescription import RigDescription
from gonio.service import GonioService, JobRequest
from gonio.sim.memrig import MemRig
from gonio.store import JobStore
from gonio.worker import Worker
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")
BASIS = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 1.0})
# min_gain tiny: the MemRig's readings swing with cos 2 alpha, so the posterior refines.
PLAN = AdaptivePlan(initial_rotations=8, exposure=FAST, min_gain=1e-9, max_rounds=2)


class Provider:
    """A basis provider that records, at each call, how many readings the job had and on
    which thread it ran; raises after ``serve`` calls (finishing is not under test)."""

    def __init__(self, store: JobStore, serve: int = 1, fail: Exception | None = None) -> None:
        self.store, self.serve, self.fail = store, serve, fail
        self.calls: list[tuple[int, str]] = []

    def __call__(self) -> Any:
        self.calls.append((len(self.store.readings(1)), threading.current_thread().name))
        if self.fail is not None:
            raise self.fail
        if len(self.calls) > self.serve:
            raise RuntimeError("this test measures only; no reconstruction")
        return BASIS


def _worker(store: JobStore, provider: Provider, data_dir: Path
            ) -> tuple[Worker, RigDescription]:
    """The worker on a MemRig; results go under ``data_dir`` (a test's tmp_path, never the
    working directory)."""
    rig = MemRig()
    desc = RigDescription.from_rig(rig)

    async def get_rig() -> MemRig:
        return rig

    return Worker(store, get_rig, desc, data_dir, BasisSupply(provider),
                  fit_exports=False), desc


def _submit(store: JobStore, desc: RigDescription, plan: AdaptivePlan | UniformPlan) -> int:
    return store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                            rig=desc.model_dump(mode="json")).id


def _types(store: JobStore, job_id: int) -> list[str]:
    return [e.type for e in store.events_after(0) if e.job_id == job_id]


def test_an_adaptive_job_loads_its_basis_before_the_first_reading(tmp_path: Path) -> None:
    store = JobStore(":memory:")
    provider = Provider(store, serve=2)
    w, desc = _worker(store, provider, tmp_path)
    job = _submit(store, desc, PLAN)
    asyncio.run(w.run_once())
    # First call: no reading taken yet, and not on the event loop's thread.
    assert provider.calls[0][0] == 0
    assert provider.calls[0][1] != threading.main_thread().name
    types = _types(store, job)
    first_reading = next(i for i, t in enumerate(types) if t == "progress")
    assert types.index("basis_loading") < types.index("basis_ready") < first_reading
    # The rounds used that basis: the posterior rule planned them, and no later call
    # happened while measuring (the second call is finishing's, after every reading).
    rounds = [e.data for e in store.events_after(0) if e.type == "adaptive_round"]
    assert rounds and rounds[0]["rule"] == "posterior"
    assert all(n == len(store.readings(job)) for n, _ in provider.calls[1:])
    loading = next(e.data for e in store.events_after(0) if e.type == "basis_loading")
    assert loading["build"] is False and "before the first reading" in str(loading["message"])
    # Finished by the adaptive reconstruction, which records the prior factor it used.
    row = store.get_job(job)
    assert row.state is JobState.COMPLETED, row.reason
    assert row.summary is not None and 0 < row.summary["prior_rho"] <= 1.0


def test_uniform_and_vf_jobs_do_not_wait_for_the_basis(tmp_path: Path) -> None:
    store = JobStore(":memory:")
    provider = Provider(store, serve=0)
    w, desc = _worker(store, provider, tmp_path)
    for plan in (UniformPlan(rotations=4, exposure=FAST),
                 AdaptivePlan(initial_rotations=4, exposure=FAST, rule="vf", max_rounds=1)):
        job = _submit(store, desc, plan)
        asyncio.run(w.run_once())
        assert "basis_loading" not in _types(store, job)
        # The only call is finishing's, after measuring.
        assert provider.calls[-1][0] == len(store.readings(job)) > 0


def test_a_basis_that_cannot_be_had_leaves_the_job_measuring_with_the_vf_rule(
        tmp_path: Path) -> None:
    store = JobStore(":memory:")
    provider = Provider(store, fail=OSError("basis file unreadable"))
    w, desc = _worker(store, provider, tmp_path)
    plan = AdaptivePlan(initial_rotations=8, exposure=FAST, threshold=0.01, max_rounds=2)
    job = _submit(store, desc, plan)
    asyncio.run(w.run_once())
    events = [e for e in store.events_after(0) if e.job_id == job]
    failed = next(e.data for e in events if e.type == "basis_failed")
    assert "unreadable" in str(failed["message"]) and "V&F" in str(failed["note"])
    rounds = [e.data for e in events if e.type == "adaptive_round"]
    assert rounds and rounds[0]["rule"] == "vf"
    assert {s.round for s in store.steps(job)} == {0, 1}


def test_a_job_cancelled_while_its_basis_loads_never_moves_the_stage(tmp_path: Path) -> None:
    """The status says what the job waits for; a cancel during the wait is honoured."""
    release = threading.Event()
    entered = threading.Event()

    def slow_basis() -> Any:
        entered.set()
        release.wait(60)
        return BASIS

    rig = MemRig()
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), rig, data_dir=tmp_path / "d",
                       basis=BasisSupply(slow_basis))

    async def go() -> tuple[str | None, JobState]:
        await svc.start()
        info = svc.submit(JobRequest(plan=PLAN))
        await asyncio.to_thread(entered.wait, 60)
        activity = svc.get_job(info.id).activity
        svc.cancel(info.id)
        release.set()
        for _ in range(1200):  # until the worker has let go of the job (generous)
            if svc.worker.current_job is None:
                break
            await asyncio.sleep(0.05)
        state = svc.get_job(info.id).state
        await svc.stop()
        return activity, state

    activity, state = asyncio.run(go())
    assert activity is not None and "before the first reading" in activity
    assert state is JobState.ABORTED
    assert svc.readings(1) == []
    assert svc.store.steps(1) == []


def test_at_start_a_queue_with_an_adaptive_job_builds_the_basis_in_the_background(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    store = JobStore(":memory:")
    provider = Provider(store, serve=2)
    w, desc = _worker(store, provider, tmp_path)
    monkeypatch.setattr(w.basis, "build_needed", lambda: True)
    job = _submit(store, desc, PLAN)

    async def go() -> None:
        task = asyncio.create_task(w.run_forever())
        while store.get_job(job).state not in (JobState.RECONSTRUCTING, JobState.FAILED,
                                                JobState.COMPLETED):
            await asyncio.sleep(0.05)
        await w.stop()
        task.cancel()

    asyncio.run(go())
    prewarm = [e for e in store.events_after(0) if e.type == "basis_prewarm"]
    assert prewarm and prewarm[0].data["jobs"] == [job]
    # The job's own load waited for that build (one at a time) and took its basis: the
    # basis was made once, before any reading.
    assert provider.calls == [(0, "gonio-basis-prewarm")]
    loading = next(e.data for e in store.events_after(0) if e.type == "basis_loading")
    assert loading["build"] is True and "building" in str(loading["message"])


def test_at_start_nothing_is_built_for_a_queue_without_adaptive_jobs(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    store = JobStore(":memory:")
    provider = Provider(store, serve=0)
    w, desc = _worker(store, provider, tmp_path)
    monkeypatch.setattr(w.basis, "build_needed", lambda: True)
    _submit(store, desc, UniformPlan(rotations=4, exposure=FAST))
    w._loop = None
    w._start_prewarm()
    assert not w.basis.prewarming and provider.calls == []


def test_the_dry_run_says_when_the_first_adaptive_job_builds_the_basis(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(), data_dir=tmp_path / "d",
                       basis=BasisSupply(lambda: BASIS))
    assert svc.dry_run(PLAN).basis_build_s is None  # a provider that loads
    monkeypatch.setattr(svc.basis, "build_needed", lambda: True)
    dr = svc.dry_run(PLAN)
    plain = dry_run(PLAN, svc.desc, svc.stage_deg)
    assert dr.basis_build_s == BASIS_BUILD_S
    assert dr.estimated_s == plain.estimated_s  # the physical time is unchanged ...
    assert dr.max_estimated_s == pytest.approx(plain.max_estimated_s + BASIS_BUILD_S)  # type: ignore[operator]
    # ... and plans that do not measure with the basis are not delayed by it.
    assert svc.dry_run(UniformPlan(rotations=8)).basis_build_s is None
    assert svc.dry_run(AdaptivePlan(rule="vf")).basis_build_s is None


def test_the_cli_dry_run_summary_names_the_build() -> None:
    from gonio.cli.scan_report import dry_run_summary

    desc = RigDescription.from_rig(MemRig())
    text = dry_run_summary(dry_run(PLAN, desc, basis_ready=False), PLAN, "mem")
    assert "builds it before its first reading" in text and "2.0 min" in text
    assert "builds it" not in dry_run_summary(dry_run(PLAN, desc), PLAN, "mem")


def test_a_job_the_calibration_in_effect_covers_in_part_fails_before_anything_moves(
    tmp_path: Path,
) -> None:
    """Submission refuses such a plan; a calibration that changed after it (a new calibration
    job, a file edited by hand) is caught again when the job starts."""
    from gonio.calibration import Calibration, PairCalibration

    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    first = rig.pairs[0]
    cal = Calibration(pairs=(PairCalibration(light=first.light, sensor=first.sensor,
                                             factor=(1e-4,)),), source="edited by hand")

    async def get_rig() -> MemRig:
        return rig

    store = JobStore(tmp_path / "jobs.sqlite")
    w = Worker(store, get_rig, desc, tmp_path / "d", BasisSupply(lambda: BASIS),
               calibration=lambda: cal)
    plan = UniformPlan(rotations=2, exposure=FAST)
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json")).id
    row = asyncio.run(w.run_once())
    assert row is not None and row.id == job and row.state is JobState.FAILED
    assert row.reason is not None and row.reason.startswith("not started: ")
    assert "(edited by hand) has no factors for" in row.reason
    assert rig.mstage.moves == [] and store.reading_count(job) == 0


def test_checked_plans_of_jobs_that_never_start_are_dropped(tmp_path: Path) -> None:
    """The worker keeps each submitted job's checked plan until the job starts; those of
    jobs cancelled before they start are dropped once it keeps more than KEEP_CHECKED, and
    a queued job's stays (it starts with it)."""
    from gonio.plans.checked import check_plan
    from gonio.plans.models import UniformPlan
    from gonio.worker import KEEP_CHECKED

    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    store = JobStore(tmp_path / "jobs.sqlite")

    async def get_rig() -> MemRig:
        return rig

    worker = Worker(store, get_rig, desc, data_dir=tmp_path, basis=BasisSupply(lambda: BASIS))
    checked = check_plan(UniformPlan(rotations=2), desc)
    ids = []
    for _ in range(KEEP_CHECKED + 1):
        row = store.create_job(kind="uniform", specimen="s",
                               plan=checked.plan.model_dump(mode="json"),
                               rig=desc.model_dump(mode="json"))
        worker.take_checked(row.id, checked)
        ids.append(row.id)
    kept = ids[-1]
    for job_id in ids[:-2]:
        store.set_state(job_id, JobState.ABORTED, reason="cancelled")  # as a cancel does
    extra = store.create_job(kind="uniform", specimen="s",
                             plan=checked.plan.model_dump(mode="json"),
                             rig=desc.model_dump(mode="json"))
    worker.take_checked(extra.id, checked)
    assert set(worker._checked) == {ids[-2], kept, extra.id}
    assert worker._checked_plan(store.get_job(kept)) is checked
    assert kept not in worker._checked


def _calibration_with(rig: MemRig, channels: int) -> Any:
    """A calibration of every pair of ``rig`` at FAST's exposure, ``channels`` per factor."""
    from gonio.calibration import Calibration, PairCalibration

    return Calibration(pairs=tuple(PairCalibration(light=p.light, sensor=p.sensor,
                                                   factor=(1e-4,) * channels)
                                   for p in rig.pairs),
                       exposure_s=FAST.exposure_s, source="job 9: spectral white reference")


def _other_sensors_calibration(rig: MemRig) -> Any:
    """A calibration of every pair of ``rig`` with 31 channels per factor (its sensors read
    3): one measured with spectrometers that have the RGB sensors' names and directions."""
    return _calibration_with(rig, 31)


def test_a_calibration_of_other_sensors_refuses_the_job_before_anything_moves(
    tmp_path: Path,
) -> None:
    """Factors with 31 channels for sensors that read 3 made the job measure every angle and
    fail only when it finished ("calibration of pair L1/S1 has 31 channels, the readings have
    3"); the job is refused when it starts, naming both counts and what to do."""
    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    cal = _other_sensors_calibration(rig)

    async def get_rig() -> MemRig:
        return rig

    store = JobStore(tmp_path / "jobs.sqlite")
    w = Worker(store, get_rig, desc, tmp_path / "d", BasisSupply(lambda: BASIS),
               calibration=lambda: cal)
    job = _submit(store, desc, UniformPlan(rotations=2, exposure=FAST))
    row = asyncio.run(w.run_once())
    assert row is not None and row.id == job and row.state is JobState.FAILED
    assert row.reason is not None and row.reason.startswith("not started: ")
    assert "have 31 channels, sensor" in row.reason and "reads 3" in row.reason
    assert "--white-reference" in row.reason
    assert rig.mstage.moves == [] and store.reading_count(job) == 0


def test_submission_refuses_a_calibration_of_other_sensors_unless_one_is_queued(
    tmp_path: Path,
) -> None:
    """The API's and gonio scan's submission refuse such a scan (PlanError), but accept it
    behind a queued calibration job, which calibrates these sensors before it starts."""
    from gonio.service import PlanError
    from gonio.sim.rig import WHITE_REFERENCE_ALBEDO

    rig = MemRig()
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), rig, data_dir=tmp_path / "d",
                       calibration=_other_sensors_calibration(rig))
    scan = UniformPlan(rotations=2, exposure=FAST)
    with pytest.raises(PlanError, match=r"31 channels, sensor .* reads 3"):
        svc.submit(JobRequest(plan=scan))
    assert svc.store.list_jobs() == []
    from gonio.plans.models import CalibrationPlan

    svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=WHITE_REFERENCE_ALBEDO,
                                               exposure=FAST)))
    assert svc.submit(JobRequest(plan=scan)).state is JobState.QUEUED


def test_a_calibration_queued_below_the_scans_priority_does_not_let_it_through(
    tmp_path: Path,
) -> None:
    """The queue takes the higher priority first: a calibration queued at priority 0 runs
    after a scan submitted at 5, so it calibrates nothing for that scan. Such a scan was
    accepted and then failed "not started" at its first move; it is refused at submission,
    naming the calibration job and what to do. The same for a calibration at the scan's
    exposure; at the calibration's priority or below, both are accepted."""
    from gonio.plans.models import CalibrationPlan
    from gonio.service import PlanError
    from gonio.sim.rig import WHITE_REFERENCE_ALBEDO

    rig = MemRig()
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), rig, data_dir=tmp_path / "d",
                       calibration=_other_sensors_calibration(rig))
    svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=WHITE_REFERENCE_ALBEDO,
                                               exposure=FAST)))
    scan = UniformPlan(rotations=2, exposure=FAST)
    with pytest.raises(PlanError, match=r"31 channels, sensor .* reads 3.* \(calibration job 1 "
                       r"is queued at priority 0, below this scan's 5: it would run after the "
                       r"scan; queue the scan at priority 0 or lower, or raise the "
                       r"calibration's priority first\)"):
        svc.submit(JobRequest(plan=scan, priority=5))
    assert [j.id for j in svc.store.list_jobs()] == [1]
    assert svc.submit(JobRequest(plan=scan, priority=0)).state is JobState.QUEUED

    # The exposure: the calibration in effect was measured at FAST's 2 ms; a calibration job
    # at 4 ms, queued at priority -1, runs after a 4 ms scan at 0.
    other = tmp_path / "other"
    svc2 = GonioService(JobStore(other / "jobs.sqlite"), rig, data_dir=other / "d",
                        calibration=_calibration_with(rig, 3))
    slow = ExposureSettings(exposure_s=0.004, light_settle_s=0.0)
    svc2.submit(JobRequest(plan=CalibrationPlan(reference_albedo=WHITE_REFERENCE_ALBEDO,
                                                exposure=slow), priority=-1))
    with pytest.raises(PlanError, match=r"0\.004 s.*\(calibration job 1 is queued at priority "
                       r"-1, below this scan's 0"):
        svc2.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=slow)))
    assert svc2.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=slow),
                                  priority=-1)).state is JobState.QUEUED
