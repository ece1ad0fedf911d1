"""The drivers' checks of approach settings and of targets with their overshoot
(gonio.drivers._stage_settings)."""

from __future__ import annotations

import pytest

from gonio.drivers._stage_settings import check_approach, check_target
from gonio.hal import TravelLimits
from gonio.motion import approach_waypoints


def test_approach_settings_are_validated_with_clear_messages() -> None:
    with pytest.raises(ValueError, match="approach must be one of positive, negative, none"):
        check_approach("stage", "upwards", 0.5)
    with pytest.raises(ValueError, match="backlash_deg must be a number >= 0"):
        check_approach("stage", "positive", -1.0)


def test_overshoot_beyond_travel_limit_is_refused_before_moving() -> None:
    limits = TravelLimits(0.0, 180.0)
    with pytest.raises(ValueError, match=r"outside the travel limits \[0, 180\]"):
        check_target("stage", limits, 200.0, [200.0])
    with pytest.raises(ValueError, match=r"needs an overshoot to -0\.5 deg"):
        check_target("stage", limits, 0.0, approach_waypoints(10.0, 0.0, "positive", 0.5))
