"""Adaptive plans with the posterior rule, through the real engine on the in-memory rig."""

from __future__ import annotations

import asyncio

import numpy as np

from gonio.brdf.reconstruction.posterior import next_angles
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.engine import ScanEngine
from gonio.jobstates import JobState
from gonio.plans.models import AdaptivePlan, ExposureSettings
from gonio.plans.validation import plan_pairs
from gonio.refinement import PosteriorRefiner
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig
from gonio.store import JobStore
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")
BASIS = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 1.0})


def _run(plan: AdaptivePlan, with_refiner: bool = True) -> tuple[JobStore, ScanEngine,
                                                                   RigDescription]:
    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    refiner = PosteriorRefiner(lambda: BASIS, desc, plan_pairs(plan, desc)) if with_refiner \
        else None
    eng = ScanEngine(rig, store, job.id, plan, desc, refiner=refiner)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    return store, eng, desc


def _events(store: JobStore, kind: str) -> list[dict[str, object]]:
    return [dict(e.data or {}) for e in store.events_after(0) if e.type == kind]


def test_the_engine_measures_the_angles_the_posterior_rule_plans() -> None:
    """Round 1 holds exactly the angles next_angles plans from round 0's readings over the
    plan's half turn (the MemRig's readings swing with cos 2 alpha, so the rule refines),
    within the budget."""
    plan = AdaptivePlan(initial_rotations=8, exposure=FAST, min_gain=1e-9, max_rounds=2,
                        max_samples=4 * 12)
    store, eng, desc = _run(plan)
    steps = store.steps(1)
    first = [s for s in steps if s.round == 0]
    later = sorted(round(s.specimen_deg % 360.0, 6) for s in steps if s.round == 1)
    angles, values = eng.measured_values(first)
    n_pairs = len(eng.pairs)
    cells, ph = eng.refiner.cells, eng.refiner.ph_lab  # type: ignore[union-attr]
    vals = np.maximum(values, 0.0)
    # The rule's measure is the drop of the self-estimate: the fit's witnesses go in with the
    # readings; its posterior sizes a per-pair offset from the scan.
    rec = reconstruct(BASIS, cells, ph, np.deg2rad(angles), vals)
    want = next_angles(BASIS, cells, ph, angles, vals, threshold=1e-9,
                       min_step_deg=desc.resolution_deg,
                       budget_angles=plan.max_samples // n_pairs - 8,  # type: ignore[operator]
                       per_gap=1, period_deg=180.0,  # the plan's default arc, half a turn
                       cv_sample_error=rec.cv_sample_error, mahalanobis=rec.mahalanobis,
                       offset="scan")
    assert later and later == [round(a, 6) for a in want.angles_deg]
    assert len(steps) * n_pairs <= plan.max_samples  # type: ignore[operator]
    assert _events(store, "adaptive_round")[0]["rule"] == "posterior"


def test_the_plan_stops_when_the_rule_says() -> None:
    plan = AdaptivePlan(initial_rotations=8, exposure=FAST, min_gain=1e3)
    store, _eng, _ = _run(plan)
    assert {s.round for s in store.steps(1)} == {0}
    (done,) = _events(store, "adaptive_done")
    assert (done["reason"], done["rule"]) == ("converged", "posterior")
    # What the rule saw is in the event: the drop that stopped it is below the plan's min_gain.
    assert 0 <= float(done["best_drop"]) < plan.min_gain  # type: ignore[arg-type]
    assert {"rho", "offset", "expected_log_rmse"} <= set(done)
    # Converged: nothing about a limit in the result.
    from typing import Any

    from gonio.finishing import _record_adaptive_stop

    metrics: dict[str, Any] = {}
    _record_adaptive_stop(store, 1, metrics, {})
    assert metrics == {"adaptive_stop": "converged"}


def test_without_a_basis_the_engine_uses_the_vf_rule_and_says_so() -> None:
    plan = AdaptivePlan(initial_rotations=8, exposure=FAST, threshold=0.01, max_rounds=2)
    store, _eng, _ = _run(plan, with_refiner=False)
    assert {s.round for s in store.steps(1)} == {0, 1}
    assert _events(store, "adaptive_round")[0]["rule"] == "vf"


def test_the_plan_default_is_the_calibrated_threshold() -> None:
    from gonio.brdf.reconstruction.posterior import REFINE_GAIN

    assert AdaptivePlan().rule == "posterior" and AdaptivePlan().min_gain == REFINE_GAIN


def test_a_failing_posterior_rule_falls_back_to_vf_and_says_why() -> None:
    """A basis that cannot be loaded must not fail the scan: the round uses V&F's rule and the
    event log keeps the reason."""
    plan = AdaptivePlan(initial_rotations=8, exposure=FAST, threshold=0.01, max_rounds=2)
    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))

    def no_basis() -> object:
        raise OSError("basis file unreadable")

    refiner = PosteriorRefiner(no_basis, desc, plan_pairs(plan, desc))
    eng = ScanEngine(rig, store, job.id, plan, desc, refiner=refiner)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert {s.round for s in store.steps(job.id)} == {0, 1}
    failed = [e for e in _events(store, "adaptive_round") if "posterior_failed" in e]
    assert failed and "unreadable" in str(failed[0]["posterior_failed"])


def test_the_job_stops_at_max_rotations() -> None:
    """A rule that would refine on (min_gain tiny, six rounds allowed) stops at the plan's cap
    on stage angles, and says why; the default cap is the dry run's bound (16)."""
    plan = AdaptivePlan(initial_rotations=4, exposure=FAST, min_gain=1e-12, max_rotations=7)
    store, _eng, _ = _run(plan)
    steps = store.steps(1)
    assert len(steps) == 7 and len({round(s.specimen_deg % 360.0, 6) for s in steps}) == 7
    done = _events(store, "adaptive_done")[-1]
    assert done["reason"] == "budget"
    assert AdaptivePlan().max_rotations == 16
    # The rule was still asked at the cap: with a tiny min_gain it wanted more, and the job
    # says so in its event and, through finishing, in its result's metrics and provenance.
    assert isinstance(done["wanted"], int) and done["wanted"] > 0
    assert "limit of 7 stage angles" in str(done["message"])
    from typing import Any

    from gonio.finishing import _record_adaptive_stop

    metrics: dict[str, Any] = {}
    provenance: dict[str, Any] = {}
    _record_adaptive_stop(store, 1, metrics, provenance)
    assert metrics["adaptive_stop"] == "budget" and metrics["adaptive_wanted"] == done["wanted"]
    assert metrics["adaptive_limit"] == provenance["adaptive_limit"] == done["message"]


def test_a_half_turn_job_refines_and_moves_only_within_its_half_turn() -> None:
    """An adaptive job over half a turn from 300 deg (the arc [300, 480), i.e. 300..360 and
    0..120), refined all the way (min_gain tiny) to its cap of 16 angles: every gap of the
    half turn is halved each round (4 -> 8 -> 16), so it measures exactly the 16 uniform angles
    300 + 11.25 k of the half turn, and the stage never goes to the other half."""
    plan = AdaptivePlan(initial_rotations=4, exposure=FAST, min_gain=1e-12, start_deg=300.0)
    assert plan.span_deg == 180.0
    store, eng, _ = _run(plan)
    steps = store.steps(1)
    arc = {round((300.0 + 11.25 * k) % 360.0, 6) for k in range(16)}
    assert sorted(s.round for s in steps) == [0] * 4 + [1] * 4 + [2] * 8
    assert {round(s.specimen_deg % 360.0, 6) for s in steps} == arc
    moves = eng.rig.mstage.moves  # type: ignore[attr-defined]
    assert moves and all(not 120.0 < m % 360.0 < 300.0 for m in moves)
    assert _events(store, "adaptive_done")[-1]["reason"] == "budget"


def test_the_vf_rule_over_a_half_turn_moves_only_within_it() -> None:
    """Without a basis the engine's V&F rule refines within the plan's half turn too."""
    plan = AdaptivePlan(initial_rotations=8, exposure=FAST, threshold=1e-6, max_rounds=2,
                        span_deg=180.0, rule="vf")
    store, eng, _ = _run(plan, with_refiner=False)
    later = sorted(round(s.specimen_deg % 360.0, 6) for s in store.steps(1) if s.round == 1)
    assert later == [11.25 + 22.5 * k for k in range(8)]  # every midpoint of 0, 22.5, .., 157.5
    moves = eng.rig.mstage.moves  # type: ignore[attr-defined]
    assert moves and all(m % 360.0 < 180.0 for m in moves)


# PosteriorRefiner on its own (channel counts, calibration, what a new angle buys):
# tests/unit/test_refinement.py.
