"""Move, settle and exposure times of a plan, against hand-computed trapezoid profiles.

The rig below moves at 10 deg/s with 100 deg/s^2: a move of d >= 1 deg takes d / 10 + 0.1 s,
a shorter one 2 sqrt(d / 100) s (math.md's trapezoid and triangle).
"""

from __future__ import annotations

import pytest

from gonio.hal import PairSpec
from gonio.plans.models import AdaptivePlan, ExposureSettings, UniformPlan
from gonio.plans.timing import adaptive_bound, estimate_angles, travel
from gonio.rigdescription import LightInfo, RigDescription, SensorInfo


def rig(**kw: object) -> RigDescription:
    base: dict[str, object] = dict(
        stage_min_deg=-10.0, stage_max_deg=720.0, speed_dps=10.0, accel_dps2=100.0,
        settle_s=0.2, lights=(LightInfo(name="L1", theta_deg=30, phi_deg=0),
                              LightInfo(name="L2", theta_deg=50, phi_deg=90)),
        sensors=(SensorInfo(name="S", theta_deg=0, phi_deg=0, channels=("v",)),),
        pairs=(PairSpec(light="L1", sensor="S"), PairSpec(light="L2", sensor="S")))
    base.update(kw)
    return RigDescription.model_validate(base)


def test_straight_moves_from_below() -> None:
    motion, moves, end = travel([90.0, 180.0], 0.0, rig(), backlash_deg=0.0)
    assert motion == pytest.approx(2 * (90 / 10 + 0.1))
    assert (moves, end) == (2, 180.0)


def test_a_short_move_is_a_triangle() -> None:
    motion, _, _ = travel([0.25], 0.0, rig(), backlash_deg=0.0)
    assert motion == pytest.approx(2 * (0.25 / 100) ** 0.5)


def test_the_plan_backlash_overshoots_below_a_target_reached_from_above() -> None:
    # 0 -> 90 (9.1 s), then 90 -> 40 (5.1 s) and 40 -> 45 (0.6 s): three move_to calls
    motion, moves, end = travel([90.0, 45.0], 0.0, rig(), backlash_deg=5.0)
    assert motion == pytest.approx(9.1 + 5.1 + 0.6)
    assert (moves, end) == (3, 45.0)


def test_the_overshoot_stops_at_the_lower_travel_limit() -> None:
    # the overshoot point 40 is below the limit 42: 90 -> 42 (4.9 s), 42 -> 45 (0.4 s)
    motion, moves, _ = travel([90.0, 45.0], 0.0, rig(stage_min_deg=42.0), backlash_deg=5.0)
    assert motion == pytest.approx(9.1 + 4.9 + 0.4)
    assert moves == 3


def test_the_driver_approach_adds_legs_inside_one_move() -> None:
    # positive approach with 2 deg: 90 -> 43 (4.8 s) and 43 -> 45 (0.3 s) inside one move_to
    r = rig(approach="positive", approach_backlash_deg=2.0)
    motion, moves, _ = travel([90.0, 45.0], 0.0, r, backlash_deg=0.0)
    assert motion == pytest.approx(9.1 + 4.8 + 0.3)
    assert moves == 2


@pytest.mark.parametrize(("dark", "first_dark", "exposures"), [
    ("once", True, 3 * 2 + 1), ("once", False, 3 * 2), ("every_angle", False, 3 * 2 + 3),
    ("none", False, 3 * 2),
])
def test_estimate_counts_settles_and_exposures(dark: str, first_dark: bool,
                                               exposures: int) -> None:
    plan = UniformPlan(exposure=ExposureSettings(exposure_s=0.01, averages=3,
                                                 light_settle_s=0.05, dark=dark))
    motion, settle, exposure = estimate_angles([0.0, 90.0, 180.0], 0.0, 2, plan, rig(),
                                               first_dark)
    assert motion == pytest.approx(2 * 9.1)
    # three move_to calls (the first one to where the stage is) and 3 angles x 2 lights
    assert settle == pytest.approx(3 * 0.2 + 3 * 2 * 0.05)
    assert exposure == pytest.approx(exposures * 0.01 * 3)


FAST = ExposureSettings(exposure_s=0.01, averages=2, light_settle_s=0.05, dark="once")
PER_ANGLE = 2 * (0.05 + 0.01 * 2)  # two lights, each settled and exposed twice
QUICK = dict(speed_dps=1e6, accel_dps2=1e9, settle_s=0.0)  # motion negligible (< 2 ms)


@pytest.mark.parametrize(("kw", "angles"), [
    # every gap halved twice: 4 then 8 midpoints, within max_rotations 16
    (dict(max_rounds=3, max_rotations=16), 12),
    # the second round's room is 16 - 8 = 8 of its 8 midpoints; a third round has no room
    (dict(max_rounds=5, max_rotations=16), 12),
    # half a 45 deg gap is below min_step_deg 30: one round only
    (dict(max_rounds=5, max_rotations=64, min_step_deg=30.0), 4),
    # max_samples 18 over 3 pairs allows 6 angles: 2 more
    (dict(max_rounds=5, max_rotations=64, max_samples=18), 2),
])
def test_adaptive_bound_counts_the_midpoints_each_round_may_add(kw: dict[str, object],
                                                                angles: int) -> None:
    plan = AdaptivePlan(exposure=FAST, span_deg=360.0, min_step_deg=kw.pop("min_step_deg", 1.0),
                        **kw)  # type: ignore[arg-type]
    extra, seconds = adaptive_bound(plan, rig(**QUICK), n_pairs=3, n_lights=2,
                                    first_angles=[0.0, 90.0, 180.0, 270.0], end_deg=270.0)
    assert extra == angles
    assert seconds == pytest.approx(angles * PER_ANGLE, abs=0.05)


def test_adaptive_bound_of_a_half_turn_stays_in_it() -> None:
    """Over half a turn the last gap runs to 180: four midpoints in one round."""
    plan = AdaptivePlan(exposure=FAST, span_deg=180.0, max_rounds=2, max_rotations=64,
                        min_step_deg=1.0)
    extra, _ = adaptive_bound(plan, rig(**QUICK), 1, 2, [0.0, 45.0, 90.0, 135.0], 135.0)
    assert extra == 4


def test_adaptive_bound_time_includes_the_moves() -> None:
    """One round from 270 to the midpoints 45..315 on the slow rig: at least the turn to
    cover them (270 deg at 10 deg/s) and their settles and exposures."""
    plan = AdaptivePlan(exposure=FAST, span_deg=360.0, max_rounds=2, max_rotations=64,
                        min_step_deg=1.0)
    extra, seconds = adaptive_bound(plan, rig(), 1, 2, [0.0, 90.0, 180.0, 270.0], 270.0)
    assert extra == 4
    assert seconds >= 4 * PER_ANGLE + 4 * 0.2 + 270 / 10
