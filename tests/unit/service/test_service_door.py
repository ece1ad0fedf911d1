"""The service as the one door: foreground runs (gonio scan), the worker's handle on the job
being measured, and the one readings-to-array function."""

from __future__ import annotations

import asyncio
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gonio.calibration import Calibration, PairCalibration, readings_array
from gonio.hal import PairSpec
from gonio.jobstates import JobState
from gonio.plans.models import CalibrationPlan, ExposureSettings, UniformPlan
from gonio.service import Conflict, GonioService, JobRequest
from gonio.sim.memrig import MemRig
from gonio.store import JobStore

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0)


def _service(tmp_path: Path) -> GonioService:
    return GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(), data_dir=tmp_path / "d")


def test_foreground_run_measures_one_job_and_leaves_the_others(tmp_path: Path) -> None:
    svc = _service(tmp_path)
    other = svc.submit(JobRequest(plan=UniformPlan(rotations=3, exposure=FAST)))
    mine = svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.9, rotations=2,
                                                      exposure=FAST)))

    async def go() -> JobState:
        try:
            return await svc.run_in_foreground(mine.id)
        finally:
            await svc.stop()

    assert asyncio.run(go()) is JobState.COMPLETED
    assert svc.get_job(mine.id).done_angles == 2
    # No queue worker: the job queued before it was not taken.
    assert svc.get_job(other.id).state is JobState.QUEUED


def test_unfinished_job_is_the_same_plan_only(tmp_path: Path) -> None:
    svc = _service(tmp_path)
    plan = UniformPlan(rotations=4, exposure=FAST)
    job = svc.submit(JobRequest(plan=plan))
    svc.store.set_state(job.id, JobState.RUNNING)  # as a killed scan leaves it
    found = svc.unfinished_job(plan)
    assert found is not None and found.id == job.id
    assert svc.unfinished_job(UniformPlan(rotations=5, exposure=FAST)) is None
    # A foreground run judges no other job: it stays active.
    assert svc.get_job(job.id).state is JobState.RUNNING


def test_foreground_run_refused_while_the_queue_worker_runs(tmp_path: Path) -> None:
    svc = _service(tmp_path)

    async def go() -> None:
        await svc.start()
        try:
            job = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST)))
            with pytest.raises(Conflict, match="worker runs the queue"):
                await svc.run_in_foreground(job.id)
        finally:
            await svc.stop()

    asyncio.run(go())


def test_worker_controls_refuse_a_job_that_is_not_measuring(tmp_path: Path) -> None:
    svc = _service(tmp_path)
    w = svc.worker
    assert w.measuring() is None and w.progress() is None and w.progress(1) is None
    assert not w.pause_measurement(1) and not w.resume_measurement(1)
    assert not w.abort_measurement(1)
    w.halt_measurement()  # nothing measuring: nothing to stop, no error


def _reading(angle: int, light: str, sensor: str, raw: tuple[float, ...],
             dark: tuple[float, ...]) -> SimpleNamespace:
    return SimpleNamespace(angle_index=angle, light=light, sensor=sensor, raw=raw, dark=dark)


def test_readings_array_orders_subtracts_calibrates_and_marks_gaps() -> None:
    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L2", sensor="S1")]
    readings = [
        _reading(0, "L1", "S1", (10.0, 20.0), (1.0, 2.0)),
        _reading(1, "L1", "S1", (30.0, 40.0), (1.0, 2.0)),
        _reading(1, "L2", "S1", (5.0, 6.0), (1.0, 1.0)),
        _reading(1, "L9", "S9", (99.0, 99.0), (0.0, 0.0)),  # not a plan pair: left out
        _reading(7, "L1", "S1", (99.0, 99.0), (0.0, 0.0)),  # not an asked angle: left out
    ]
    # Columns in the order asked (angle 1 first), raw - dark, NaN where nothing was read.
    v = readings_array(readings, pairs, [1, 0], 2)
    assert v.shape == (2, 2, 2)
    np.testing.assert_array_equal(v[0], [[29.0, 38.0], [9.0, 18.0]])
    np.testing.assert_array_equal(v[1, 0], [4.0, 5.0])
    assert np.isnan(v[1, 1]).all()
    cal = Calibration(pairs=(PairCalibration(light="L1", sensor="S1", factor=(0.5, 0.25)),))
    c = readings_array(readings, pairs, [1, 0], 2, cal)
    np.testing.assert_array_equal(c[0], [[14.5, 9.5], [4.5, 4.5]])
    np.testing.assert_array_equal(c[1, 0], [4.0, 5.0])  # uncalibrated pair: factor 1


def test_a_scan_behind_a_queued_calibration_needs_no_acceptance(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # `gonio serve --sim --demo-scan` queues a calibration (job 1), then its scan: refused
    # with "would be uncalibrated although the rig was calibrated" whenever a `gonio sim` rig
    # of the same geometry had been calibrated in the user data folder, though the scan runs
    # after the calibration and is finished with it.
    import gonio.service

    own = tmp_path / "own"
    own.mkdir()
    (own / "calibration.json").write_text("{}")  # the rig's own data directory calibrated
    monkeypatch.setattr(gonio.service, "scan_data_dir", lambda cfg: own)
    svc = _service(tmp_path)
    plan = UniformPlan(rotations=3, exposure=FAST)
    assert svc.uncalibrated_refusal(plan) is not None  # the premise: refused on its own
    cal = svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.99, rotations=2,
                                                     exposure=FAST), priority=1000))
    assert svc.uncalibrated_refusal(plan) is None
    svc.store.set_state(cal.id, JobState.RUNNING)
    assert svc.uncalibrated_refusal(plan) is None
    svc.store.set_state(cal.id, JobState.FAILED)  # a calibration that failed calibrates nothing
    assert svc.uncalibrated_refusal(plan) is not None
    # Queued, a calibration lifts the refusal only for scans the queue takes after it: at its
    # priority or below (the queue takes the higher priority first, the earlier among equals).
    svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.99, rotations=2,
                                               exposure=FAST), priority=5))
    assert svc.uncalibrated_refusal(plan, priority=5) is None
    assert svc.uncalibrated_refusal(plan, priority=0) is None
    assert svc.uncalibrated_refusal(plan, priority=6) is not None  # it would run first


def test_the_rig_data_directory_a_scan_is_judged_against_can_be_given(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`gonio scan --sim` keeps its own data directory (scan-sim/): its service must judge an
    uncalibrated scan against that folder, not against `scans/`, which a `gonio sim` rig of
    the same geometry calibrates (the cross-talk the separate folder removed came back
    through this refusal)."""
    import gonio.service

    rigs = tmp_path / "scans-rig"
    rigs.mkdir()
    (rigs / "calibration.json").write_text("{}")  # the gonio sim rig's folder, calibrated
    monkeypatch.setattr(gonio.service, "scan_data_dir", lambda cfg: rigs)
    plan = UniformPlan(rotations=3, exposure=FAST)
    default = _service(tmp_path)
    assert default.uncalibrated_refusal(plan) is not None  # judged against the rig's folder
    own = tmp_path / "scan-sim"
    own.mkdir()
    svc = GonioService(JobStore(tmp_path / "own.sqlite"), MemRig(), data_dir=own,
                       own_data_dir=own)
    assert svc.uncalibrated_refusal(plan) is None  # its own folder: nothing calibrated elsewhere
