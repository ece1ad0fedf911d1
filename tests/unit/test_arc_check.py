"""A half-turn plan meets a basis that is not half-turn periodic: warned early, nothing refused.

The plan reads the stage over half a turn (``span_deg`` 180, the default); a basis whose prior
holds odd harmonics along ``ph`` (a material without twofold symmetry in its training set) then
leaves the other half turn to the prior. The dry run (service, CLI summary), the submission
and the job's own events say so, naming the materials the basis knows and the way out
(``span_deg`` 360, ``--span 360``); a full-turn plan, a half-turn periodic basis or a basis
that is not built yet say nothing.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from gonio.basis_supply import BasisSupply
from gonio.brdf.reconstruction.basis import Basis
from gonio.jobstates import JobState
from gonio.plans.dryrun import BasisSymmetry, dry_run
from gonio.plans.models import AdaptivePlan, CalibrationPlan, ExposureSettings, UniformPlan
from gonio.results import read_result
from gonio.rigdescription import RigDescription
from gonio.service import GonioService, JobRequest
from gonio.sim.memrig import MemRig
from gonio.store import JobStore
from gonio.worker import Worker
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")
HALF = UniformPlan(rotations=4, span_deg=180, exposure=FAST)
FULL = UniformPlan(rotations=4, span_deg=360, exposure=FAST)


def _named(b: Basis, names: list[str]) -> Basis:
    return Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials,
                 {**b.provenance, "without_twofold_symmetry": names}, b.ph_prior)


# A prior with an odd harmonic (m = 1): a material without twofold symmetry was learnt.
ODD = _named(_with_prior(random_basis(6, seed=1), {0: 1.0, 1: 0.3, 2: 0.5}), ["pile-lean"])
# Only even harmonics, as the shipped basis: a specimen turned by half a turn reads the same.
EVEN = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 0.5})


def _says_what_and_what_to_do(message: str, names: tuple[str, ...] = ("pile-lean",)) -> None:
    assert "twofold symmetry" in message and "half a turn" in message
    assert "other half" in message and "prior" in message
    assert "span_deg 360" in message and "--span 360" in message
    for name in names:
        assert name in message


@pytest.fixture
def desc() -> RigDescription:
    return RigDescription.from_rig(MemRig())


def test_the_fixture_bases_are_what_their_names_say() -> None:
    assert not ODD.half_turn_periodic and ODD.without_twofold_symmetry == ("pile-lean",)
    assert EVEN.half_turn_periodic


def test_a_half_turn_plan_with_a_basis_without_twofold_symmetry_is_warned(
        desc: RigDescription) -> None:
    for plan in (HALF, AdaptivePlan(initial_rotations=4, exposure=FAST)):  # both 180 deg
        warnings = dry_run(plan, desc, basis=BasisSymmetry.of(ODD)).warnings
        assert len(warnings) == 1
        _says_what_and_what_to_do(warnings[0])
    # A basis that does not know which materials: still warned, no names.
    unnamed = _with_prior(random_basis(6, seed=1), {0: 1.0, 1: 0.3})
    (message,) = dry_run(HALF, desc, basis=BasisSymmetry.of(unnamed)).warnings
    _says_what_and_what_to_do(message, names=())


def test_no_warning_for_a_full_turn_an_even_basis_no_basis_or_a_calibration(
        desc: RigDescription) -> None:
    assert dry_run(FULL, desc, basis=BasisSymmetry.of(ODD)).warnings == []
    assert dry_run(AdaptivePlan(rule="vf", exposure=FAST), desc,  # vf: a full turn
                   basis=BasisSymmetry.of(ODD)).warnings == []
    assert dry_run(HALF, desc, basis=BasisSymmetry.of(EVEN)).warnings == []
    assert dry_run(HALF, desc).warnings == []  # not built: the dry run does not build it
    calibration = CalibrationPlan(reference_albedo=0.99, exposure=FAST)
    assert dry_run(calibration, desc, basis=BasisSymmetry.of(ODD)).warnings == []


def test_the_cli_dry_run_summary_shows_the_warning(desc: RigDescription) -> None:
    from gonio.cli.scan_report import dry_run_summary

    text = dry_run_summary(dry_run(HALF, desc, basis=BasisSymmetry.of(ODD)), HALF, "rig")
    (line,) = [ln for ln in text.splitlines() if "warning" in ln]
    _says_what_and_what_to_do(line)
    assert "warning" not in dry_run_summary(dry_run(FULL, desc, basis=BasisSymmetry.of(ODD)),
                                            FULL, "rig")


def _cache_with(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, basis: Basis | None) -> None:
    """A cache folder of this test's own, holding ``basis`` as the built default basis."""
    from gonio.brdf.reconstruction.basis import default_basis_path

    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    if basis is not None:
        path = default_basis_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        basis.save(path)


def _arc_events(store: JobStore, job_id: int) -> list[dict[str, Any]]:
    return [e.data for e in store.events_after(0, job_id=job_id) if e.type == "arc_warning"]


def test_the_service_warns_once_the_default_basis_is_built(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _cache_with(monkeypatch, tmp_path, None)
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(), data_dir=tmp_path / "d")
    assert svc.basis.is_default
    assert svc.dry_run(HALF).warnings == []  # not built yet: not checked, not built
    _cache_with(monkeypatch, tmp_path, ODD)
    (message,) = svc.dry_run(HALF).warnings
    _says_what_and_what_to_do(message)
    assert svc.dry_run(FULL).warnings == []
    # Submission warns, it does not refuse: the job is queued and its record says why.
    info = svc.submit(JobRequest(plan=HALF))
    assert svc.get_job(info.id).state is JobState.QUEUED
    (event,) = _arc_events(svc.store, info.id)
    _says_what_and_what_to_do(event["message"])
    assert event["materials"] == ["pile-lean"] and event["span_deg"] == 180
    assert _arc_events(svc.store, svc.submit(JobRequest(plan=FULL)).id) == []


def test_the_service_says_nothing_with_the_shipped_like_even_basis(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _cache_with(monkeypatch, tmp_path, EVEN)
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(), data_dir=tmp_path / "d")
    assert svc.dry_run(HALF).warnings == []
    assert _arc_events(svc.store, svc.submit(JobRequest(plan=HALF)).id) == []


def _worker(store: JobStore, provider: Any, tmp_path: Path) -> tuple[Worker, RigDescription]:
    """A worker on a MemRig with a basis supply of ``provider`` (None: the default basis)."""
    rig = MemRig()
    desc = RigDescription.from_rig(rig)

    async def get_rig() -> MemRig:
        return rig

    return Worker(store, get_rig, desc, tmp_path / "d", BasisSupply(provider),
                  fit_exports=False), desc


def _queue(store: JobStore, desc: RigDescription, plan: UniformPlan) -> int:
    """A job queued straight into the store: no submission check has recorded anything."""
    return store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                            rig=desc.model_dump(mode="json")).id


def test_a_job_records_the_warning_before_its_first_reading(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _cache_with(monkeypatch, tmp_path, ODD)
    store = JobStore(tmp_path / "jobs.sqlite")
    w, desc = _worker(store, None, tmp_path)
    job = _queue(store, desc, HALF)
    asyncio.run(w.run_once())
    events = store.events_after(0, job_id=job)
    types = [e.type for e in events]
    assert types.count("arc_warning") == 1  # at the start, not again when finishing
    assert "progress" in types and types.index("arc_warning") < types.index("progress")
    _says_what_and_what_to_do(_arc_events(store, job)[0]["message"])
    # A daemon restarted on the same store (a new worker) does not record it again.
    again, _ = _worker(store, None, tmp_path)
    again.basis.note_arc(store, job, HALF, BasisSymmetry.of(ODD))
    assert len(_arc_events(store, job)) == 1


def test_a_job_whose_basis_comes_only_at_finishing_records_it_then(tmp_path: Path) -> None:
    """A provider other than the default one is never called early (it may block): its basis
    is checked when the finishing gets it, and is known to later dry runs."""
    store = JobStore(tmp_path / "jobs.sqlite")
    w, desc = _worker(store, lambda: ODD, tmp_path)
    assert w.basis.symmetry() is None
    job = _queue(store, desc, HALF)
    asyncio.run(w.run_once())
    (event,) = _arc_events(store, job)
    _says_what_and_what_to_do(event["message"])
    assert w.basis.symmetry() == BasisSymmetry(False, ("pile-lean",))
    # The lasting record: the job's summary and its result file carry the warning too.
    row = store.get_job(job)
    assert row.state is JobState.COMPLETED, row.reason
    assert row.summary is not None
    _says_what_and_what_to_do(row.summary["arc_warning"])
    result = read_result(tmp_path / "d" / row.summary["result_path"])
    _says_what_and_what_to_do(result.provenance["arc_warning"])
    full = _queue(store, desc, FULL)
    asyncio.run(w.run_once())
    assert _arc_events(store, full) == []
    row = store.get_job(full)
    assert row.summary is not None and "arc_warning" not in row.summary
    assert "arc_warning" not in read_result(tmp_path / "d" / row.summary["result_path"]).provenance


def test_gonio_scan_prints_a_warning_the_job_records_later(
        capsys: pytest.CaptureFixture[str]) -> None:
    """The in-process scan follows its job's events: an arc warning recorded only when the job
    starts or finishes (its basis unknown at submission) is printed then, for that job only."""
    from types import SimpleNamespace

    from gonio.cli.scan_commands import _progress

    class Service:
        def add_event_listener(self, listener: Any) -> None:
            self.listener = listener

    svc = Service()
    bar = _progress(svc, 3, disabled=True)
    svc.listener(SimpleNamespace(job_id=3, type="arc_warning", data={"message": "mine"}))
    svc.listener(SimpleNamespace(job_id=4, type="arc_warning", data={"message": "another's"}))
    bar.close()
    err = capsys.readouterr().err
    assert "warning: mine" in err and "another's" not in err
