"""Plan validation, ordering, timing and adaptive refinement (no hardware)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gonio.hal import PairSpec
from gonio.motion import move_time
from gonio.plans.adaptive import adaptive_refinement
from gonio.plans.dryrun import dry_run
from gonio.plans.models import (
    MAX_ROTATIONS,
    AdaptivePlan,
    CalibrationPlan,
    ExposureSettings,
    PlanError,
    UniformPlan,
    parse_plan,
)
from gonio.plans.route import order_for_travel
from gonio.plans.validation import validate_plan
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig


@pytest.fixture
def desc() -> RigDescription:
    return RigDescription.from_rig(MemRig(speed_dps=30.0))


def _limited(desc: RigDescription, lo: float, hi: float) -> RigDescription:
    return desc.model_copy(update={"stage_min_deg": lo, "stage_max_deg": hi})


def test_uniform_dry_run_counts_and_times(desc: RigDescription) -> None:
    plan = UniformPlan(rotations=6, exposure=ExposureSettings(exposure_s=0.1, averages=2,
                                                              light_settle_s=0.05, dark="once"))
    d = dry_run(plan, desc)
    assert d.angles_deg == [0, 60, 120, 180, 240, 300]
    assert d.readings == 3 * 6  # three pairs
    assert d.lights == ["L1", "L2"]
    assert d.exposures == 6 * 2 + 1  # one per light and angle, one dark
    assert d.exposure_s == pytest.approx(13 * 0.2)
    assert d.motion_s == pytest.approx(5 * move_time(60, 30.0, 300.0))
    assert d.estimated_s == pytest.approx(d.motion_s + d.settle_s + d.exposure_s)


def test_move_time_trapezoid_and_triangle() -> None:
    assert move_time(90, 30, 60) == pytest.approx(90 / 30 + 30 / 60)
    assert move_time(1, 30, 60) == pytest.approx(2 * math.sqrt(1 / 60))
    assert move_time(0, 30, 60) == 0


@pytest.mark.parametrize(
    ("plan", "match"),
    [
        (UniformPlan(rotations=0), "at least one stage angle"),
        (UniformPlan(rotations=100000), "duplicate angles"),
        (UniformPlan(pairs=[]), "no pairs"),
        (UniformPlan(pairs=[PairSpec(light="L2", sensor="S2")]), "not one of the rig's pairs"),
        (UniformPlan(pairs=[PairSpec(light="L1", sensor="S1")] * 2), "listed twice"),
        (UniformPlan(exposure=ExposureSettings(exposure_s=20.0)), "outside sensor"),
        (AdaptivePlan(initial_rotations=2), "at least 3"),
        (AdaptivePlan(max_samples=5), "smaller than the first round"),
        (AdaptivePlan(min_step_deg=0.001), "finer than the stage resolution"),
    ],
)
def test_bad_plans_refused(desc: RigDescription, plan: object, match: str) -> None:
    with pytest.raises(PlanError, match=match):
        validate_plan(plan, desc)  # type: ignore[arg-type]


def test_angles_beyond_travel_refused(desc: RigDescription) -> None:
    small = _limited(desc, 0.0, 180.0)
    with pytest.raises(PlanError, match=r"outside the stage travel \[0, 180\]"):
        validate_plan(UniformPlan(rotations=4), small)
    validate_plan(UniformPlan(rotations=1, start_deg=90), small)


def test_parse_plan_messages() -> None:
    with pytest.raises(PlanError, match="kind"):
        parse_plan({"kind": "spiral"})
    with pytest.raises(PlanError, match="exposure_s"):
        parse_plan('{"kind": "uniform", "exposure": {"exposure_s": -1}}')
    p = parse_plan({"kind": "calibration", "reference_albedo": 0.99})
    assert isinstance(p, CalibrationPlan)
    assert parse_plan(p.model_dump_json()) == p


def test_order_is_increasing_and_starts_near_the_stage(desc: RigDescription) -> None:
    angles = [0, 90, 180, 270]
    route = order_for_travel(angles, 100.0, desc)
    assert all(b > a for a, b in itertools.pairwise(route))
    # Back 10 deg to 90, then up to 360 (280 deg) beats 180 -> 450 (350 deg).
    assert route == pytest.approx([90.0, 180.0, 270.0, 360.0])
    # From 175 the route starting ahead at 180 is shorter.
    assert order_for_travel(angles, 175.0, desc)[0] == pytest.approx(180.0)
    assert sorted(a % 360 for a in route) == angles
    # A stage that cannot pass 360 must go back to the lowest angle first.
    route = order_for_travel(angles, 100.0, _limited(desc, 0.0, 300.0))
    assert route == [0, 90, 180, 270]


def test_adaptive_refines_where_pchip_fails() -> None:
    a = np.arange(8) * 45.0
    smooth = 1 + 0.1 * np.cos(np.deg2rad(a))
    values = np.stack([smooth, smooth], axis=0)[:, :, None]
    assert adaptive_refinement(a, values, 0.1, 0.5, None) == []
    spiky = smooth.copy()
    spiky[2] = 3.0  # a narrow highlight at 90 deg
    values = np.stack([smooth, spiky], axis=0)[:, :, None]
    new = adaptive_refinement(a, values, 0.1, 0.5, None)
    assert 67.5 in new and 112.5 in new
    assert all(x not in a for x in new)
    assert len(adaptive_refinement(a, values, 0.1, 0.5, 1)) == 1
    assert adaptive_refinement(a, values, 0.1, 30.0, None) == []  # min step stops refinement


# --------------------------------------------------------------------------- honest time
def _brute_force_route(angles: list[float], current: float, rig: RigDescription,
                       backlash: float) -> list[float]:
    """The documented rule, written out the slow way: build every cyclic route from every
    stage position of its first angle, keep those inside the limits, pick the least travel."""
    base = sorted({round(a % 360.0, 9) for a in angles})
    best: tuple[float, list[float]] | None = None
    for s in range(len(base)):
        cyc = base[s:] + base[:s]
        for m in range(-5, 6):
            first = cyc[0] + 360.0 * m
            if not rig.stage_min_deg - 1e-9 <= first <= rig.stage_max_deg + 1e-9:
                continue
            if abs(first - current) > 720.0 + backlash:
                continue
            route = [first]
            for a in cyc[1:]:
                route.append(route[-1] + (a - route[-1]) % 360.0)
            if route[-1] > rig.stage_max_deg + 1e-9:
                continue
            if current <= first:
                cost = route[-1] - current
            else:
                pre = max(rig.stage_min_deg, first - backlash)
                cost = (current - pre) + (route[-1] - pre)
            if best is None or cost < best[0] - 1e-9:
                best = (cost, route)
    assert best is not None
    return best[1]


def test_linear_ordering_matches_the_brute_force_rule(desc: RigDescription) -> None:
    rng = np.random.default_rng(7)
    for trial in range(200):
        lo, hi = [(-360.0, 720.0), (0.0, 360.0), (-180.0, 540.0), (0.0, 300.0)][trial % 4]
        rig = _limited(desc, lo, hi)
        n = int(rng.integers(1, 12))
        angles = list(rng.uniform(0, 300 if hi == 300 else 360, n).round(2))
        current = float(rng.uniform(lo, hi))
        backlash = float(rng.choice([0.0, 2.0]))
        got = order_for_travel(angles, current, rig, backlash)
        assert got == pytest.approx(_brute_force_route(angles, current, rig, backlash))


def test_rotation_cap_is_a_clear_error(desc: RigDescription) -> None:
    validate_plan(UniformPlan(rotations=MAX_ROTATIONS), desc)
    with pytest.raises(PlanError, match=f"at most {MAX_ROTATIONS} stage angles"):
        validate_plan(UniformPlan(rotations=MAX_ROTATIONS + 1), desc)
    with pytest.raises(PlanError, match=r"initial_rotations .* at most"):
        validate_plan(AdaptivePlan(initial_rotations=5000), desc)
    # The largest plan is still checked and timed (linear ordering): every angle visited once.
    d = dry_run(UniformPlan(rotations=MAX_ROTATIONS), desc)
    assert len(d.positions_deg) == MAX_ROTATIONS


def test_dry_run_counts_the_return_from_where_the_stage_is(desc: RigDescription) -> None:
    rig = _limited(desc, -360.0, 720.0)
    plan = UniformPlan(rotations=4, exposure=ExposureSettings(light_settle_s=0.0))
    from_zero = dry_run(plan, rig)
    assert not from_zero.from_known and from_zero.from_deg == 0.0
    parked = dry_run(plan, rig, current_deg=700.0)
    assert parked.from_known
    # From 700 the stage cannot go on past 720: back down to 450 (250 deg), then 3 x 90 deg.
    assert parked.positions_deg == pytest.approx([450.0, 540.0, 630.0, 720.0])
    v, a = rig.speed_dps, rig.accel_dps2
    assert parked.motion_s == pytest.approx(move_time(250, v, a) + 3 * move_time(90, v, a))
    assert parked.estimated_s > from_zero.estimated_s


def test_dry_run_counts_backlash_approaches(desc: RigDescription) -> None:
    v, a = desc.speed_dps, desc.accel_dps2
    plan = UniformPlan(rotations=4, backlash_deg=5.0, exposure=ExposureSettings(dark="none"))
    # The engine's own overshoot: coming down from 100 to 90 it first goes to 85.
    d = dry_run(plan, desc, current_deg=100.0)
    assert d.positions_deg[0] == pytest.approx(90.0)
    assert d.motion_s == pytest.approx(move_time(15, v, a) + move_time(5, v, a)
                                       + 3 * move_time(90, v, a))
    # A driver approaching from above overshoots every upward move by its backlash.
    neg = desc.model_copy(update={"approach": "negative", "approach_backlash_deg": 2.0,
                                  "settle_s": 0.1})
    plan0 = UniformPlan(rotations=4, exposure=ExposureSettings(dark="none", light_settle_s=0))
    d = dry_run(plan0, neg, current_deg=-10.0)
    assert d.positions_deg == pytest.approx([0.0, 90.0, 180.0, 270.0])
    assert d.motion_s == pytest.approx(move_time(12, v, a) + move_time(2, v, a)
                                       + 3 * (move_time(92, v, a) + move_time(2, v, a)))
    assert d.settle_s == pytest.approx(4 * 0.1)  # one settle per move_to call


def test_adaptive_plans_get_a_bound(desc: RigDescription) -> None:
    plan = AdaptivePlan(initial_rotations=8, max_rounds=3,
                        exposure=ExposureSettings(exposure_s=0.1, light_settle_s=0.0,
                                                  dark="none"))
    d = dry_run(plan, desc)
    # Worst case: every gap halved in each of the two refinement rounds: 8 + 8 + 16 angles.
    assert d.max_angles == 32
    assert d.max_estimated_s is not None
    # At least the exposures of 32 angles (two lights each), and more than the first round.
    assert d.max_estimated_s >= 32 * 2 * 0.1 and d.max_estimated_s > d.estimated_s
    # A budget of 3 pairs x 12 angles stops after 4 more angles; a coarse min step sooner.
    assert dry_run(plan.model_copy(update={"max_samples": 36}), desc).max_angles == 12
    assert dry_run(plan.model_copy(update={"min_step_deg": 20.0}), desc).max_angles == 16
    assert dry_run(UniformPlan(), desc).max_estimated_s is None
