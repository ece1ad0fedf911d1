"""Stage motion rules shared by plans, engine and drivers (gonio.motion)."""

from __future__ import annotations

import math

import pytest

from gonio.motion import approach_waypoints, move_time, plan_overshoot_legs


def test_move_time_trapezoid_and_triangle() -> None:
    assert move_time(90, 30, 60) == pytest.approx(90 / 30 + 30 / 60)
    assert move_time(1, 30, 60) == pytest.approx(2 * math.sqrt(1 / 60))
    assert move_time(0, 30, 60) == 0


@pytest.mark.parametrize(
    ("current", "target", "approach", "expected"),
    [
        (0.0, 10.0, "positive", [10.0]),
        (20.0, 10.0, "positive", [9.0, 10.0]),
        (0.0, 10.0, "negative", [11.0, 10.0]),
        (20.0, 10.0, "negative", [10.0]),
        (20.0, 10.0, "none", [10.0]),
        (10.0, 10.0, "positive", [10.0]),
    ],
)
def test_targets_are_approached_from_the_configured_side(
    current: float, target: float, approach: str, expected: list[float]
) -> None:
    assert approach_waypoints(current, target, approach, 1.0) == expected


@pytest.mark.parametrize(
    ("current", "target", "backlash", "expected"),
    [
        (50.0, 10.0, 2.0, [8.0, 10.0]),  # from above: overshoot below, then up to the target
        (0.0, 10.0, 2.0, [10.0]),  # from below: already the positive side
        (50.0, 1.0, 2.0, [0.0, 1.0]),  # the overshoot stops at the lower limit (0 here)
        (50.0, 10.0, 0.0, [10.0]),  # no plan backlash: straight there
    ],
)
def test_plan_overshoot_goes_below_a_target_approached_from_above(
    current: float, target: float, backlash: float, expected: list[float]
) -> None:
    assert plan_overshoot_legs(current, target, backlash, min_deg=0.0) == expected


def test_trapezoid_and_triangle_durations() -> None:
    # 60 deg/s, 240 deg/s^2: ramps take 0.25 s and 7.5 deg each, so 45 deg cruises 30 deg.
    assert move_time(45.0, 60.0, 240.0) == pytest.approx(0.25 + 0.5 + 0.25)
    assert move_time(-45.0, 60.0, 240.0) == move_time(45.0, 60.0, 240.0)
    # Too short to reach full speed: accelerate over half, brake over the other half.
    assert move_time(6.0, 60.0, 240.0) == pytest.approx(2.0 * math.sqrt(3.0 / 120.0))
    assert move_time(0.0, 60.0, 240.0) == 0.0
    # Both formulas agree where the profile just reaches full speed (15 deg here).
    assert move_time(15.0, 60.0, 240.0) == pytest.approx(2.0 * math.sqrt(15.0 / 240.0))
