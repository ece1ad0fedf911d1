"""The twofold symmetry test's verdict chooses the reconstruction basis (docs/science.md 7.4).

A scan whose test calls its specimen asymmetric over a full turn is reconstructed with the
basis supply's basis with odd harmonics (:meth:`gonio.basis_supply.BasisSupply.asymmetric`);
the switch is in the job's summary, its ``basis_switch`` event and its result file, and a
rebuild switches the same way. A symmetric specimen stays on the default basis and the
asymmetric one is never asked for. The in-memory rig reads ``1 + 0.5 cos 2 alpha`` (twofold
symmetric), times ``1 + lean cos alpha`` when it is given a lean; the bases are small random
ones of different K, so the recorded K says which one reconstructed.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest

from gonio.basis_supply import BasisSupply
from gonio.brdf.reconstruction.basis import Basis
from gonio.finishing import rebuild_result
from gonio.jobstates import JobState
from gonio.plans.arc import ARC_TEST_EVENT
from gonio.plans.models import AdaptivePlan, ExposureSettings, UniformPlan
from gonio.results import read_result
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig
from gonio.store import JobRow, JobStore
from gonio.worker import Worker
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")
AUTO = UniformPlan(rotations=4, arc="auto", exposure=FAST)
FULL = UniformPlan(rotations=8, span_deg=360, exposure=FAST)
# Only even harmonics along ph, as the shipped basis.
EVEN = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 0.5})
# An odd harmonic too: a prior that can represent a specimen without twofold symmetry.
ODD = _with_prior(random_basis(7, seed=2), {0: 1.0, 1: 0.3, 2: 0.5})


def _never() -> Basis:
    raise AssertionError("a symmetric specimen needs no asymmetric basis")


def _run(tmp_path: Path, lean: float, plan: UniformPlan | AdaptivePlan, asymmetric: Any
         ) -> tuple[JobStore, JobRow]:
    """One job of ``plan`` on an in-memory rig of ``lean``, measured and finished."""
    rig = MemRig(lean=lean)
    desc = RigDescription.from_rig(rig)
    store = JobStore(tmp_path / "jobs.sqlite")

    async def get_rig() -> MemRig:
        return rig

    worker = Worker(store, get_rig, desc, tmp_path / "d", BasisSupply(lambda: EVEN, asymmetric),
                    fit_exports=False)
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json")).id
    asyncio.run(worker.run_once())
    row = store.get_job(job)
    assert row.state is JobState.COMPLETED, row.reason
    return store, row


def _events(store: JobStore, job: int, kind: str) -> list[dict[str, Any]]:
    return [e.data for e in store.events_after(0, job_id=job) if e.type == kind]


def test_an_asymmetric_specimen_is_reconstructed_with_the_asymmetric_basis(
        tmp_path: Path) -> None:
    store, row = _run(tmp_path, 0.3, AUTO, lambda: ODD)
    (test,) = _events(store, row.id, ARC_TEST_EVENT)
    assert not test["symmetric"] and test["arc_deg"] == 360.0
    summary = row.summary
    assert summary is not None
    assert summary["reconstruction_basis"] == "asymmetric" and summary["K"] == ODD.K
    assert "NOT twofold symmetric" in summary["basis_switch"]
    (event,) = _events(store, row.id, "basis_switch")
    assert event["basis"] == "asymmetric" and event["K"] == ODD.K
    assert event["message"] == summary["basis_switch"]
    result = read_result(tmp_path / "d" / summary["result_path"])
    assert result.metrics["reconstruction_basis"] == "asymmetric"
    assert result.provenance["reconstruction_basis"] == "asymmetric"
    assert result.provenance["basis_switch"] == summary["basis_switch"]
    assert int(result.provenance["basis_K"]) == ODD.K
    assert json.loads(result.provenance["basis_materials"]) == list(ODD.materials)
    # Rebuilt from the stored readings, the stored verdict switches it again.
    again = rebuild_result(store, tmp_path / "d", row.id,
                           BasisSupply(lambda: EVEN, lambda: ODD))
    assert again["reconstruction_basis"] == "asymmetric" and again["K"] == ODD.K


def test_a_symmetric_specimen_stays_on_the_default_basis(tmp_path: Path) -> None:
    store, row = _run(tmp_path, 0.0, AUTO, _never)
    (test,) = _events(store, row.id, ARC_TEST_EVENT)
    assert test["symmetric"] and test["arc_deg"] == 180.0
    assert row.summary is not None
    assert row.summary["reconstruction_basis"] == "default" and row.summary["K"] == EVEN.K
    assert "basis_switch" not in row.summary
    assert _events(store, row.id, "basis_switch") == []


def test_a_full_turn_plan_is_tested_at_finishing_and_switched(tmp_path: Path) -> None:
    """A lab that chose a full turn itself (span_deg 360, 8 angles: 4 opposite pairs) gets the
    same verdict, from the finishing's test of its readings, and the same basis."""
    store, row = _run(tmp_path, 0.3, FULL, lambda: ODD)
    assert row.summary is not None
    assert not row.summary["arc_symmetric"] and row.summary["arc_deg"] == 360.0
    assert row.summary["reconstruction_basis"] == "asymmetric" and row.summary["K"] == ODD.K
    assert len(_events(store, row.id, "basis_switch")) == 1


def test_an_asymmetric_basis_that_cannot_be_had_keeps_the_measurement(tmp_path: Path) -> None:
    def broken() -> Basis:
        raise OSError("cache folder not writable")

    _, row = _run(tmp_path, 0.3, AUTO, broken)
    summary = row.summary
    assert summary is not None and summary["reconstruction_basis"] == "default"
    assert summary["K"] == EVEN.K
    assert "cache folder not writable" in summary["basis_switch"]
    assert "gonio jobs rebuild" in summary["basis_switch"]
    assert (tmp_path / "d" / summary["result_path"]).is_file()


def test_a_supply_without_an_asymmetric_basis_says_so(tmp_path: Path) -> None:
    _, row = _run(tmp_path, 0.3, AUTO, None)
    assert row.summary is not None and row.summary["reconstruction_basis"] == "default"
    assert "has none with odd harmonics" in row.summary["basis_switch"]


def test_an_adaptive_auto_plan_refines_with_the_basis_it_will_finish_with(
        tmp_path: Path) -> None:
    """Issue 25: once the test calls the specimen asymmetric, the refinement rounds over the
    full turn plan with the asymmetric basis' posterior (the one finishing reconstructs with),
    and each round's event says so; a symmetric specimen's rounds plan with the default basis
    and the asymmetric one is never asked for."""
    plan = AdaptivePlan(initial_rotations=4, max_rotations=12, min_gain=1e-9, arc="auto",
                        exposure=FAST)
    store, row = _run(tmp_path, 0.3, plan, lambda: ODD)
    (test,) = _events(store, row.id, ARC_TEST_EVENT)
    assert not test["symmetric"] and test["arc_deg"] == 360.0
    rounds = _events(store, row.id, "adaptive_round") + _events(store, row.id, "adaptive_done")
    assert rounds and all(r["rule"] == "posterior" and r["basis"] == "asymmetric"
                          for r in rounds)
    assert any(s.specimen_deg > 180.0 for s in store.steps(row.id) if s.round >= 2)
    assert row.summary is not None and row.summary["reconstruction_basis"] == "asymmetric"
    sym_store, sym = _run(tmp_path / "sym", 0.0, plan, _never)
    rounds = (_events(sym_store, sym.id, "adaptive_round")
              + _events(sym_store, sym.id, "adaptive_done"))
    assert rounds and all(r["basis"] == "default" and "basis_note" not in r for r in rounds)
    assert sym.summary is not None and sym.summary["reconstruction_basis"] == "default"


@pytest.mark.parametrize("lean", [0.0, 0.3])
def test_a_forced_half_turn_never_switches(tmp_path: Path, lean: float) -> None:
    """Over half a turn the readings cannot tell an odd harmonic from its alias: no plan
    kind reads opposite angles over half a turn, so there is no test and no switch."""
    _, row = _run(tmp_path, lean, UniformPlan(rotations=4, exposure=FAST), _never)
    assert row.summary is not None and "reconstruction_basis" not in row.summary
    assert row.summary["K"] == EVEN.K


def test_a_full_turn_fixed_by_its_plan_is_not_said_to_be_the_tests_choice(
        tmp_path: Path) -> None:
    """A symmetric specimen scanned over a full turn because the plan fixed it: the test, run
    at finishing, would have chosen half a turn. The result said "Scanned over half a turn:
    the first round's readings ... say the specimen is twofold symmetric" on the page and in
    the terminal, and its file's test said arc_deg 180. Now every place says the arc scanned
    and that the plan chose it."""
    from gonio.cli.scan_report import scan_summary
    from gonio.figures import headline_error

    _, row = _run(tmp_path, 0.0, FULL, _never)
    summary = row.summary
    assert summary is not None
    assert summary["arc_symmetric"] is True and summary["arc_deg"] == 360.0
    assert summary["arc_mode"] == "fixed"
    result = read_result(tmp_path / "d" / summary["result_path"])
    test = json.loads(result.provenance["arc_test"])
    assert test["arc_deg"] == 360.0 and test["arc_chosen_by"] == "plan"
    assert test["arc_the_test_would_choose"] == 180.0
    headline = headline_error(result.metrics)
    assert headline is not None
    assert headline["arc"].startswith("Scanned over a full turn, as its plan fixed it; its "
                                      "readings at opposite stage angles say the specimen is "
                                      "twofold symmetric (chi-square "), headline["arc"]
    assert "half a turn" not in headline["meaning"] and "first round" not in headline["meaning"]
    lines = [text for text, _ in scan_summary(row.id, summary, None, "kept")]
    (arc,) = [t for t in lines if t.startswith("  arc: ")]
    assert arc.startswith("  arc: 360 deg (the plan's); its readings at opposite stage angles "
                          "read the specimen twofold symmetric (chi-square "), arc
