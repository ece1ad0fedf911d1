"""Angles within a scan's arc: positions, gaps and the arc's stage angles
(gonio.brdf.reconstruction.periodic.arc_gaps / arc_angle)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.reconstruction.periodic import arc_angle, arc_gaps


def test_half_turn_gaps_close_at_the_first_angle_plus_180() -> None:
    pos, gaps = arc_gaps([135.0, 0.0, 90.0, 45.0], 180.0)
    np.testing.assert_allclose(pos, [0.0, 45.0, 90.0, 135.0])
    np.testing.assert_allclose(gaps, [45.0, 45.0, 45.0, 45.0])
    # Over a full turn the same angles leave the 225 degree gap back to 360.
    np.testing.assert_allclose(arc_gaps([135.0, 0.0, 90.0, 45.0], 360.0)[1],
                               [45.0, 45.0, 45.0, 225.0])


def test_angles_half_a_turn_apart_are_one_position() -> None:
    pos, gaps = arc_gaps([10.0, 190.0, 370.0 - 1e-12], 180.0)
    np.testing.assert_allclose(pos, [10.0])
    np.testing.assert_allclose(gaps, [180.0])
    assert arc_gaps([], 180.0)[0].size == 0


def test_an_arc_from_300_wraps_through_zero() -> None:
    """The arc [300, 480): positions from 300, stage angles back in [0, 360)."""
    pos, gaps = arc_gaps([300.0, 345.0, 30.0, 75.0], 180.0, start_deg=300.0)
    np.testing.assert_allclose(pos, [0.0, 45.0, 90.0, 135.0])
    np.testing.assert_allclose(gaps, [45.0] * 4)
    mids = arc_angle(pos + gaps / 2, 180.0, start_deg=300.0)
    np.testing.assert_allclose(mids, [322.5, 7.5, 52.5, 97.5])


def test_a_period_outside_one_turn_is_refused() -> None:
    with pytest.raises(ValueError, match="period_deg"):
        arc_gaps([0.0], 0.0)
    with pytest.raises(ValueError, match="period_deg"):
        arc_gaps([0.0], 720.0)
