"""The move-completion poll schedule shared by the stage drivers (gonio.drivers._arrival)."""

from __future__ import annotations

import math

import pytest

from gonio.drivers._arrival import FINE_POLL_S, poll_delay
from gonio.motion import move_time


def test_trapezoid_and_triangle_durations() -> None:
    # 60 deg/s, 240 deg/s^2: ramps take 0.25 s and 7.5 deg each, so 45 deg cruises 30 deg.
    assert move_time(45.0, 60.0, 240.0) == pytest.approx(0.25 + 0.5 + 0.25)
    assert move_time(-45.0, 60.0, 240.0) == move_time(45.0, 60.0, 240.0)
    # Too short to reach full speed: accelerate over half, brake over the other half.
    assert move_time(6.0, 60.0, 240.0) == pytest.approx(2.0 * math.sqrt(3.0 / 120.0))
    assert move_time(0.0, 60.0, 240.0) == 0.0
    # Both formulas agree where the profile just reaches full speed (15 deg here).
    assert move_time(15.0, 60.0, 240.0) == pytest.approx(2.0 * math.sqrt(15.0 / 240.0))


def test_poll_delay_is_coarse_then_exact_then_fine() -> None:
    end = 10.0
    assert poll_delay(9.0, end, 0.02) == 0.02  # well before the end
    assert poll_delay(9.99, end, 0.02) == pytest.approx(0.01)  # wake at the predicted end
    assert poll_delay(10.0, end, 0.02) == FINE_POLL_S
    assert poll_delay(10.5, end, 0.02) == FINE_POLL_S  # slower than predicted: keep fine
    assert poll_delay(9.0, None, 0.02) == 0.02  # no prediction (homing)
    assert poll_delay(9.0, end, 0.001) == 0.001  # a coarse interval below fine wins
