"""The arc from the data (gonio.plans.arc, ArcRounds): which angles test, what the test says,
where the scan goes next, and what the dry run bounds for either verdict.

The readings are synthetic with known symmetry: a BRDF-like swing ``exp(cos 2 a)`` per pair
(twofold symmetric: it repeats every 180 deg) and the same with a ``cos(a - a0)`` factor (a
lean one way, as tilted facets or pile give), each with 1 % relative noise, the level the test
is told.
"""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest

from gonio.hal import PairSpec
from gonio.motion import move_time
from gonio.plans.arc import (
    ARC_TEST_EVENT,
    arc_test,
    branch_bounds,
    fill_angles,
    first_round_angles,
    half_turn_warning,
    opposites_needed,
)
from gonio.plans.checked import check_plan
from gonio.plans.dryrun import dry_run
from gonio.plans.models import AdaptivePlan, ExposureSettings, PlanError, UniformPlan, parse_plan
from gonio.plans.rounds import AdaptiveRounds, ArcRounds, NextRound, SingleRound, rounds_for
from gonio.rigdescription import RigDescription

NOISE = 0.01


def _readings(angles: list[float], lean: float, n_pairs: int = 10, seed: int = 0,
              channels: int = 3) -> np.ndarray:
    """(n_pairs, r, C) readings: each pair a swing of its own phase and scale, times
    ``exp(lean cos(a - a0_q))`` (0: twofold symmetric), with 1 % relative noise."""
    rng = np.random.default_rng(seed)
    a = np.deg2rad(np.asarray(angles, float))[None, :, None]
    phase = rng.uniform(0, np.pi, (n_pairs, 1, 1))
    lean_dir = rng.uniform(0, 2 * np.pi, (n_pairs, 1, 1))
    scale = rng.uniform(100.0, 5000.0, (n_pairs, 1, channels))
    clean = scale * np.exp(np.cos(2 * (a - phase)) + lean * np.cos(a - lean_dir))
    return clean * (1.0 + NOISE * rng.standard_normal(clean.shape))


def _next(rounds: Any, angles: list[float], values: np.ndarray, planned: int,
          last: int) -> NextRound:
    return asyncio.run(rounds.next_round(angles, values, planned, last))


def test_the_first_round_reads_one_opposite_or_two_a_quarter_turn_apart() -> None:
    # Counted by hand: 8 over half a turn from 0 plus the opposite of 0.
    assert first_round_angles(0.0, 8) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180])
    assert fill_angles(0.0, 8) == pytest.approx([202.5, 225, 247.5, 270, 292.5, 315, 337.5])
    # Pairs in one plane: the opposites of 0 and 90.
    assert first_round_angles(0.0, 8, 2) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180, 270])
    assert fill_angles(0.0, 8, 2) == pytest.approx([202.5, 225, 247.5, 292.5, 315, 337.5])
    # Together: 16 uniform angles over the full turn, each once, either way.
    for k in (1, 2):
        both = sorted(first_round_angles(0.0, 8, k) + fill_angles(0.0, 8, k))
        assert both == pytest.approx([22.5 * j for j in range(16)])
    assert first_round_angles(30.0, 4) == pytest.approx([30, 75, 120, 165, 210])
    assert fill_angles(30.0, 4) == pytest.approx([255, 300, 345])
    assert first_round_angles(30.0, 4, 2) == pytest.approx([30, 75, 120, 165, 210, 300])
    assert fill_angles(30.0, 4, 2) == pytest.approx([255, 345])
    for k in (1, 2):
        assert first_round_angles(350.0, 1, k) == pytest.approx([350, 170])
        assert fill_angles(350, 1, k) == []
    with pytest.raises(ValueError, match="1 or 2"):
        first_round_angles(0.0, 8, 3)


def _dirs(theta_phi: list[tuple[float, float]]) -> np.ndarray:
    t, p = np.deg2rad(np.asarray(theta_phi, float)).T
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)


def test_pairs_in_one_plane_need_a_second_opposite() -> None:
    # An in-plane instrument: lights at 45 deg, sensors at -15 .. 110 deg aspecular, all in
    # the plane phi = 0 / 180 (and one on the normal, which lies in every plane).
    lights = _dirs([(45, 180)] * 4)
    sensors = _dirs([(30, 0), (60, 0), (0, 0), (65, 180)])
    assert opposites_needed(lights, sensors) == 2
    # Within the tolerance of that plane: still in-plane.
    assert opposites_needed(lights, _dirs([(30, 1.5), (60, 0), (0, 0), (65, 180)])) == 2
    # One sensor out of the plane (an MA98-like out-of-plane geometry): one opposite.
    assert opposites_needed(lights, _dirs([(30, 0), (60, 0), (45, 90), (65, 180)])) == 1
    # Everything on the normal: no azimuth to tell, the safe two.
    assert opposites_needed(_dirs([(0, 0)]), _dirs([(0, 0)])) == 2


def test_a_lean_across_the_plane_is_seen_only_by_the_second_opposite() -> None:
    """Why in-plane pairs read two opposites: a lean at 90 deg to their plane makes each
    pair's ``ln f(a) - ln f(a + 180)`` vary as ``cos(a - 90)``, zero at 0 and 180."""
    rng = np.random.default_rng(3)
    one, two = first_round_angles(0.0, 8, 1), first_round_angles(0.0, 8, 2)

    def read(angles: list[float]) -> np.ndarray:
        a = np.deg2rad(np.asarray(angles))[None, :, None]
        clean = 1000.0 * np.exp(np.cos(2 * a) + 0.2 * np.cos(a - np.pi / 2)) * np.ones((6, 1, 3))
        return clean * (1.0 + NOISE * rng.standard_normal(clean.shape))

    assert arc_test(one, read(one), NOISE)["symmetric"]
    assert not arc_test(two, read(two), NOISE)["symmetric"]


def test_a_symmetric_specimen_keeps_half_a_turn_and_a_leaning_one_gets_the_full_turn() -> None:
    angles = first_round_angles(0.0, 8)
    sym = arc_test(angles, _readings(angles, 0.0), NOISE)
    assert sym["symmetric"] and sym["arc_deg"] == 180.0
    assert sym["opposite_pairs"] == 1 and sym["dof"] == 10 * 1 * 3
    assert half_turn_warning(sym) is None
    # A lean of 5 % in log (the difference at opposite angles up to 10 %, seven times the
    # noise of a difference) is found whichever way each pair leans.
    lean = arc_test(angles, _readings(angles, 0.05), NOISE)
    assert not lean["symmetric"] and lean["arc_deg"] == 360.0
    assert lean["p_value"] < 1e-6 and lean["asymmetric_pairs"] >= 5
    assert "NOT twofold symmetric" in lean["message"]
    warning = half_turn_warning(lean)
    assert warning is not None and "span_deg 360" in warning
    # The pair's scale does not matter (uncalibrated counts): the same readings x 1000.
    assert arc_test(angles, 1000 * _readings(angles, 0.05), NOISE)["statistic"] == \
        pytest.approx(lean["statistic"])


def test_the_false_alarm_rate_is_the_level() -> None:
    """200 symmetric specimens with noise at the model's level: the test calls about 1 %
    (its level) asymmetric; binomial(200, 0.01) exceeds 8 with probability below 1e-3."""
    angles = first_round_angles(0.0, 8)
    called = sum(not arc_test(angles, _readings(angles, 0.0, seed=s), NOISE)["symmetric"]
                 for s in range(200))
    assert called <= 8


def test_readings_that_cannot_be_tested_take_the_full_turn() -> None:
    angles = first_round_angles(0.0, 4)
    out = arc_test(angles, np.zeros((3, len(angles), 1)), NOISE)
    assert not out["symmetric"] and out["arc_deg"] == 360.0 and out["statistic"] is None
    assert "could not run" in out["message"] and half_turn_warning(out) is None


def _auto(desc: RigDescription, **kw: Any) -> Any:
    kind = AdaptivePlan if kw.pop("adaptive", False) else UniformPlan
    return check_plan(kind(arc="auto", **kw), desc)


def test_a_symmetric_uniform_plan_stops_after_its_first_round(desc: RigDescription) -> None:
    checked = _auto(desc, rotations=8)
    assert list(checked.angles_deg) == pytest.approx(first_round_angles(0.0, 8))
    rounds = rounds_for(checked)
    assert isinstance(rounds, ArcRounds)
    angles = list(checked.angles_deg)
    nxt = _next(rounds, angles, _readings(angles, 0.0, n_pairs=3), len(angles), 0)
    assert nxt.angles_deg == []
    assert [t for t, _ in nxt.events] == [ARC_TEST_EVENT]
    assert nxt.events[0][1]["symmetric"] and rounds.arc_deg == 180.0


def test_an_asymmetric_uniform_plan_fills_the_full_turn_then_stops(
        desc: RigDescription) -> None:
    checked = _auto(desc, rotations=8)
    rounds = rounds_for(checked)
    angles = list(checked.angles_deg)
    nxt = _next(rounds, angles, _readings(angles, 0.05, n_pairs=3), len(angles), 0)
    assert nxt.angles_deg == pytest.approx(fill_angles(0.0, 8))
    assert nxt.events[0][0] == ARC_TEST_EVENT and rounds.arc_deg == 360.0
    done = angles + nxt.angles_deg
    # Round 1 was the fill: nothing more, and the test is not run or recorded again.
    last = _next(rounds, done, _readings(done, 0.05, n_pairs=3), len(done), 1)
    assert last == NextRound([])


def test_a_resumed_plan_goes_on_on_the_arc_it_chose(desc: RigDescription) -> None:
    """The stored choice wins over the readings: symmetric readings, but the job chose the full
    turn before it was interrupted; it fills, and records no second test."""
    checked = _auto(desc, rotations=4)
    angles = list(checked.angles_deg)
    values = _readings(angles, 0.0, n_pairs=3)
    chosen = arc_test(angles, _readings(angles, 0.1, n_pairs=3), NOISE)
    assert not chosen["symmetric"]
    nxt = _next(rounds_for(checked, chosen=chosen), angles, values, len(angles), 0)
    assert nxt == NextRound(fill_angles(0.0, 4), [])


def test_a_job_whose_first_round_read_two_opposites_does_not_read_one_twice(
        desc: RigDescription) -> None:
    """A job started by a gonio that read 180 and 270 on every rig, resumed by this one (one
    opposite on the MemRig's pairs): the fill skips 270, already read."""
    checked = _auto(desc, rotations=8)
    old_first = first_round_angles(0.0, 8, 2)
    chosen = arc_test(old_first, _readings(old_first, 0.1, n_pairs=3), NOISE)
    nxt = _next(rounds_for(checked, chosen=chosen), old_first,
                _readings(old_first, 0.1, n_pairs=3), len(old_first), 0)
    assert nxt.angles_deg == pytest.approx([202.5, 225, 247.5, 292.5, 315, 337.5])


def test_adaptive_plans_refine_within_the_arc_chosen(desc: RigDescription) -> None:
    checked = _auto(desc, adaptive=True, rule="vf", initial_rotations=4, max_rounds=4)
    assert checked.plan.span_deg == 180.0  # auto keeps vf's first round over half a turn
    angles = list(checked.angles_deg)
    # Symmetric: V&F's rule over half a turn, every new angle in [0, 180).
    sym = rounds_for(checked)
    nxt = _next(sym, angles, _readings(angles, 0.0, n_pairs=3), len(angles), 0)
    assert isinstance(sym._after(), AdaptiveRounds) and sym._after().arc_deg == (0.0, 180.0)
    assert nxt.angles_deg and all(0 <= a < 180 for a in nxt.angles_deg)
    assert next(t for t, _ in nxt.events) == ARC_TEST_EVENT
    # Asymmetric: the fill, then V&F's rule over the full turn (new angles past 180 too).
    asym = rounds_for(checked)
    fill = _next(asym, angles, _readings(angles, 0.1, n_pairs=3), len(angles), 0)
    assert fill.angles_deg == pytest.approx([225.0, 270.0, 315.0])
    done = angles + fill.angles_deg
    nxt = _next(asym, done, _readings(done, 0.1, n_pairs=3), len(done), 1)
    assert asym._after().arc_deg == (0.0, 360.0)
    assert nxt.angles_deg and any(a > 180 for a in nxt.angles_deg)
    assert ARC_TEST_EVENT not in [t for t, _ in nxt.events]


def test_fixed_plans_keep_their_rounds(desc: RigDescription) -> None:
    assert isinstance(rounds_for(check_plan(UniformPlan(), desc)), SingleRound)
    assert isinstance(rounds_for(check_plan(AdaptivePlan(), desc)), AdaptiveRounds)


def test_auto_with_a_forced_full_turn_is_refused_with_what_to_do() -> None:
    with pytest.raises(PlanError, match="drop arc 'auto' or span_deg 360"):
        parse_plan({"kind": "uniform", "arc": "auto", "span_deg": 360})
    with pytest.raises(PlanError, match=r"'fixed'.*'auto'"):
        parse_plan({"kind": "uniform", "arc": "half"})
    with pytest.raises(PlanError, match="arc_noise"):
        parse_plan({"kind": "uniform", "arc": "auto", "arc_noise": 0})
    # A stored plan from before the field reads as fixed (its meaning at submission).
    old = UniformPlan().model_dump(mode="json")
    old.pop("arc")
    assert parse_plan(old).arc == "fixed"


EX = ExposureSettings(exposure_s=0.1, light_settle_s=0.0, dark="none")


def test_the_dry_run_bounds_both_verdicts_of_a_uniform_plan(desc: RigDescription) -> None:
    """Counted by hand, 3 pairs (not in one plane: one opposite), 2 lights, 0.1 s per
    exposure, from 0 at 30 deg/s: symmetric, the first round's 9 angles (0 .. 180 in 22.5
    steps); asymmetric, 7 more (202.5 .. 337.5 in 22.5 steps, on from 180)."""
    d = dry_run(UniformPlan(rotations=8, arc="auto", exposure=EX), desc)
    v, a = desc.speed_dps, desc.accel_dps2
    first_motion = 8 * move_time(22.5, v, a)
    assert d.motion_s == pytest.approx(first_motion)
    assert d.estimated_s == pytest.approx(first_motion + 9 * 2 * 0.1)
    assert d.arc_branches is not None
    sym, asym = d.arc_branches
    assert (sym.arc_deg, sym.angles, sym.readings) == (180.0, 9, 27)
    assert sym.estimated_s == pytest.approx(d.estimated_s)
    assert (asym.arc_deg, asym.angles, asym.readings) == (360.0, 16, 48)
    fill_motion = 7 * move_time(22.5, v, a)
    assert asym.estimated_s == pytest.approx(d.estimated_s + fill_motion + 7 * 2 * 0.1)
    assert d.max_angles == 16 and d.max_estimated_s == pytest.approx(asym.estimated_s)
    assert dry_run(UniformPlan(exposure=EX), desc).arc_branches is None


def test_pairs_in_one_plane_read_two_opposites_through_the_plan(desc: RigDescription) -> None:
    """The rule reaches the plan: the MemRig's pair L1/S1 alone lies in the plane phi = 0 /
    180 (light at phi 0, sensor at 180), so its first round reads 0/180 and 90/270, and the
    fill the 6 others (hand count as in the first test)."""
    plan = UniformPlan(rotations=8, arc="auto", exposure=EX,
                       pairs=[PairSpec(light="L1", sensor="S1")])
    checked = check_plan(plan, desc)
    assert checked.arc_opposites == 2
    assert list(checked.angles_deg) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180, 270])
    d = dry_run(plan, desc)
    assert d.arc_branches is not None
    assert [(b.angles, b.readings) for b in d.arc_branches] == [(10, 10), (16, 16)]
    rounds = rounds_for(checked)
    angles = list(checked.angles_deg)
    lean = _readings(angles, 0.1, n_pairs=1)
    assert _next(rounds, angles, lean, len(angles), 0).angles_deg == pytest.approx(
        [202.5, 225, 247.5, 292.5, 315, 337.5])


def test_the_dry_run_says_which_basis_each_verdict_reconstructs_with(
        desc: RigDescription) -> None:
    """Found asymmetric, the job is reconstructed with the basis with odd harmonics, and waits
    at finishing for its build when it is not built yet (not in the measuring bound)."""
    from gonio.plans.dryrun import BasisSymmetry

    plan = UniformPlan(rotations=8, arc="auto", exposure=EX)
    d = dry_run(plan, desc, asymmetric_build_s=300.0)
    assert d.arc_branches is not None
    sym, asym = d.arc_branches
    assert (sym.basis, sym.basis_build_s) == ("default", None)
    assert (asym.basis, asym.basis_build_s) == ("asymmetric", 300.0)
    assert d.max_estimated_s == pytest.approx(asym.estimated_s)  # measuring only
    built = dry_run(plan, desc).arc_branches
    assert built is not None and (built[1].basis, built[1].basis_build_s) == ("asymmetric", None)
    # No such basis in the process, or its own basis already holds odd harmonics: kept.
    for kept in (dry_run(plan, desc, asymmetric_basis=False, asymmetric_build_s=300.0),
                 dry_run(plan, desc, basis=BasisSymmetry(False, ("pile-000",)))):
        assert kept.arc_branches is not None
        assert [(b.basis, b.basis_build_s) for b in kept.arc_branches] == [
            ("default", None), ("default", None)]


def test_the_dry_run_bounds_both_verdicts_of_an_adaptive_plan(desc: RigDescription) -> None:
    """Counted by hand, 4 first angles and one opposite, max_rounds 3, no cap: symmetric, 0
    45 90 135 (180 is the same position as 0 over half a turn) gain 4 then 8 midpoints:
    5 + 4 + 8 = 17; asymmetric, the fill (225, 270, 315) makes 8 over the full turn, one
    refinement round left adds 8 midpoints: 16."""
    plan = AdaptivePlan(initial_rotations=4, max_rounds=3, max_rotations=None, arc="auto",
                        exposure=EX)
    d = dry_run(plan, desc)
    assert d.angles_deg == pytest.approx([0, 45, 90, 135, 180])
    assert d.arc_branches is not None
    assert [(b.arc_deg, b.angles) for b in d.arc_branches] == [(180.0, 17), (360.0, 16)]
    assert d.max_angles == 17
    assert all(b.estimated_s >= b.angles * 2 * 0.1 for b in d.arc_branches)
    assert check_plan(plan, desc).max_angles == 17
    # The bounds are branch_bounds' (what the engine's ETA uses too).
    extra = branch_bounds(plan, desc, 2, 3, d.angles_deg, d.positions_deg[-1])
    assert {k: n for k, (n, _) in extra.items()} == {180.0: 12, 360.0: 11}
