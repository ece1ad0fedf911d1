"""Linear sRGB for exports, against the IEC 61966-2-1 matrix."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.colour.conditions import ViewingConditions
from gonio.brdf.colour.exportspace import conversion_record, xyz_to_linear_srgb

# IEC 61966-2-1: linear sRGB from XYZ (D65, 2 degree observer).
SRGB_FROM_XYZ = np.array([
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
])


def test_d65_2_degree_xyz_follows_the_srgb_standard() -> None:
    cond = ViewingConditions("D65", "2")
    xyz = np.array([[41.24, 21.26, 1.93], [20.0, 30.0, 40.0]])
    got = xyz_to_linear_srgb(xyz, cond)
    assert got == pytest.approx(xyz / 100 @ SRGB_FROM_XYZ.T, abs=2e-3)


def test_white_maps_to_white_under_each_conditions() -> None:
    for cond in (ViewingConditions(), ViewingConditions("D50", "2")):
        assert xyz_to_linear_srgb(cond.white_xyz, cond) == pytest.approx([1, 1, 1], abs=5e-3)


def test_record_states_the_conversion() -> None:
    rec = conversion_record(ViewingConditions(), "spectral bands (31)")
    assert rec["xyz_conditions"] == "D65/10" and rec["chromatic_adaptation"] == "Bradford"
    assert rec["space"].startswith("linear sRGB")
