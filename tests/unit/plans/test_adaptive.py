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
