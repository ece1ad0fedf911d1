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

from gonio.motion import move_time
from gonio.plans.arc import (
    ARC_TEST_EVENT,
    arc_test,
    branch_bounds,
    fill_after,
    fill_angles,
    first_round_angles,
    half_turn_warning,
    opposites_needed,
    pair_planes_deg,
)
from gonio.plans.checked import check_plan
from gonio.plans.dryrun import dry_run
from gonio.plans.models import AdaptivePlan, ExposureSettings, PlanError, UniformPlan, parse_plan
from gonio.plans.rounds import (
    AdaptiveRounds,
    ArcRounds,
    NextRound,
    RoundRequest,
    SingleRound,
    refinement_basis,
    rounds_for,
)
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
    # A pair's channels alike within 20 % (an RGB sensor on a pale specimen): a channel far
    # dimmer than its pair's brightest has more shot noise than 1 % and weighs less.
    scale = rng.uniform(100.0, 5000.0, (n_pairs, 1, 1)) * rng.uniform(0.8, 1.0,
                                                                     (n_pairs, 1, channels))
    clean = scale * np.exp(np.cos(2 * (a - phase)) + lean * np.cos(a - lean_dir))
    return clean * (1.0 + NOISE * rng.standard_normal(clean.shape))


def _next(rounds: Any, angles: list[float], values: np.ndarray, planned: int,
          last: int) -> NextRound:
    return asyncio.run(rounds.next_round(angles, values, planned, last))


def test_the_first_round_reads_one_opposite_or_two_a_quarter_turn_apart() -> None:
    # Counted by hand: 8 over half a turn from 0 plus the opposite of 0 (one opposite), or of
    # 0 and 90 (two); the fill reads the other opposites.
    assert first_round_angles(0.0, 8, 1) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180])
    assert fill_angles(0.0, 8, 1) == pytest.approx([202.5, 225, 247.5, 270, 292.5, 315, 337.5])
    assert first_round_angles(0.0, 8, opposites=2) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180, 270])
    assert fill_angles(0.0, 8, opposites=2) == pytest.approx(
        [202.5, 225, 247.5, 292.5, 315, 337.5])
    # Together, either way: 16 uniform angles over the full turn, each once.
    for k in (1, 2):
        both = sorted(first_round_angles(0.0, 8, k) + fill_angles(0.0, 8, k))
        assert both == pytest.approx([22.5 * j for j in range(16)])
    assert first_round_angles(30.0, 4, 1) == pytest.approx([30, 75, 120, 165, 210])
    assert fill_angles(30.0, 4, 1) == pytest.approx([255, 300, 345])
    assert first_round_angles(30.0, 4, 2) == pytest.approx([30, 75, 120, 165, 210, 300])
    assert fill_angles(30.0, 4, 2) == pytest.approx([255, 345])
    for k in (1, 2):
        assert first_round_angles(350.0, 1, k) == pytest.approx([350, 170])
        assert fill_angles(350, 1, k) == []
    with pytest.raises(ValueError, match="1 or 2"):
        first_round_angles(0.0, 8, 3)


def test_the_fill_after_any_first_round_is_the_opposites_not_read() -> None:
    # By hand: after 0 .. 157.5 and 180, the other seven opposites; after 180 and 270 too,
    # six; a stored round that also read 225 leaves five; nothing read but the half turn's
    # first angle's opposite missing: all eight.
    half = [22.5 * k for k in range(8)]
    assert fill_after(0.0, 8, [*half, 180]) == pytest.approx(
        [202.5, 225, 247.5, 270, 292.5, 315, 337.5])
    assert fill_after(0.0, 8, [*half, 180, 270]) == pytest.approx(
        [202.5, 225, 247.5, 292.5, 315, 337.5])
    assert fill_after(0.0, 8, [*half, 180, 225, 270]) == pytest.approx(
        [202.5, 247.5, 292.5, 315, 337.5])
    assert fill_after(0.0, 8, half) == pytest.approx([180 + 22.5 * k for k in range(8)])


def _dirs(*pairs: tuple[tuple[float, float], tuple[float, float]]) -> tuple[Any, Any]:
    """Lab vectors of (light, sensor) pairs given as ((theta, phi), (theta, phi)) degrees."""
    from gonio.hal import LabDirection

    return (np.array([LabDirection(*li).vector() for li, _ in pairs]),
            np.array([LabDirection(*se).vector() for _, se in pairs]))


def test_each_pair_has_a_plane_and_one_opposite_needs_planes_spread() -> None:
    # By hand: an in-plane pair lies in its plane of incidence, a retro pair in its own
    # azimuth's; both at the pole, or at right angles and equally tilted, have no axis.
    planes = pair_planes_deg(*_dirs(((45, 30), (45, 210)), ((30, 100), (30, 100)),
                                    ((0, 0), (0, 0)), ((45, 0), (45, 90)),
                                    ((45, 170), (60, 350))))
    assert planes[:2] == pytest.approx([30, 100])
    assert np.isnan(planes[2]) and np.isnan(planes[3]) and planes[4] == pytest.approx(170)
    # Light (60, 90), sensor (45, 180): (i sin 60)^2 + (-sin 45)^2 = -0.25, axis 90.
    assert pair_planes_deg(*_dirs(((60, 90), (45, 180)))) == pytest.approx([90])
    in_plane = ((45, 0), (45, 180))
    assert opposites_needed(*_dirs(in_plane)) == 2  # one pair: two opposites
    assert opposites_needed(*_dirs(in_plane, ((45, 30), (45, 210)))) == 2  # 30 deg apart
    assert opposites_needed(*_dirs(in_plane, ((45, 60), (45, 240)))) == 1  # 60 deg apart
    assert opposites_needed(*_dirs(in_plane, ((45, 150), (45, 330)))) == 2  # 150 = -30
    assert opposites_needed(*_dirs(in_plane, ((0, 0), (0, 0)))) == 2  # no axis: not counted


def test_a_lean_across_the_pairs_plane_is_seen_only_by_the_second_opposite() -> None:
    """Why pairs in one plane read two opposites: a lean at 90 deg to their plane makes each
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
    angles = first_round_angles(0.0, 8, opposites=2)
    sym = arc_test(angles, _readings(angles, 0.0), NOISE)
    assert sym["symmetric"] and sym["arc_deg"] == 180.0
    assert sym["opposite_pairs"] == 2 and sym["dof"] == 10 * 2 * 3
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
    # One opposite: the ten pairs lean each its own way (as pairs in different planes see one
    # lean), so at one stage angle some see it; the same 5 % lean is found.
    one = first_round_angles(0.0, 8, 1)
    sym1 = arc_test(one, _readings(one, 0.0), NOISE)
    assert sym1["symmetric"] and sym1["opposite_pairs"] == 1 and sym1["dof"] == 10 * 3
    lean1 = arc_test(one, _readings(one, 0.05), NOISE)
    assert not lean1["symmetric"] and lean1["p_value"] < 1e-6


def test_the_false_alarm_rate_is_the_level() -> None:
    """200 symmetric specimens with noise at the model's level: the test calls about 1 %
    (its level) asymmetric; binomial(200, 0.01) exceeds 8 with probability below 1e-3."""
    angles = first_round_angles(0.0, 8, opposites=2)
    called = sum(not arc_test(angles, _readings(angles, 0.0, seed=s), NOISE)["symmetric"]
                 for s in range(200))
    assert called <= 8


def _spectral_counts(angles: list[float], lean: float, seed: int) -> np.ndarray:
    """(12, r, 31) ``raw - dark`` counts of a 31-band sensor: each pair's brightest band at
    1000-30000 counts, the others down to an eighth of it (a silicon sensor's responsivity
    behind narrow filters), a specimen flat along the rotation times ``exp(lean cos(a -
    a0_q))``, with a photodiode's noise: shot noise (variance 0.5 counts per count) and 2
    counts of read noise, the Gaussian limit of a Poisson count."""
    rng = np.random.default_rng(seed)
    wl = np.linspace(400.0, 700.0, 31)
    response = 0.125 + 0.875 * np.exp(-0.5 * ((wl - 520.0) / 50.0) ** 2)
    a = np.deg2rad(np.asarray(angles, float))[None, :, None]
    lean_dir = rng.uniform(0, 2 * np.pi, (12, 1, 1))
    mean = (rng.uniform(1000.0, 30000.0, (12, 1, 1)) * response[None, None, :]
            * np.exp(lean * np.cos(a - lean_dir)))
    return mean + np.sqrt(0.5 * mean + 4.0) * rng.standard_normal(mean.shape)


def test_a_spectral_sensors_dim_bands_do_not_make_a_flat_specimen_asymmetric() -> None:
    """A spectral sensor's dim bands carry more shot noise than the 1 % the test assumes:
    scaled each by its own brightest reading, they called an isotropic paint asymmetric on 2
    of 5 full-turn scans of the simulated spectral rig (p down to 3e-4, chi-square at 1.03-1.15
    times its 1488 degrees of freedom), and on most such synthetic scans. Scaled by the pair's
    brightest reading over all bands, the level holds: binomial(200, 0.01) exceeds 8 with
    probability below 1e-3. A 5 % lean is still found."""
    angles = [45.0 * k for k in range(8)]  # a full turn: four opposite pairs
    called = sum(not arc_test(angles, _spectral_counts(angles, 0.0, s), NOISE)["symmetric"]
                 for s in range(200))
    assert called <= 8
    lean = arc_test(angles, _spectral_counts(angles, 0.05, 1), NOISE)
    assert not lean["symmetric"] and lean["p_value"] < 1e-6


def test_readings_that_cannot_be_tested_take_the_full_turn() -> None:
    angles = first_round_angles(0.0, 4, 1)
    out = arc_test(angles, np.zeros((3, len(angles), 1)), NOISE)
    assert not out["symmetric"] and out["arc_deg"] == 360.0 and out["statistic"] is None
    assert "could not run" in out["message"] and half_turn_warning(out) is None


def _auto(desc: RigDescription, **kw: Any) -> Any:
    kind = AdaptivePlan if kw.pop("adaptive", False) else UniformPlan
    return check_plan(kind(arc="auto", **kw), desc)


def _spread(desc: RigDescription) -> RigDescription:
    """The in-memory rig with light L2 at (60, 90): pair L2/S1's plane at 90 deg (by hand,
    test above) against L1/S1's at 0, so one opposite tests it."""
    lights = tuple(li.model_copy(update={"theta_deg": 60.0, "phi_deg": 90.0})
                   if li.name == "L2" else li for li in desc.lights)
    return desc.model_copy(update={"lights": lights})


def test_the_pairs_planes_choose_the_first_round(desc: RigDescription) -> None:
    # The in-memory rig's pairs lie in planes at 0, 12 and 0 deg: two opposites.
    assert list(_auto(desc, rotations=8).angles_deg) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180, 270])
    assert list(_auto(_spread(desc), rotations=8).angles_deg) == pytest.approx(
        [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5, 180])


def test_an_auto_plan_whose_full_turn_the_travel_cannot_reach_is_refused_before_it_runs(
        desc: RigDescription) -> None:
    """Travel [-10, 200] deg: the spread rig's first round (0 ... 157.5, 180) fits, but the
    fill round an asymmetric specimen reads (202.5 ... 337.5) does not; refused at the check,
    naming the fix, not after the first round. The in-plane rig's first round (270) already
    does not fit."""
    limited = {"stage_min_deg": -10.0, "stage_max_deg": 200.0}
    with pytest.raises(PlanError, match=r"arc 'auto' reads the full turn .* 202\.5.*"
                                        r"arc 'fixed' with span_deg 180"):
        _auto(_spread(desc).model_copy(update=limited), rotations=8)
    with pytest.raises(PlanError, match=r"180, 270 deg cannot all be visited"):
        _auto(desc.model_copy(update=limited), rotations=8)
    # A fixed half turn on the same stage is fine.
    assert check_plan(UniformPlan(rotations=8, exposure=EX),
                      desc.model_copy(update=limited)).angles_deg[-1] == pytest.approx(157.5)


def test_a_symmetric_uniform_plan_stops_after_its_first_round(desc: RigDescription) -> None:
    checked = _auto(desc, rotations=8)
    assert list(checked.angles_deg) == pytest.approx(first_round_angles(0.0, 8, 2))
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
    assert nxt.angles_deg == pytest.approx(fill_angles(0.0, 8, 2))
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
    assert nxt == NextRound(fill_angles(0.0, 4, 2), [])


def test_one_opposite_fills_seven_angles_and_never_reads_an_angle_twice(
        desc: RigDescription) -> None:
    """Pairs spread: the first round's 9 angles, then (asymmetric) the 7 other opposites
    (202.5 ... 337.5, 270 among them). A job whose round 0 already read 270 (two opposites,
    stored by an earlier version) fills the other 6."""
    checked = _auto(_spread(desc), rotations=8)
    angles = list(checked.angles_deg)
    nxt = _next(rounds_for(checked), angles, _readings(angles, 0.1, n_pairs=3), len(angles), 0)
    assert nxt.angles_deg == pytest.approx([202.5, 225, 247.5, 270, 292.5, 315, 337.5])
    old = [*angles, 270.0]
    chosen = arc_test(old, _readings(old, 0.1, n_pairs=3), NOISE)
    nxt = _next(rounds_for(checked, chosen=chosen), old, _readings(old, 0.1, n_pairs=3),
                len(old), 0)
    assert nxt.angles_deg == pytest.approx([202.5, 225, 247.5, 292.5, 315, 337.5])


def test_a_job_whose_pairs_closed_up_after_its_first_round_still_reads_every_opposite(
        desc: RigDescription) -> None:
    """Round 0 stored with the pairs spread (9 angles, one opposite); resumed on a rig whose
    pairs now lie in one plane (check_plan lists two opposites, 180 and 270). The fill reads
    every opposite round 0 did not (counted by hand: 202.5 ... 337.5, 270 among them), so the
    full turn still holds the 16 uniform angles."""
    first = list(_auto(_spread(desc), rotations=8).angles_deg)
    assert len(first) == 9
    checked = _auto(desc, rotations=8)  # the same plan, checked on the closed-up rig
    assert len(checked.angles_deg) == 10
    values = _readings(first, 0.1, n_pairs=3)
    nxt = _next(rounds_for(checked), first, values, len(first), 0)
    assert nxt.angles_deg == pytest.approx([202.5, 225, 247.5, 270, 292.5, 315, 337.5])
    assert sorted(first + nxt.angles_deg) == pytest.approx([22.5 * j for j in range(16)])


def test_the_test_uses_every_opposite_its_first_round_read(desc: RigDescription) -> None:
    """A first round stored with two opposites (0/180 and 90/270), resumed where the check now
    lists one: both opposite pairs are tested, not only 0/180."""
    checked = _auto(_spread(desc), rotations=8)
    assert len(checked.angles_deg) == 9  # one opposite now
    stored = first_round_angles(0.0, 8, 2)
    nxt = _next(rounds_for(checked), stored, _readings(stored, 0.0, n_pairs=3), len(stored), 0)
    (kind, data), = nxt.events
    assert kind == ARC_TEST_EVENT and data["opposite_pairs"] == 2


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
    assert fill.angles_deg == pytest.approx([225.0, 315.0])
    done = angles + fill.angles_deg
    nxt = _next(asym, done, _readings(done, 0.1, n_pairs=3), len(done), 1)
    assert asym._after().arc_deg == (0.0, 360.0)
    assert nxt.angles_deg and any(a > 180 for a in nxt.angles_deg)
    assert ARC_TEST_EVENT not in [t for t, _ in nxt.events]


class _Recorder:
    """A posterior rule that records what each round asks it and plans one midpoint."""

    def __init__(self) -> None:
        self.requests: list[RoundRequest] = []

    def next_angles(self, request: RoundRequest) -> list[float]:
        self.requests.append(request)
        a = sorted(request.angles_deg)
        return [0.5 * (a[0] + a[1])]

    def describe(self) -> dict[str, Any]:
        return {"basis": self.requests[-1].basis} if self.requests else {}


def test_the_refinement_plans_with_the_basis_the_verdict_chooses(desc: RigDescription) -> None:
    """After an asymmetric verdict the posterior rule is asked for the asymmetric basis (the one
    finishing reconstructs with) over the full turn, and the round's event says which; after a
    symmetric one, for the default basis over half a turn. A resumed job given its stored test
    asks the same as the job that made it."""
    checked = _auto(desc, adaptive=True, initial_rotations=4, max_rotations=12)
    angles = list(checked.angles_deg)
    rule = _Recorder()
    asym = rounds_for(checked, rule)
    lean = _readings(angles, 0.1, n_pairs=3)
    fill = _next(asym, angles, lean, len(angles), 0)
    assert rule.requests == []  # the fill round is the arc's, not the rule's
    done = angles + fill.angles_deg
    nxt = _next(asym, done, _readings(done, 0.1, n_pairs=3), len(done), 1)
    (req,) = rule.requests
    assert req.basis == "asymmetric" and req.arc_deg == (0.0, 360.0)
    (kind, data), = nxt.events
    assert kind == "adaptive_round" and data["basis"] == "asymmetric"
    # Resumed after the fill with the stored test: the same basis, no second test.
    test = next(d for t, d in fill.events if t == ARC_TEST_EVENT)
    again = _Recorder()
    _next(rounds_for(checked, again, chosen=test), done, _readings(done, 0.1, n_pairs=3),
          len(done), 1)
    assert [r.basis for r in again.requests] == ["asymmetric"]
    # Symmetric: the default basis over half a turn.
    plain = _Recorder()
    _next(rounds_for(checked, plain), angles, _readings(angles, 0.0, n_pairs=3), len(angles), 0)
    assert [(r.basis, r.arc_deg) for r in plain.requests] == [("default", (0.0, 180.0))]
    # Fixed plans never ask for it.
    fixed = _Recorder()
    plan = check_plan(AdaptivePlan(initial_rotations=4, span_deg=360), desc)
    _next(rounds_for(plan, fixed), list(plan.angles_deg),
          _readings(list(plan.angles_deg), 0.1, n_pairs=3), 4, 0)
    assert [r.basis for r in fixed.requests] == ["default"]


def test_the_refinement_basis_follows_finishing_s_choice() -> None:
    """As :func:`gonio.finishing._basis_for_test`: the asymmetric basis only for a test that ran,
    called the specimen asymmetric, and chose the full turn."""
    assert refinement_basis(None) == "default"
    assert refinement_basis({"symmetric": True, "arc_deg": 180.0, "statistic": 3.0}) == "default"
    assert refinement_basis({"symmetric": False, "arc_deg": 360.0, "statistic": 99.0}) == \
        "asymmetric"
    # Readings that could not be tested take the full turn but keep the default basis.
    assert refinement_basis({"symmetric": False, "arc_deg": 360.0, "statistic": None}) == \
        "default"
    assert refinement_basis({"symmetric": False, "arc_deg": 180.0, "statistic": 99.0}) == \
        "default"


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
    """Counted by hand, 3 pairs, 2 lights, 0.1 s per exposure, from 0 at 30 deg/s:
    symmetric, the first round's 10 angles (0 .. 157.5 in 22.5 steps, then 180 and 270);
    asymmetric, 6 more (202.5, 225, 247.5 after coming down from 270, then 292.5 .. 337.5)."""
    d = dry_run(UniformPlan(rotations=8, arc="auto", exposure=EX), desc)
    v, a = desc.speed_dps, desc.accel_dps2
    first_motion = 7 * move_time(22.5, v, a) + move_time(22.5, v, a) + move_time(90, v, a)
    assert d.motion_s == pytest.approx(first_motion)
    assert d.estimated_s == pytest.approx(first_motion + 10 * 2 * 0.1)
    assert d.arc_branches is not None
    sym, asym = d.arc_branches
    assert (sym.arc_deg, sym.angles, sym.readings) == (180.0, 10, 30)
    assert sym.estimated_s == pytest.approx(d.estimated_s)
    assert (asym.arc_deg, asym.angles, asym.readings) == (360.0, 16, 48)
    fill_motion = move_time(270 - 202.5, v, a) + 2 * move_time(22.5, v, a) + \
        move_time(45, v, a) + 2 * move_time(22.5, v, a)
    assert asym.estimated_s == pytest.approx(d.estimated_s + fill_motion + 6 * 2 * 0.1)
    assert d.max_angles == 16 and d.max_estimated_s == pytest.approx(asym.estimated_s)
    assert dry_run(UniformPlan(exposure=EX), desc).arc_branches is None


def test_the_dry_run_bounds_both_verdicts_with_one_opposite(desc: RigDescription) -> None:
    """Counted by hand, the spread rig (3 pairs, 2 lights), 0.1 s per exposure, from 0:
    symmetric, 9 angles (0 .. 157.5, then 180: eight moves of 22.5); asymmetric, 7 more
    (202.5 .. 337.5 from 180: seven moves of 22.5), 16 in all."""
    spread = _spread(desc)
    d = dry_run(UniformPlan(rotations=8, arc="auto", exposure=EX), spread)
    v, a = spread.speed_dps, spread.accel_dps2
    assert d.motion_s == pytest.approx(8 * move_time(22.5, v, a))
    assert d.estimated_s == pytest.approx(8 * move_time(22.5, v, a) + 9 * 2 * 0.1)
    assert d.arc_branches is not None
    sym, asym = d.arc_branches
    assert (sym.arc_deg, sym.angles, sym.readings) == (180.0, 9, 27)
    assert (asym.arc_deg, asym.angles, asym.readings) == (360.0, 16, 48)
    assert asym.estimated_s == pytest.approx(
        d.estimated_s + 7 * move_time(22.5, v, a) + 7 * 2 * 0.1)
    assert d.max_angles == 16


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
    """Counted by hand, 4 first angles, max_rounds 3, no cap: symmetric, 0 45 90 135 (180 and
    270 are the same positions over half a turn) gain 4 then 8 midpoints: 6 + 4 + 8 = 18;
    asymmetric, the fill (225, 315) makes 8 over the full turn, one refinement round left
    adds 8 midpoints: 16."""
    plan = AdaptivePlan(initial_rotations=4, max_rounds=3, max_rotations=None, arc="auto",
                        exposure=EX)
    d = dry_run(plan, desc)
    assert d.angles_deg == pytest.approx([0, 45, 90, 135, 180, 270])
    assert d.arc_branches is not None
    assert [(b.arc_deg, b.angles) for b in d.arc_branches] == [(180.0, 18), (360.0, 16)]
    assert d.max_angles == 18
    assert all(b.estimated_s >= b.angles * 2 * 0.1 for b in d.arc_branches)
    assert check_plan(plan, desc).max_angles == 18
    # The bounds are branch_bounds' (what the engine's ETA uses too).
    extra = branch_bounds(plan, desc, 2, 3, d.angles_deg, d.positions_deg[-1])
    assert {k: n for k, (n, _) in extra.items()} == {180.0: 12, 360.0: 10}
