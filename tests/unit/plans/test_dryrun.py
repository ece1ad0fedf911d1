"""Dry runs: counts and times of a plan before it runs, and the bound for adaptive plans
(gonio.plans.dryrun)."""

from __future__ import annotations

import pytest

from gonio.motion import move_time
from gonio.plans.dryrun import dry_run
from gonio.plans.models import (
    AdaptivePlan,
    ExposureSettings,
    UniformPlan,
)
from gonio.rigdescription import RigDescription


def _limited(desc: RigDescription, lo: float, hi: float) -> RigDescription:
    return desc.model_copy(update={"stage_min_deg": lo, "stage_max_deg": hi})


@pytest.mark.parametrize("span", [360.0, 180.0])
def test_uniform_dry_run_counts_and_times(desc: RigDescription, span: float) -> None:
    plan = UniformPlan(rotations=6, span_deg=span,
                       exposure=ExposureSettings(exposure_s=0.1, averages=2,
                                                 light_settle_s=0.05, dark="once"))
    d = dry_run(plan, desc)
    step = span / 6
    assert d.angles_deg == pytest.approx([k * step for k in range(6)])
    assert d.readings == 3 * 6  # three pairs
    assert d.lights == ["L1", "L2"]
    assert d.exposures == 6 * 2 + 1  # one per light and angle, one dark
    assert d.exposure_s == pytest.approx(13 * 0.2)
    assert d.motion_s == pytest.approx(5 * move_time(step, 30.0, 300.0))
    assert d.estimated_s == pytest.approx(d.motion_s + d.settle_s + d.exposure_s)


def test_dry_run_counts_the_return_from_where_the_stage_is(desc: RigDescription) -> None:
    rig = _limited(desc, -360.0, 720.0)
    plan = UniformPlan(rotations=4, span_deg=360, exposure=ExposureSettings(light_settle_s=0.0))
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
    plan = UniformPlan(rotations=4, span_deg=360, backlash_deg=5.0,
                       exposure=ExposureSettings(dark="none"))
    # The engine's own overshoot: coming down from 100 to 90 it first goes to 85.
    d = dry_run(plan, desc, current_deg=100.0)
    assert d.positions_deg[0] == pytest.approx(90.0)
    assert d.motion_s == pytest.approx(move_time(15, v, a) + move_time(5, v, a)
                                       + 3 * move_time(90, v, a))
    # A driver approaching from above overshoots every upward move by its backlash.
    neg = desc.model_copy(update={"approach": "negative", "approach_backlash_deg": 2.0,
                                  "settle_s": 0.1})
    plan0 = UniformPlan(rotations=4, span_deg=360,
                        exposure=ExposureSettings(dark="none", light_settle_s=0))
    d = dry_run(plan0, neg, current_deg=-10.0)
    assert d.positions_deg == pytest.approx([0.0, 90.0, 180.0, 270.0])
    assert d.motion_s == pytest.approx(move_time(12, v, a) + move_time(2, v, a)
                                       + 3 * (move_time(92, v, a) + move_time(2, v, a)))
    assert d.settle_s == pytest.approx(4 * 0.1)  # one settle per move_to call


def test_adaptive_plans_get_a_bound(desc: RigDescription) -> None:
    plan = AdaptivePlan(initial_rotations=8, max_rounds=3, max_rotations=None, span_deg=360,
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


def test_the_bound_of_a_half_turn_adaptive_plan_halves_the_half_turns_gaps(
        desc: RigDescription) -> None:
    """Counted by hand over half a turn: 0, 45, 90, 135 have four 45 deg gaps (the last from
    135 to 180); round 1 adds 22.5, 67.5, 112.5, 157.5 (8 angles, gaps 22.5), round 2 the eight
    odd multiples of 11.25 (16). With min_step_deg 15 round 2's half gaps (11.25) are too
    small: 8 angles. (Halving modulo 360 would leave a 225 deg gap and, with min_step_deg 15,
    count 10.)"""
    ex = ExposureSettings(exposure_s=0.1, light_settle_s=0.0, dark="none")
    plan = AdaptivePlan(initial_rotations=4, max_rounds=3, max_rotations=None, exposure=ex)
    assert plan.span_deg == 180.0
    d = dry_run(plan, desc)
    assert d.angles_deg == pytest.approx([0.0, 45.0, 90.0, 135.0])
    assert d.max_angles == 16
    assert d.max_estimated_s is not None and d.max_estimated_s >= 16 * 2 * 0.1
    assert dry_run(plan.model_copy(update={"min_step_deg": 15.0}), desc).max_angles == 8
    # From 30 deg (the arc 30..210) the same count.
    assert dry_run(plan.model_copy(update={"start_deg": 30.0, "min_step_deg": 15.0}),
                   desc).max_angles == 8


def test_the_bound_of_a_default_adaptive_plan_is_its_cap(desc: RigDescription) -> None:
    """The posterior rule stops at max_rotations (default 16): from 4 angles the bound is 16,
    not the 4 x 2^5 = 128 of six uncapped rounds; the cap binds in the time bound too."""
    ex = ExposureSettings(exposure_s=0.1, light_settle_s=0.0, dark="none")
    d = dry_run(AdaptivePlan(exposure=ex), desc)
    assert (len(d.angles_deg), d.max_angles) == (4, 16)
    uncapped = dry_run(AdaptivePlan(exposure=ex, max_rotations=None), desc)
    assert uncapped.max_angles == 4 * 2**5
    assert d.max_estimated_s is not None and uncapped.max_estimated_s is not None
    # 12 more angles of two lights' exposures at most (plus moves), far below 124 more.
    assert d.max_estimated_s >= 16 * 2 * 0.1
    assert d.max_estimated_s < uncapped.max_estimated_s - 100 * 2 * 0.1
    # A cap that is not a doubling stops mid-round: 4 + 4 + 2.
    assert dry_run(AdaptivePlan(exposure=ex, max_rotations=10), desc).max_angles == 10
    # V&F's rule keeps its uncapped default: 8 angles doubled in each of 5 rounds.
    assert dry_run(AdaptivePlan(exposure=ex, rule="vf"), desc).max_angles == 8 * 2**5


def test_a_cap_below_the_first_round_is_refused(desc: RigDescription) -> None:
    from gonio.plans.models import PlanError

    with pytest.raises(PlanError, match="max_rotations 6 is fewer than the first round's 8"):
        dry_run(AdaptivePlan(initial_rotations=8, max_rotations=6), desc)
