"""GonioService on an in-memory rig: submit validation, control refusals, events, results."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest

from gonio.jobstates import IllegalTransition, JobState
from gonio.plans.models import CalibrationPlan, ExposureSettings, PlanError, UniformPlan
from gonio.results import read_result
from gonio.service import Conflict, GonioService, JobRequest, NotFound
from gonio.sim.memrig import MemRig
from gonio.store import JobStore

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0)


def _service(tmp_path: Path, *, fit_exports: bool = True) -> tuple[MemRig, GonioService]:
    rig = MemRig()
    return rig, GonioService(JobStore(tmp_path / "jobs.sqlite"), rig, data_dir=tmp_path / "d",
                             fit_exports=fit_exports)


def test_bad_request_refused_before_queueing(tmp_path: Path) -> None:
    rig, svc = _service(tmp_path)
    with pytest.raises(PlanError, match="at least one stage angle"):
        svc.submit(JobRequest(plan=UniformPlan(rotations=0)))
    with pytest.raises(PlanError, match="invalid job request"):
        svc.submit({"plan": {"kind": "uniform", "rotations": "many"}})
    assert svc.list_jobs() == []
    assert rig.mstage.moves == []


def test_calibration_job_runs_to_completion_with_events(tmp_path: Path) -> None:
    _rig, svc = _service(tmp_path)

    async def go() -> list[str]:
        await svc.start()
        info = svc.submit(JobRequest(plan=CalibrationPlan(
            reference_albedo=0.9, rotations=2, exposure=FAST)))
        types: list[str] = []
        async for ev in svc.subscribe(0):
            types.append(ev.type)
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        await svc.stop()
        assert svc.get_job(info.id).state is JobState.COMPLETED, svc.get_job(info.id).reason
        return types

    types = asyncio.run(go())
    assert types[0] == "created" and types.count("progress") == 2
    cal = json.loads((tmp_path / "d" / "calibration.json").read_text())
    assert len(cal["pairs"]) == 3 and cal["reference_albedo"] == 0.9
    res = read_result(svc.result_path(1))
    assert res.table is None and len(res.readings) == 6
    # factor * (raw - dark) of the reference is albedo / pi on average
    f = cal["pairs"][0]["factor"][0]
    vals = [(r.raw[0] - r.dark[0]) * f for r in res.readings
            if (r.light, r.sensor) == (cal["pairs"][0]["light"], cal["pairs"][0]["sensor"])]
    assert sum(vals) / len(vals) == pytest.approx(0.9 / 3.141592653589793)
    assert svc.metrics(1)["readings"] == 6


def test_actions_refused_with_clear_errors(tmp_path: Path) -> None:
    _, svc = _service(tmp_path)
    info = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST)))
    with pytest.raises(IllegalTransition, match="cannot pause job 1: it is queued"):
        svc.pause(info.id)
    with pytest.raises(IllegalTransition, match="cannot resume job 1: it is queued"):
        svc.resume(info.id)
    with pytest.raises(NotFound):
        svc.get_job(42)
    with pytest.raises(NotFound, match="no result yet"):
        svc.result_path(info.id)
    with pytest.raises(Conflict):
        svc.reorder(info.id)
    assert svc.get_job(info.id).queue_position == 0
    svc.cancel(info.id)
    assert svc.get_job(info.id).state is JobState.ABORTED
    with pytest.raises(IllegalTransition, match="cannot cancel job 1: it is aborted"):
        svc.cancel(info.id)
    with pytest.raises(IllegalTransition, match="cannot abort"):
        svc.abort(info.id)
    svc.remove(info.id)
    assert svc.list_jobs() == []


async def _paused_after_an_angle(svc: GonioService, plan: UniformPlan) -> int:
    """Start ``svc``, queue ``plan``, ask a pause once its first angle is measured; its id."""
    await svc.start()
    info = svc.submit(JobRequest(plan=plan))
    async for ev in svc.subscribe(0, job_id=info.id):
        if ev.type == "progress":
            break
    svc.pause(info.id)
    return info.id


def test_pause_resume_abort_through_the_service(tmp_path: Path) -> None:
    rig, svc = _service(tmp_path)
    plan = UniformPlan(rotations=20, exposure=ExposureSettings(exposure_s=0.01, light_settle_s=0))

    async def go() -> None:
        info_id = await _paused_after_an_angle(svc, plan)
        info = svc.get_job(info_id)
        async for ev in svc.subscribe(svc.seq - 1, job_id=info.id):
            if ev.data.get("state") == "paused":
                break
        with pytest.raises(IllegalTransition, match="cannot pause"):
            svc.pause(info.id)
        svc.resume(info.id)
        svc.abort(info.id)
        async for ev in svc.subscribe(0, job_id=info.id):
            if ev.data.get("state") == "aborted":
                break
        await svc.stop()

    asyncio.run(go())
    assert svc.get_job(1).state is JobState.ABORTED
    assert not rig.any_light_on()


def test_a_pause_asked_before_a_restart_holds_after_it(tmp_path: Path) -> None:
    """"pause asked" was answered, then the daemon stopped before the angle under way ended:
    the restarted daemon resumed the job measuring, though the lab may have reached for the
    specimen. The pause is kept (a pause_asked event): the job comes back paused, reads
    nothing until resumed, then completes."""
    slow = MemRig(speed_dps=20.0)  # an angle's move of 18 deg takes about a second
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), slow, data_dir=tmp_path / "d")
    plan = UniformPlan(rotations=10, exposure=ExposureSettings(exposure_s=0.01,
                                                               light_settle_s=0))

    async def first() -> int:
        job = await _paused_after_an_angle(svc, plan)
        await svc.stop()  # before the next checkpoint: the job stays active
        return job

    job = asyncio.run(first())
    assert svc.get_job(job).state is JobState.RUNNING
    done = svc.get_job(job).done_angles
    assert done < 10
    again = GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(speed_dps=3600.0),
                         data_dir=tmp_path / "d")

    async def second() -> None:
        await again.start()
        async with asyncio.timeout(60):  # a job that never pauses fails here, not hangs
            async for ev in again.subscribe(0, job_id=job):
                if ev.type == "state" and ev.data["state"] == "paused":
                    break
        await asyncio.sleep(0.5)  # time for angles, were it measuring
        assert again.get_job(job).state is JobState.PAUSED
        assert again.get_job(job).done_angles == done
        again.resume(job)
        async for ev in again.subscribe(0, job_id=job):
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        await again.stop()

    asyncio.run(second())
    assert again.get_job(job).state is JobState.COMPLETED, again.get_job(job).reason


def test_status_snapshot_and_readings_while_measuring(tmp_path: Path) -> None:
    rig, svc = _service(tmp_path)
    plan = UniformPlan(rotations=20, exposure=ExposureSettings(exposure_s=0.01, light_settle_s=0))
    n_pairs = len(rig.pairs)

    async def go() -> None:
        idle = svc.status()
        assert idle.current_job is None and idle.running is None and idle.queue_held is None
        await svc.start()
        info = svc.submit(JobRequest(plan=plan))
        async for ev in svc.subscribe(0, job_id=info.id):
            if ev.type == "progress" and ev.data["done"] >= 2:
                break
        st = svc.status()
        assert st.current_job == info.id and st.running is not None
        assert st.running.id == info.id and st.running.total_angles == 20
        assert 2 <= st.running.done_angles < 20
        rows = svc.readings(info.id)
        assert len(rows) >= 2 * n_pairs and len(rows) % n_pairs == 0
        first = min(r.angle_index for r in rows)
        assert all(r.angle_index > first for r in svc.readings(info.id, after_angle=first))
        svc.halt()
        assert svc.status().queue_held == "emergency halt"
        await svc.stop()

    asyncio.run(go())
    with pytest.raises(NotFound, match="no job with id 7"):
        svc.readings(7)


def test_scan_at_another_exposure_than_its_calibration_is_flagged(tmp_path: Path) -> None:
    from dataclasses import replace

    from gonio.calibration import Calibration
    from gonio.finishing import exposure_mismatch

    _rig, svc = _service(tmp_path)

    async def go() -> None:
        await svc.start()
        svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.9, rotations=2,
                                                   exposure=FAST)))
        async for ev in svc.subscribe(0, job_id=1):
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        await svc.stop()

    asyncio.run(go())
    cal = Calibration.model_validate_json((tmp_path / "d" / "calibration.json").read_text())
    assert cal.exposure_s == FAST.exposure_s
    same = svc.readings(1)
    assert exposure_mismatch(cal, same) is None
    longer = [replace(r, exposure_s=0.004) for r in same]
    msg = exposure_mismatch(cal, longer)
    assert msg is not None and "0.002 s" in msg and "0.004 s" in msg
    assert exposure_mismatch(Calibration(), longer) is None  # uncalibrated: nothing to flag


def test_queue_holds_are_stored_and_outlive_the_service(tmp_path: Path) -> None:
    _rig, svc = _service(tmp_path)
    svc.halt()  # nothing running: only the hold
    assert svc.status().queue_held == "emergency halt"
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST))).id
    # A new process on the same store (what a restart after kill -9 sees).
    _rig2, again = _service(tmp_path)
    assert again.status().queue_held == "emergency halt"
    assert again.worker.next_job() is None
    again.release_queue()
    assert again.worker.next_job() is not None and again.worker.next_job().id == job  # type: ignore[union-attr]
    _rig3, third = _service(tmp_path)
    assert third.status().queue_held is None  # the release was stored too


def test_a_failed_job_that_stops_the_queue_holds_it_across_restarts(tmp_path: Path) -> None:
    rig, svc = _service(tmp_path)
    rig.mstage.fault_next_moves = [hal_fault()]

    async def go() -> None:
        await svc.start()
        info = svc.submit(JobRequest(plan=UniformPlan(rotations=2, start_deg=30, exposure=FAST,
                                                      stop_queue_on_failure=True)))
        async for ev in svc.subscribe(0):
            if ev.type == "state" and ev.data["state"] == "failed" and ev.job_id == info.id:
                break
        await svc.stop()

    asyncio.run(go())
    _rig2, again = _service(tmp_path)
    assert again.status().queue_held == "job 1 failed and asked to stop the queue"


def hal_fault() -> Exception:
    from gonio import hal

    return hal.StageFault("stage", "encoder broken", code="encoder", recoverable=False)


def test_the_maintenance_lock_stops_queued_and_resumed_jobs(tmp_path: Path) -> None:
    _rig, svc = _service(tmp_path)
    queued = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST))).id
    svc.maintenance.lock("replacing lamp L2", by="alice")
    assert svc.worker.next_job() is None
    assert svc.status().queue_held == "maintenance lock: replacing lamp L2"
    # A job left running by a previous process does not resume under the lock either.
    svc.store.set_state(queued, JobState.RUNNING)
    _rig2, again = _service(tmp_path)  # the lock is a file: a restart sees it
    assert again.worker.next_job() is None
    (tmp_path / "d" / "MAINTENANCE").unlink()  # released from a shell
    nxt = again.worker.next_job()
    assert nxt is not None and nxt.id == queued


def test_a_plan_the_calibration_covers_in_part_is_refused_at_submission(tmp_path: Path
                                                                        ) -> None:
    from gonio.calibration import Calibration, PairCalibration
    from gonio.hal import PairSpec

    rig = MemRig()
    pairs = list(rig.pairs)
    # Three channels, as the MemRig sensors read (a calibration of other sensors is refused
    # before the check under test).
    cal = Calibration(pairs=(PairCalibration(light=pairs[0].light, sensor=pairs[0].sensor,
                                             factor=(1e-4,) * 3),), source="test")
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), rig, data_dir=tmp_path / "d",
                       calibration=cal)
    with pytest.raises(PlanError, match="no factors for") as e:
        svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST)))
    assert all(p.label() in str(e.value) for p in pairs[1:])
    assert svc.list_jobs() == [] and rig.mstage.moves == []
    # Only its calibrated pair: accepted. A calibration job needs none: accepted.
    one = [PairSpec(light=pairs[0].light, sensor=pairs[0].sensor)]
    svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST, pairs=one)))
    svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.9, exposure=FAST)))
    assert len(svc.list_jobs()) == 2


def test_a_plan_checked_before_submission_is_the_one_that_runs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`gonio scan` checks its plan once and submits it with the check: the job runs with
    that check (its engine holds the same CheckedPlan); a check of another plan is not
    taken for the request's, which is checked and refused on its own."""
    from gonio.engine import ScanEngine
    from gonio.plans.checked import check_plan

    # The job's export fits are not under test (seconds of CPU; a daemon's scan stores
    # them in tests/system/api/test_colour.py).
    rig, svc = _service(tmp_path, fit_exports=False)
    plan = UniformPlan(rotations=2, exposure=FAST)
    checked = svc.check(plan)
    assert svc.dry_run(checked) == svc.dry_run(plan)
    with pytest.raises(PlanError, match="at least one stage angle"):
        svc.submit(JobRequest(plan=UniformPlan(rotations=0)), checked=checked)
    info = svc.submit(JobRequest(plan=plan), checked=checked)
    seen: list[object] = []
    real_run = ScanEngine.run

    async def run(engine: ScanEngine) -> JobState:  # the real run, noting its plan
        seen.append(engine.checked)
        return await real_run(engine)

    async def go() -> JobState:
        try:
            return await svc.run_in_foreground(info.id)
        finally:
            await svc.stop()

    monkeypatch.setattr(ScanEngine, "run", run)
    assert asyncio.run(go()) is JobState.COMPLETED
    assert seen == [checked] and seen[0] is checked
    assert check_plan(plan, svc.desc) == checked
    assert len(rig.mstage.moves) >= 2


def test_the_start_refuses_only_an_unasked_uncalibrated_scan(tmp_path: Path) -> None:
    # Whether a scan would be uncalibrated on a rig calibrated elsewhere is the daemon's
    # (tests/system/api/test_calibration_state.py); here, what the job keeps of its user's
    # acceptance and what the start makes of it.
    _, svc = _service(tmp_path)
    svc._uncalibrated_why = lambda plan: "calibrated elsewhere"  # type: ignore[method-assign]
    plan = UniformPlan(rotations=2, exposure=FAST)
    unasked = svc.submit(JobRequest(plan=plan))
    accepted = svc.submit(JobRequest(plan=plan), accept_uncalibrated=True)
    moved = svc.submit(JobRequest(plan=plan))
    svc.store.append_event(moved.id, "uncalibrated_accepted", {"by": "reorder"})
    # Queued by a gonio that kept no acceptance: its created event lacks the key.
    older = svc.store.create_job(kind="uniform", specimen="x", plan=plan.model_dump(mode="json"),
                                 rig=svc.desc.model_dump(mode="json"))
    rows = {j: svc.store.get_job(j) for j in (unasked.id, accepted.id, moved.id, older.id)}
    why = svc.unasked_uncalibrated(rows[unasked.id], plan)
    assert why is not None
    assert why.startswith("calibrated elsewhere. It was queued without asking, before"), why
    assert "accept_uncalibrated=true" in why
    for job in (accepted.id, moved.id, older.id):
        assert svc.unasked_uncalibrated(rows[job], plan) is None, job
    # A scan the calibration in effect covers (no reason) starts whatever it was asked.
    svc._uncalibrated_why = lambda plan: None  # type: ignore[method-assign]
    assert svc.unasked_uncalibrated(rows[unasked.id], plan) is None


def test_queued_jobs_say_when_they_start_or_that_it_is_not_known(tmp_path: Path) -> None:
    """Each queued job's starts_in_s: the rig is free (nothing runs: the worker is not
    started), so the first starts now and each later one after the dry-run durations of those
    ahead (a scan's with the finishing estimate, the first scan's with a due basis build);
    a held queue makes every start unknown, said, never a number."""
    from gonio.plans.dryrun import BASIS_BUILD_S

    _rig, svc = _service(tmp_path)
    cal_plan = CalibrationPlan(rotations=2, reference_albedo=0.99, exposure=FAST)
    scan_plan = UniformPlan(rotations=3, exposure=FAST)
    cal = svc.submit(JobRequest(plan=cal_plan)).id
    first = svc.submit(JobRequest(plan=scan_plan)).id
    second = svc.submit(JobRequest(plan=scan_plan)).id
    jobs = {j.id: j for j in svc.list_jobs()}
    finishing = svc._finishing_estimate().seconds
    build = BASIS_BUILD_S if svc.basis.build_needed() else 0.0
    cal_s = svc.dry_run(cal_plan).estimated_s
    scan_s = svc.dry_run(scan_plan).estimated_s
    assert jobs[cal].starts_in_s == 0.0
    assert jobs[first].starts_in_s == pytest.approx(cal_s)
    assert jobs[second].starts_in_s == pytest.approx(cal_s + scan_s + finishing + build)
    assert not any(j.starts_in_bound for j in jobs.values())
    assert jobs[second].starts_in_estimate == (
        f"the estimated durations of jobs {cal}, {first} ahead")
    # The job's own view says the same.
    assert svc.get_job(second).starts_in_s == jobs[second].starts_in_s
    svc.halt()
    for job in svc.list_jobs():
        assert job.starts_in_s is None
        assert job.starts_in_estimate is not None
        assert job.starts_in_estimate.startswith("not known: the queue is held (emergency halt)")
    svc.release_queue()
    svc.cancel(cal)
    ended = svc.get_job(cal)
    assert ended.starts_in_s is None and ended.starts_in_estimate is None
    assert svc.list_jobs()[1].starts_in_s == 0.0


def test_an_auto_arc_scan_ahead_bounds_the_start_with_the_asymmetric_basis_build(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A scan queued behind an auto-arc scan said "starts within 17 s" and started 65 s
    later: the bound left out the asymmetric branch, whose basis (not built yet on a fresh
    machine) is built before that scan finishes. Counted once, in the bound."""
    from gonio.plans.dryrun import BASIS_BUILD_S
    _rig, svc = _service(tmp_path)
    monkeypatch.setattr(svc.basis, "asymmetric_build_needed", lambda: True)
    monkeypatch.setattr(svc.basis, "asymmetric_build_s", lambda: 240.0)
    auto = UniformPlan(rotations=3, exposure=FAST, arc="auto")
    plain = UniformPlan(rotations=3, exposure=FAST)
    first = svc.submit(JobRequest(plan=auto)).id
    second = svc.submit(JobRequest(plan=plain)).id
    third = svc.submit(JobRequest(plan=auto)).id
    jobs = {j.id: j for j in svc.list_jobs()}
    assert jobs[first].starts_in_s == 0.0  # the rig is free
    finishing = svc._finishing_estimate().seconds
    build = BASIS_BUILD_S if svc.basis.build_needed() else 0.0
    auto_s = svc.dry_run(auto).max_estimated_s
    plain_s = svc.dry_run(plain).estimated_s
    assert auto_s is not None
    assert jobs[second].starts_in_s == pytest.approx(auto_s + finishing + build + 240.0)
    assert jobs[second].starts_in_bound
    # The build happens once: the second auto-arc scan does not add it again.
    assert jobs[third].starts_in_s == pytest.approx(
        auto_s + finishing + build + 240.0 + plain_s + finishing)


def test_a_full_turn_scan_ahead_bounds_the_start_with_the_asymmetric_basis_build(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A fixed full turn is tested for twofold symmetry when it finishes, and a specimen it
    calls asymmetric waits for that basis there: "13 s left" stood through a two-minute
    build, and the scans behind it were timed without it. Its finishing (dry run) and the
    starts behind it count the build as a bound, once; a half turn does not."""
    from gonio.plans.dryrun import BASIS_BUILD_S
    _rig, svc = _service(tmp_path)
    monkeypatch.setattr(svc.basis, "asymmetric_build_needed", lambda: True)
    monkeypatch.setattr(svc.basis, "asymmetric_build_s", lambda: 240.0)
    full = UniformPlan(rotations=4, span_deg=360.0, exposure=FAST)
    half = UniformPlan(rotations=4, exposure=FAST)
    finishing = svc._finishing_estimate().seconds
    assert finishing is not None
    build = BASIS_BUILD_S if svc.basis.build_needed() else 0.0
    assert svc.dry_run(full).finishing_s == pytest.approx(finishing + build + 240.0)
    assert "without twofold symmetry" in (svc.dry_run(full).finishing_source or "")
    assert svc.dry_run(half).finishing_s == pytest.approx(finishing + build)
    # Five angles over a full turn hold no opposite ones: never tested, nothing to wait for.
    odd = UniformPlan(rotations=5, span_deg=360.0, exposure=FAST)
    assert svc.dry_run(odd).finishing_s == pytest.approx(finishing + build)
    first = svc.submit(JobRequest(plan=full)).id
    second = svc.submit(JobRequest(plan=half)).id
    third = svc.submit(JobRequest(plan=full)).id
    jobs = {j.id: j for j in svc.list_jobs()}
    full_s, half_s = svc.dry_run(full).estimated_s, svc.dry_run(half).estimated_s
    assert jobs[second].starts_in_s == pytest.approx(full_s + finishing + build + 240.0)
    assert jobs[second].starts_in_bound
    assert jobs[third].starts_in_s == pytest.approx(
        full_s + finishing + build + 240.0 + half_s + finishing)
    assert jobs[first].starts_in_s == 0.0


def test_a_queued_plan_that_cannot_be_timed_leaves_the_job_list_answering(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A stored plan whose dry run raises something other than PlanError (an older plan, a
    bug) failed every GET /api/v1/jobs while it was queued: its start is unknown instead, and
    so are those of the jobs behind it; the job itself and the list still answer."""
    import gonio.service as service_module

    def broken(*args: object, **kwargs: object) -> None:
        raise ValueError("a plan this gonio cannot time")

    _rig, svc = _service(tmp_path)
    monkeypatch.setattr(service_module, "dry_run", broken)
    plan = UniformPlan(rotations=3, exposure=FAST)
    first = svc.submit(JobRequest(plan=plan)).id
    second = svc.submit(JobRequest(plan=plan)).id
    jobs = {j.id: j for j in svc.list_jobs()}
    assert jobs[first].starts_in_s == 0.0  # nothing ahead of it
    assert jobs[second].starts_in_s is None and jobs[second].starts_in_estimate


def test_a_submission_and_a_reorder_answer_with_the_jobs_start(tmp_path: Path) -> None:
    """POST /jobs and the reorder answered starts_in_estimate null, which the schema defines
    as "not queued", for a job that was queued: they answer as the job list does."""
    _rig, svc = _service(tmp_path)
    plan = UniformPlan(rotations=3, exposure=FAST)
    first = svc.submit(JobRequest(plan=plan))
    second = svc.submit(JobRequest(plan=plan))
    listed = {j.id: j for j in svc.list_jobs()}
    assert first.starts_in_estimate is not None and first.starts_in_s == 0.0
    assert second.starts_in_s == listed[second.id].starts_in_s is not None
    moved = svc.reorder(second.id, position=0)
    assert moved.starts_in_s == 0.0 and moved.starts_in_estimate is not None


def test_a_job_taken_while_the_queue_is_read_does_not_wait_for_itself(tmp_path: Path) -> None:
    """The worker took job 1 between the service's two reads of the store (the queue, then the
    jobs holding the rig): its start estimate was its own time left, "starts in about 37 s
    (job 1's time left)", for a job that had just started. It is answered as queued with the
    rig free (the other read decides nothing about a job the first read listed)."""
    _rig, svc = _service(tmp_path)
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST))).id
    real_queue = svc.store.queue

    def queue_then_taken() -> Any:
        rows = real_queue()
        if svc.store.get_job(job).state is JobState.QUEUED:
            svc.store.set_state(job, JobState.RUNNING)  # as the worker does, just after
        return rows

    svc.store.queue = queue_then_taken  # type: ignore[method-assign]
    (info,) = svc.list_jobs()
    assert info.state is JobState.QUEUED  # the list's own read, before the worker took it
    assert info.starts_in_s == 0.0, info
    assert f"job {job}" not in (info.starts_in_estimate or ""), info.starts_in_estimate


def test_a_damaged_calibration_file_does_not_block_moving_the_calibration_that_replaces_it(
        tmp_path: Path) -> None:
    """The reorder judges which calibration each queued scan would start under, reading the
    calibration in effect; a damaged calibration file (which the worker refuses with its
    reason when a scan starts) must not refuse the move that puts a new calibration job
    first: it answered the file's error instead."""
    from gonio.calibration import CALIBRATION_FILE, CalibrationError

    _rig, svc = _service(tmp_path)
    svc.halt()  # nothing starts: the jobs stay queued
    plan = UniformPlan(rotations=3, exposure=FAST)
    scan = svc.submit(JobRequest(plan=plan))
    cal = svc.submit(JobRequest(plan=CalibrationPlan(rotations=2, reference_albedo=0.99,
                                                     exposure=FAST)))
    damaged = tmp_path / "d" / CALIBRATION_FILE
    damaged.parent.mkdir(parents=True, exist_ok=True)
    damaged.write_text("{ not json")
    with pytest.raises(CalibrationError):
        svc.calibration()  # the file is damaged, as this test means it to be
    moved = svc.reorder(cal.id, position=0)
    assert moved.id == cal.id
    assert [r.id for r in svc.store.queue()] == [cal.id, scan.id]
