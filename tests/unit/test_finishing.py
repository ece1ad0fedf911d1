"""Finishing (gonio.finishing): a result rebuilt from the stored readings, and what it refuses.

The whole path on a real daemon and a truncated file is tests/system/test_state_files.py; here
the rules, on an in-memory rig.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import sqlite3
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.basis_supply import BasisSupply
from gonio.finishing import RebuildError, _older_rig_config, rebuild_result
from gonio.plans.models import CalibrationPlan, ExposureSettings, UniformPlan
from gonio.results import read_result
from gonio.service import GonioService, JobRequest
from gonio.sim.memrig import MemRig
from gonio.store import JobStore

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0)


def _no_basis() -> None:
    raise AssertionError("a calibration job needs no basis")


def _calibrated(tmp_path: Path) -> GonioService:
    """A service on an in-memory rig after one completed calibration job (job 1)."""
    svc = GonioService(JobStore(tmp_path / "d" / "gonio.sqlite"), MemRig(),
                       data_dir=tmp_path / "d")

    async def go() -> None:
        await svc.start()
        svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.9, rotations=2,
                                                   exposure=FAST)))
        async for ev in svc.subscribe(0, job_id=1):
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        await svc.stop()

    asyncio.run(go())
    assert svc.get_job(1).state.value == "completed", svc.get_job(1).reason
    return svc


def _scanned(tmp_path: Path, plan: UniformPlan,
             truth: Callable[[], dict[str, Any] | None] | None = None,
             on_submit: Callable[[GonioService, int], None] | None = None) -> GonioService:
    """A service on an in-memory rig with the small test basis, after a calibration (job 1)
    and a completed scan of ``plan`` (job 2); ``truth`` is the rig's specimen truth,
    ``on_submit(service, job)`` runs right after the scan is queued."""
    from tests.unit.brdf.reconstruction.test_basis import small_basis

    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    basis = small_basis()
    svc = GonioService(JobStore(data / "gonio.sqlite"), MemRig(), data_dir=data,
                       basis=BasisSupply(lambda: basis), fit_exports=False)
    if truth is not None:
        svc.specimen_truth = truth

    async def go() -> None:
        await svc.start()
        job = svc.submit(JobRequest(plan=plan)).id
        if on_submit is not None:
            on_submit(svc, job)
        async for ev in svc.subscribe(0, job_id=job):
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        await svc.stop()

    asyncio.run(go())
    assert svc.store.get_job(2).state.value == "completed", svc.store.get_job(2).reason
    return svc


def test_a_calibration_job_is_rebuilt_without_replacing_the_calibration_in_effect(
    tmp_path: Path
) -> None:
    svc = _calibrated(tmp_path)
    data = tmp_path / "d"
    result = data / "results" / "job-1.h5"
    original = Path(shutil.copyfile(result, tmp_path / "original.h5"))
    # A later calibration is in effect by now: a rebuild of job 1 must not bring job 1's back.
    later = (data / "calibration.json").read_text().replace('"job 1', '"job 9')
    (data / "calibration.json").write_text(later)
    result.unlink()
    summary = rebuild_result(svc.store, data, 1, BasisSupply(_no_basis))
    assert summary["result_path"] == "results/job-1.h5" and summary["calibrated"] is False
    assert (data / "calibration.json").read_text() == later
    new, old = read_result(result), read_result(original)
    np.testing.assert_array_equal(new.samples.values, old.samples.values)
    # Dated by the white reference's readings, so the rebuild's is the same, whenever it runs.
    assert new.provenance["new_calibration"] == old.provenance["new_calibration"]
    last = max(r.t_read for r in svc.store.readings(1))
    assert json.loads(new.provenance["new_calibration"])["created"] == time.strftime(
        "%Y-%m-%dT%H:%M:%SZ", time.gmtime(last))
    assert "gonio jobs rebuild" in new.provenance["rebuilt"]
    assert svc.store.get_job(1).summary == summary
    assert [e.type for e in svc.store.events_after(0, job_id=1)][-1] == "rebuilt"


def test_a_rebuild_refuses_jobs_not_completed_and_missing_readings(tmp_path: Path) -> None:
    svc = _calibrated(tmp_path)
    data = tmp_path / "d"
    queued = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST))).id
    with pytest.raises(RebuildError, match=f"job {queued} is queued"):
        rebuild_result(svc.store, data, queued, BasisSupply(_no_basis))
    n = svc.store.reading_count(1)
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("DELETE FROM readings WHERE job_id = 1 AND angle_index = 0")
    left = svc.store.reading_count(1)
    assert 0 < left < n
    with pytest.raises(RebuildError, match=f"holds {left} of the {n} readings"):
        rebuild_result(svc.store, data, 1, BasisSupply(_no_basis))
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("DELETE FROM readings WHERE job_id = 1")
    with pytest.raises(RebuildError, match="holds none of its readings"):
        rebuild_result(svc.store, data, 1, BasisSupply(_no_basis))


def test_a_forced_half_turn_with_opposite_readings_that_differ_is_warned() -> None:
    """Only the finishing sees such readings (no plan kind reads opposites over half a turn
    today; a rebuild of readings from elsewhere may): symmetric readings are recorded quietly,
    a 5 % lean (ten times the noise of a difference) is warned of with what to do."""
    from types import SimpleNamespace

    from gonio.finishing import _arc_test, _record_arc_test

    def record(plan: UniformPlan, samples: Any, metrics: dict[str, Any],
               provenance: dict[str, Any]) -> None:
        _record_arc_test(1, plan, _arc_test(store, 1, plan, samples.stage_angles_deg,
                                            lambda: samples.values), metrics, provenance)

    angles = np.array([0.0, 45.0, 90.0, 135.0, 180.0, 270.0])
    a = np.deg2rad(angles)[None, :, None]
    rng = np.random.default_rng(4)
    store = JobStore(":memory:")
    for lean, warned in ((0.0, False), (0.05, True)):
        values = np.exp(np.cos(2 * a) + lean * np.cos(a)) * np.ones((4, 1, 3))
        values *= 1 + 0.01 * rng.standard_normal(values.shape)
        metrics: dict[str, Any] = {}
        provenance: dict[str, Any] = {}
        record(UniformPlan(), SimpleNamespace(stage_angles_deg=angles, values=values),
               metrics, provenance)
        assert ("arc_asymmetric" in metrics) == warned
        assert metrics["arc_symmetric"] is not warned and metrics["arc_deg"] == 180.0
        assert "arc_test" in provenance
        if warned:
            assert "span_deg 360" in metrics["arc_asymmetric"]
    # A half turn without opposite angles: nothing to test, nothing recorded.
    metrics = {}
    record(UniformPlan(), SimpleNamespace(stage_angles_deg=angles[:4],
                                          values=np.ones((4, 4, 3))), metrics, {})
    assert metrics == {}
    # A full turn is tested too (its verdict chooses the basis), never warned: its own arc.
    record(UniformPlan(span_deg=360), SimpleNamespace(
        stage_angles_deg=angles, values=np.ones((4, 6, 3))), metrics, {})
    assert metrics["arc_symmetric"] and metrics["arc_deg"] == 360.0
    assert "arc_asymmetric" not in metrics


def test_a_calibration_whose_result_cannot_be_written_does_not_take_effect(
    tmp_path: Path
) -> None:
    """The result is written before the calibration: when it cannot be (here a directory
    stands where the file goes, a real failure of the write), the job fails and the
    calibration in effect stays the earlier job's, not one whose job shows failed."""
    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    before = (data / "calibration.json").read_text()
    blocked = data / "results" / "job-2.h5"
    blocked.mkdir()
    svc = GonioService(JobStore(data / "gonio.sqlite"), MemRig(), data_dir=data)

    async def go() -> None:
        await svc.start()
        svc.submit(JobRequest(plan=CalibrationPlan(reference_albedo=0.5, rotations=2,
                                                   exposure=FAST)))
        async for ev in svc.subscribe(0, job_id=2):
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        await svc.stop()

    asyncio.run(go())
    job = svc.store.get_job(2)
    assert job.state.value == "failed", job.reason
    assert (data / "calibration.json").read_text() == before
    assert svc.calibration().source == json.loads(before)["source"]
    assert blocked.is_dir() and not any(blocked.iterdir())
    assert not list(data.glob("calibration.json*.part"))


def test_a_job_of_an_older_gonio_rebuilt_without_its_result_file_says_why_it_is_not_compared(
    tmp_path: Path
) -> None:
    """A store from before the `finishing` table (dropped here; opening the store creates it
    empty) keeps no rig config: with the result file gone, the design it ran on is unknown,
    and the rebuilt result says so where the comparison shows (metrics, provenance, the
    summary the CLI prints), and keeps saying it when rebuilt again; export fits are stored
    as the original did (its summary's fit metrics say). A calibration job is
    compared with no design, so its rebuild says nothing of it."""
    from tests.unit.brdf.reconstruction.test_basis import small_basis

    basis = small_basis()
    svc = _scanned(tmp_path, UniformPlan(rotations=4, exposure=FAST))
    data = tmp_path / "d"
    svc.store.close()
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("DROP TABLE finishing")
    store = JobStore(data / "gonio.sqlite")
    assert store.finishing_inputs(2) is None
    (data / "results" / "job-2.h5").unlink()
    summary = rebuild_result(store, data, 2, BasisSupply(lambda: basis))
    why = summary["design_comparison"]
    assert why.startswith("not available: job 2 was finished by a gonio whose job store "
                          "did not keep the rig config it ran on"), why
    assert "results/job-2.h5 is missing" in why, why
    new = read_result(data / "results" / "job-2.h5")
    assert new.metrics["design_comparison"] == why
    assert new.provenance["design_comparison"] == why
    assert "rig_config" not in new.provenance
    assert "design_expected_log_rmse" not in new.metrics
    # Its summary has no fit metric: it stored no export fits, nor does its rebuild.
    assert new.factored is None and "factored_rel_mse" not in summary
    # What a further rebuild takes from that file (a whole rebuild again costs its fits).
    assert _older_rig_config(data, store.get_job(2)) == {"design_comparison": why}
    (data / "results" / "job-1.h5").unlink()
    calibration = rebuild_result(store, data, 1, BasisSupply(_no_basis))
    assert "design_comparison" not in calibration
    assert "design_comparison" not in read_result(data / "results" / "job-1.h5").provenance


def test_a_scan_leaning_on_its_own_imported_export_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A result exported as a table and imported into the user library (gonio export
    --format table; gonio library import) becomes a local prior of the default basis; the
    next scan of the same specimen can lean on it where no pair looks, and its result then
    rests on the earlier scan. The result says so (and its exports and colour carry it); a
    scan of another specimen leaning on it does not. Which prior the joint fit picks is the
    reconstruction's business (docs/science.md 7.2.3): here it is set to the imported table."""
    import gonio.brdf.reconstruction.reconstruct as recon_module
    from gonio.brdf.materials.imports import import_files
    from gonio.export import export_result
    from gonio.result_colour import colour_warnings
    from tests.unit.test_worker import BASIS  # twofold symmetric: no other basis is built

    monkeypatch.setenv("GONIO_LIBRARY_DIR", str(tmp_path / "library"))
    svc = GonioService(JobStore(tmp_path / "d" / "gonio.sqlite"), MemRig(),
                       data_dir=tmp_path / "d", basis=BasisSupply(lambda: BASIS))
    svc.worker.fit_exports = False
    leaned: list[str] = []
    real = recon_module.reconstruct

    def leaning(*args: object, **kwargs: object) -> object:
        rec = real(*args, **kwargs)  # type: ignore[arg-type]
        if leaned:
            rec.settings.update(local_prior=leaned[0], local_prior_gain=7.5)
        return rec

    monkeypatch.setattr(recon_module, "reconstruct", leaning)

    async def scan(specimen: str) -> int:
        job = svc.submit(JobRequest(plan=UniformPlan(specimen=specimen, rotations=2,
                                                     exposure=FAST))).id
        async for ev in svc.subscribe(0, job_id=job):
            if ev.type == "state" and ev.data["state"] in ("completed", "failed"):
                break
        assert svc.get_job(job).state.value == "completed", svc.get_job(job).reason
        return job

    async def day() -> tuple[int, int, int]:
        await svc.start()
        try:
            first = await scan("green felt")
            table = tmp_path / "green-felt.npz"
            export_result(tmp_path / "d" / "results" / f"job-{first}.h5", "table", table)
            (imported,) = import_files([table])
            leaned.append(imported.stem)
            return first, await scan("Green felt"), await scan("white paper")
        finally:
            await svc.stop()

    first, again, other = asyncio.run(day())
    imported = tmp_path / "library" / f"{leaned[0]}.npz"
    res = read_result(tmp_path / "d" / "results" / f"job-{again}.h5")
    said = res.provenance["local_prior_own"]
    assert said.startswith(f"prior: the fit leaned on {imported.stem}, this specimen's own "
                           f"earlier result (measured scan, job {first})"), said
    assert "predicted_log_rmse is not independent of it" in said, said
    assert str(imported) in said
    assert svc.get_job(again).result["local_prior_own"] == said
    assert said in colour_warnings(res)  # what the colour and every export carry
    assert "local_prior_own" not in read_result(
        tmp_path / "d" / "results" / f"job-{other}.h5").provenance


def _until_ended(svc: GonioService, job: int, *, on_progress: Any = None) -> None:
    """Start ``svc``, wait for job ``job`` to end (``on_progress`` sees its progress
    events), stop it."""

    async def go() -> None:
        await svc.start()
        async for ev in svc.subscribe(0, job_id=job):
            if ev.type == "progress" and on_progress is not None:
                on_progress(ev.data)
            if ev.type == "state" and ev.data["state"] in ("completed", "failed", "aborted"):
                break
        await svc.stop()

    asyncio.run(go())


def test_a_job_failed_while_finishing_is_rebuilt_and_completed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every reading stored, then finishing raised (here: the basis did not read, once): the
    rebuild finishes it again. A rebuild whose finishing fails again leaves it failed with the
    new reason and its readings; one that works completes it with a result file that reads.
    The CLI says what it did."""
    from gonio.brdf.reconstruction.basis import BasisError
    from gonio.cli import main
    from tests.unit.brdf.reconstruction.test_basis import small_basis

    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    basis = small_basis()
    calls: list[int] = []

    def unreadable_once() -> Any:
        # The daemon's basis supply: the first load fails as an unreadable basis file does.
        calls.append(1)
        if len(calls) == 1:
            raise BasisError("basis file basis-k16.npz does not read (truncated)")
        return basis

    svc = GonioService(JobStore(data / "gonio.sqlite"), MemRig(), data_dir=data,
                       basis=BasisSupply(unreadable_once), fit_exports=False)
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=4, exposure=FAST))).id
    _until_ended(svc, job)
    store = svc.store
    failed = store.get_job(job)
    assert failed.state.value == "failed", failed.reason
    assert "basis-k16.npz does not read" in (failed.reason or "")
    # The reason says the readings are whole and how to finish the job once mended.
    assert (failed.reason or "").endswith(
        f"once the cause is mended, every reading is stored: 'gonio jobs rebuild {job} --db "
        f"{data / 'gonio.sqlite'}' finishes it once the daemon or scan running this store has "
        "stopped"), failed.reason
    assert len(calls) == 1  # it failed in finishing, not before measuring
    steps = store.steps(job)
    n = store.reading_count(job)
    assert steps and all(s.done for s in steps) and n > 0
    assert not (data / "results" / f"job-{job}.h5").exists()

    def never() -> Any:
        raise BasisError("basis file basis-k16.npz does not read (still truncated)")

    # Finishing fails again: still failed, with the new reason; the readings as they were.
    with pytest.raises(RebuildError, match=f"cannot rebuild job {job}: its finishing failed "
                       "again .*still truncated.*run gonio jobs rebuild"):
        rebuild_result(store, data, job, BasisSupply(never))
    again = store.get_job(job)
    assert again.state.value == "failed"
    assert again.reason is not None and "still truncated" in again.reason
    assert store.reading_count(job) == n
    ev = store.last_event(job, "rebuild_failed")
    assert ev is not None and ev.data["previous"] == failed.reason

    # The cause gone: `gonio jobs rebuild` completes it (its basis supply is the default one;
    # here it serves the small basis). Not while a daemon or scan holds the store: it would
    # change a job's state under them.
    monkeypatch.setattr("gonio.basis_supply.BasisSupply",
                        lambda: BasisSupply(lambda: basis))
    import subprocess
    import sys

    capsys.readouterr()
    # Another process holds the store's lock, as a daemon does (the lock is per process).
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys; from gonio.locks import claim_store; "
         f"lock = claim_store({str(data / 'gonio.sqlite')!r}, 'a daemon of this test'); "
         "print('held', flush=True); sys.stdin.read()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        assert main(["jobs", "rebuild", str(job), "--db", str(data / "gonio.sqlite")]) == 2
    finally:
        holder.communicate(timeout=60)
    err = capsys.readouterr().err
    assert "a failed job is rebuilt only in a job store no daemon or scan runs" in err, err
    assert store.get_job(job).state.value == "failed"
    code = main(["jobs", "rebuild", str(job), "--db", str(data / "gonio.sqlite")])
    out = capsys.readouterr()
    assert code == 0, out.err
    path = data / "results" / f"job-{job}.h5"
    assert f"job {job}: wrote {path} from {n} stored readings" in out.out, out.out
    assert "it was failed and is completed now" in out.out, out.out
    done = JobStore(data / "gonio.sqlite").get_job(job)
    assert done.state.value == "completed"
    assert done.reason is not None and "completed by gonio jobs rebuild" in done.reason
    assert "still truncated" in done.reason  # why it had failed
    result = read_result(path)
    assert result.table is not None and np.isfinite(result.table.values).any()
    assert "gonio jobs rebuild" in result.provenance["rebuilt"]


def test_a_job_aborted_while_finishing_is_rebuilt_and_completed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The lab aborted a scan while it was being finished (every reading stored), then wants
    its result after all: the job's reason says how, and `gonio jobs rebuild` completes it.
    A rebuild whose finishing fails leaves it aborted with the lab's reason."""
    import threading

    from gonio.brdf.reconstruction.basis import BasisError
    from gonio.cli import main
    from tests.unit.brdf.reconstruction.test_basis import small_basis

    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    db = data / "gonio.sqlite"
    basis = small_basis()
    entered, gate = threading.Event(), threading.Event()

    def held() -> Any:
        # Finishing waits here until the test has asked for the abort: then it stops.
        entered.set()
        assert gate.wait(120), "the test never opened the gate"
        return basis

    svc = GonioService(JobStore(db), MemRig(), data_dir=data, basis=BasisSupply(held),
                       fit_exports=False)
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=4, exposure=FAST))).id

    async def go() -> None:
        await svc.start()
        async for ev in svc.subscribe(0, job_id=job):
            if ev.type == "state" and ev.data["state"] == "reconstructing":
                assert await asyncio.to_thread(entered.wait, 120)
                svc.abort(job)
                gate.set()
            if ev.type == "state" and ev.data["state"] in ("completed", "failed", "aborted"):
                break
        await svc.stop()

    asyncio.run(go())
    store = svc.store
    aborted = store.get_job(job)
    assert aborted.state.value == "aborted", aborted.reason
    assert aborted.reason == (f"aborted by request while it was being finished; every reading "
                              f"is stored: 'gonio jobs rebuild {job} --db {db}' finishes it once "
                              "the daemon or scan running this store has stopped")
    n = store.reading_count(job)
    assert n > 0 and not (data / "results" / f"job-{job}.h5").exists()

    def never() -> Any:
        raise BasisError("basis file basis-k16.npz does not read (truncated)")

    with pytest.raises(RebuildError, match=f"cannot rebuild job {job}: its finishing failed "
                       r"\(reconstruction failed \(gonio jobs rebuild\): .*truncated\)\); it "
                       "stays aborted with its reason"):
        rebuild_result(store, data, job, BasisSupply(never))
    assert store.get_job(job).state.value == "aborted"
    assert store.get_job(job).reason == aborted.reason and store.reading_count(job) == n

    monkeypatch.setattr("gonio.basis_supply.BasisSupply",
                        lambda: BasisSupply(lambda: basis))
    capsys.readouterr()
    code = main(["jobs", "rebuild", str(job), "--db", str(db)])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "it was aborted and is completed now" in out.out, out.out
    done = JobStore(db).get_job(job)
    assert done.state.value == "completed"
    assert done.reason == ("completed by gonio jobs rebuild from its stored readings (it had "
                           f"been aborted while finishing: {aborted.reason})")
    result = read_result(data / "results" / f"job-{job}.h5")
    assert result.table is not None and np.isfinite(result.table.values).any()


def test_a_job_aborted_while_measuring_is_refused_with_its_counts(tmp_path: Path) -> None:
    """Aborted part way through its angles: not a whole scan, so no result to write."""
    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    svc = GonioService(JobStore(data / "gonio.sqlite"), MemRig(), data_dir=data,
                       basis=BasisSupply(_no_basis))
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=6, exposure=FAST))).id

    def abort_after_two(progress: dict[str, Any]) -> None:
        if progress["done"] == 2:
            svc.abort(job)

    _until_ended(svc, job, on_progress=abort_after_two)
    store = svc.store
    row = store.get_job(job)
    assert row.state.value == "aborted"
    measured = len({r.angle_index for r in store.readings(job)})
    planned = len(store.steps(job))
    assert 2 <= measured < planned
    with pytest.raises(RebuildError, match=f"job {job} was aborted while it was measuring "
                       rf"\({measured} of {planned} angles of its plan measured, "
                       rf"{store.reading_count(job)} readings stored; reason: aborted by "
                       r"request\).*measure it again"):
        rebuild_result(store, data, job, BasisSupply(_no_basis))
    assert store.get_job(job).state.value == "aborted"


def test_a_job_failed_while_measuring_is_refused_with_its_counts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stage fault part way through: the readings are not a whole scan. The refusal says
    how many of the plan's angles were measured and that a new scan is the way."""
    from gonio import hal
    from gonio.cli import main
    from tests.unit.engine.test_engine import QUICK_FAULTS

    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    rig = MemRig()
    svc = GonioService(JobStore(data / "gonio.sqlite"), rig, data_dir=data,
                       basis=BasisSupply(_no_basis))
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=6, exposure=FAST,
                                                 faults=QUICK_FAULTS))).id

    def fault_after_two(progress: dict[str, Any]) -> None:
        if progress["done"] == 2:
            rig.mstage.fault_next_moves = [
                hal.StageFault("stage", "encoder broken", code="encoder", recoverable=False)]

    _until_ended(svc, job, on_progress=fault_after_two)
    store = svc.store
    assert store.get_job(job).state.value == "failed"
    # The counts, from the store's own tables: angles with readings, angles planned.
    measured = len({r.angle_index for r in store.readings(job)})
    planned = len(store.steps(job))
    n = store.reading_count(job)
    assert 2 <= measured < planned
    with pytest.raises(RebuildError, match=f"job {job} failed while it was measuring "
                       rf"\({measured} of {planned} angles of its plan measured, {n} readings "
                       r"stored; reason: .*encoder broken.*measure it again \(submit the same "
                       "plan as a new scan\\)"):
        rebuild_result(store, data, job, BasisSupply(_no_basis))
    capsys.readouterr()
    code = main(["jobs", "rebuild", str(job), "--db", str(data / "gonio.sqlite")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"gonio jobs: error: job {job} failed while it was measuring ({measured} of " \
           f"{planned} angles of its plan measured, {n} readings stored" in err, err
    assert "Traceback" not in err
    assert store.get_job(job).state.value == "failed" and store.reading_count(job) == n


def test_a_failed_job_whose_finishing_recorded_no_calibration_is_not_completed_uncalibrated(
    tmp_path: Path,
) -> None:
    """A job that failed before its finishing recorded the calibration it applies (a
    calibration that did not read; a store of a gonio that kept no finishing inputs) would
    have been finished with none: a calibrated scan "completed" in sensor units. Refused."""
    import sqlite3

    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"

    def unreadable() -> Any:
        raise RuntimeError("basis does not read")

    svc = GonioService(JobStore(data / "gonio.sqlite"), MemRig(), data_dir=data,
                       basis=BasisSupply(unreadable), fit_exports=False)
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=4, exposure=FAST))).id
    _until_ended(svc, job)
    assert svc.store.get_job(job).state.value == "failed"
    assert svc.store.finishing_inputs(job)  # recorded before the basis failed
    svc.store.close()
    # As a store that never recorded them (the failure came first, or an older gonio).
    with sqlite3.connect(data / "gonio.sqlite") as db:
        db.execute("DELETE FROM finishing WHERE job_id = ?", (job,))
    store = JobStore(data / "gonio.sqlite")
    with pytest.raises(RebuildError, match=f"cannot rebuild job {job}: it failed before its "
                       "finishing recorded which calibration its readings take"):
        rebuild_result(store, data, job, BasisSupply(small_basis_supply))
    assert store.get_job(job).state.value == "failed"
    assert not (data / "results" / f"job-{job}.h5").exists()


def small_basis_supply() -> Any:
    from tests.unit.brdf.reconstruction.test_basis import small_basis

    return small_basis()


def test_the_rebuild_command_pastes_as_it_is_printed(tmp_path: Path) -> None:
    """Absolute, quoted paths (a macOS data folder has a space), and --data-dir when the
    results go elsewhere than the store's folder (the command would take that folder)."""
    import shlex

    from gonio.finishing import rebuild_command

    folder = tmp_path / "Application Support" / "gonio"
    db = folder / "gonio.sqlite"
    same = rebuild_command(3, db, folder)
    assert same == f"gonio jobs rebuild 3 --db {shlex.quote(str(db))}"
    assert shlex.split(same)[-1] == str(db)  # one argument, space and all
    other = tmp_path / "lab data"
    assert rebuild_command(3, db, other) == (f"{same} --data-dir {shlex.quote(str(other))}")


def test_gonio_jobs_abort_of_a_job_left_being_finished_says_how_to_finish_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A daemon killed while it finished a scan leaves the job `reconstructing` with every
    reading stored and its finishing's inputs recorded. `gonio jobs abort` of it said only
    that the readings stay in the store; it now gives the command that makes its result, as
    the daemon's own abort of a job being finished does (its reason, above)."""
    from gonio.brdf.reconstruction.basis import BasisError
    from gonio.cli import main

    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    db = data / "gonio.sqlite"

    def unreadable() -> Any:
        raise BasisError("basis file basis-k16.npz does not read (truncated)")

    # A finishing that stops after recording its inputs (as a kill -9 there would) ...
    svc = GonioService(JobStore(db), MemRig(), data_dir=data,
                       basis=BasisSupply(unreadable), fit_exports=False)
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=4, exposure=FAST))).id
    _until_ended(svc, job)
    assert svc.store.get_job(job).state.value == "failed"
    assert "calibration" in (svc.store.finishing_inputs(job) or {})
    svc.store.close()
    # ... and the state such a kill leaves, which no transition of a live gonio makes.
    with sqlite3.connect(db) as con:
        con.execute("UPDATE jobs SET state = 'reconstructing', reason = NULL WHERE id = ?",
                    (job,))
    capsys.readouterr()
    assert main(["jobs", "abort", str(job), "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert f"job {job} aborted (4 of 4 angles had been measured" in out, out
    assert f"it was being finished: every reading is stored: 'gonio jobs rebuild {job} --db " \
           f"{db}'" in out, out
    # A job aborted while measuring has no such line (nothing to finish).
    svc = GonioService(JobStore(db), MemRig(), data_dir=data, fit_exports=False)
    other = svc.submit(JobRequest(plan=UniformPlan(rotations=4, exposure=FAST))).id
    svc.store.close()
    assert main(["jobs", "abort", str(other), "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert f"job {other} aborted (0 of 4" in out and "being finished" not in out, out


def test_the_recorded_finishing_time_includes_writing_the_result_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The status's finishing estimate (gonio.timeleft) is the summaries' ``seconds`` and
    promises the result file too: the summary's time covers the write, which the file's own
    ``seconds`` metric cannot (it is written before the write ends). A write slowed by 0.5 s,
    as a slow disk or a 31-band result's larger file, shows in the summary and not the file."""
    import gonio.results
    from tests.unit.brdf.reconstruction.test_basis import small_basis

    real_write = gonio.results.write_result

    def slow_write(*args: Any, **kwargs: Any) -> Any:
        out = real_write(*args, **kwargs)
        time.sleep(0.5)
        return out

    monkeypatch.setattr(gonio.results, "write_result", slow_write)
    _calibrated(tmp_path).store.close()
    data = tmp_path / "d"
    basis = small_basis()
    svc = GonioService(JobStore(data / "gonio.sqlite"), MemRig(), data_dir=data,
                       basis=BasisSupply(lambda: basis), fit_exports=False)
    job = svc.submit(JobRequest(plan=UniformPlan(rotations=4, exposure=FAST))).id
    _until_ended(svc, job)
    row = svc.store.get_job(job)
    assert row.state.value == "completed", row.reason
    assert row.summary is not None
    in_file = float(read_result(data / "results" / f"job-{job}.h5").metrics["seconds"])
    assert float(row.summary["seconds"]) >= in_file + 0.5


def test_a_resumed_finishing_records_the_truth_it_kept_when_it_began(tmp_path: Path) -> None:
    """A daemon stopped while it reconstructed a simulated scan and started again on another
    material (``gonio serve --sim --material``) would have recorded the new material as the
    truth of readings made on the old one. Finishing keeps the truth when it first begins;
    resumed, it records that one, whatever the rig holds now."""
    def kept(svc: GonioService, job: int) -> None:
        # What the first, interrupted finishing kept (gonio.finishing, before anything is
        # written).
        svc.store.set_finishing_inputs(job, {"true_material": {"name": "measured"}})

    svc = _scanned(tmp_path, UniformPlan(rotations=4, exposure=FAST),
                   truth=lambda: {"name": "put on the stage after the restart"},
                   on_submit=kept)
    res = read_result(tmp_path / "d" / "results" / "job-2.h5")
    assert json.loads(res.provenance["true_material"]) == {"name": "measured"}
    assert svc.store.finishing_inputs(2)["true_material"] == {"name": "measured"}


def test_a_fixed_full_turn_is_tested_on_its_raw_counts(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The twofold test weighs each reading's shot noise, a matter of counts: finishing tested
    a fixed full turn on its calibrated values, where a spectral calibration lifts a dim band
    to its neighbours' level without lowering its noise (an isotropic paint called asymmetric
    on 2 of 5 scans). What it tests is ``raw - dark`` of the stored readings, per pair and
    stage angle, not the result's calibrated samples."""
    import gonio.plans.arc as arc_module

    seen: list[tuple[list[float], np.ndarray]] = []
    real = arc_module.arc_test

    def spy(angles: list[float], values: Any, relative: float, **kw: Any) -> dict[str, Any]:
        seen.append((list(angles), np.asarray(values, dtype=float).copy()))
        return real(angles, values, relative, **kw)

    monkeypatch.setattr(arc_module, "arc_test", spy)
    svc = _scanned(tmp_path, UniformPlan(rotations=4, span_deg=360.0, exposure=FAST))
    (angles, values), = seen
    res = read_result(tmp_path / "d" / "results" / "job-2.h5")
    assert res.samples.calibration  # the result is in 1/sr: its values are not the counts
    pairs = [(str(a), str(b)) for a, b in res.samples.pairs]
    expected = np.full(values.shape, np.nan)
    for r in svc.store.readings(2):
        q = pairs.index((r.light, r.sensor))
        j = int(np.argmin(np.abs((np.asarray(angles) - r.commanded_deg % 360.0 + 180) % 360
                                 - 180)))
        expected[q, j] = (np.asarray(r.raw, float) - np.asarray(r.dark, float)) / r.range_scale
    np.testing.assert_allclose(values, expected)
    assert not np.allclose(values, res.samples.values)
