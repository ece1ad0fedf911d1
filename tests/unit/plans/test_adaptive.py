"""Adaptive refinement: new angles where the periodic PCHIP fails (gonio.plans.adaptive)."""

from __future__ import annotations

import numpy as np

from gonio.plans.adaptive import adaptive_refinement


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


def _half_turn_readings() -> tuple[np.ndarray, np.ndarray]:
    """Six angles over half a turn, three pairs, two channels; a highlight at 60 deg in one."""
    a = np.arange(6) * 30.0
    rng = np.random.default_rng(7)
    values = 1.0 + 0.05 * rng.standard_normal((3, 6, 2))
    values[1, 2, :] = 2.5
    return a, values


def test_the_half_turn_rule_is_the_full_turn_rule_on_repeated_readings() -> None:
    """A twofold-symmetric specimen reads at a + 180 what it reads at a. V&F's rule over half
    a turn must plan what its full-turn rule plans from the readings written out at both a and
    a + 180 (the midpoints of both copies, taken modulo 180), and only angles in the half turn."""
    a, values = _half_turn_readings()
    twice_a = np.concatenate([a, a + 180.0])
    twice_v = np.concatenate([values, values], axis=1)
    for threshold in (0.5, 0.1, 0.01):
        half = adaptive_refinement(a, values, threshold, 0.5, None, period_deg=180.0)
        full = adaptive_refinement(twice_a, twice_v, threshold, 0.5, None)
        assert half == sorted({round(x % 180.0, 6) for x in full})
        assert all(0.0 <= x < 180.0 for x in half)
    assert adaptive_refinement(a, values, 0.1, 0.5, None, period_deg=180.0)  # it does refine


def test_the_half_turn_rule_keeps_to_its_arc() -> None:
    """The same readings taken from 300 deg (arc 300..360 and 0..120): the same positions in
    the arc, so the same midpoints shifted by 300, modulo 360; none in the other half."""
    a, values = _half_turn_readings()
    here = adaptive_refinement(a, values, 0.1, 0.5, None, period_deg=180.0)
    there = adaptive_refinement((a + 300.0) % 360.0, values, 0.1, 0.5, None, period_deg=180.0,
                                start_deg=300.0)
    assert there == sorted(round((x + 300.0) % 360.0, 6) for x in here)
    assert all(not 120.0 <= x < 300.0 for x in there)
