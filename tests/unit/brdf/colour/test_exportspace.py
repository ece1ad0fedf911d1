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


def test_linear_srgb_table_of_a_spectral_lambertian() -> None:
    import warnings

    from gonio.brdf.colour.exportspace import linear_srgb_table
    from gonio.brdf.colour.spectral import SpectralBands
    from gonio.brdf.tables.table import from_function

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour

    wl = np.arange(400.0, 701.0, 10.0)
    spectrum = 0.1 + 0.6 * (wl > 560)
    table = from_function(lambda i, o: np.tile(spectrum / np.pi, (i.shape[0], 1)),
                          [f"{w:g}" for w in wl], "orange", dtype=np.float32)
    bands = SpectralBands(tuple(wl), tuple(np.full(wl.size, 1.0)))
    cond = ViewingConditions()
    out = linear_srgb_table(table, bands, cond, "spectral bands (31)")
    assert out.channels == ("R", "G", "B")
    assert out.provenance["colour_space"]["clamped_at_zero"] is True
    # Independently: colour-science's XYZ of the spectrum, then its sRGB transform.
    sd = colour.SpectralDistribution(spectrum, wl)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xyz = colour.sd_to_XYZ(sd, colour.MSDS_CMFS[cond.observer_name],
                               colour.SDS_ILLUMINANTS["D65"], method="ASTM E308") / 100
        rgb = colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], cond.white_xy,
                                "Bradford", apply_cctf_encoding=False)
    expected = np.maximum(rgb, 0) / np.pi
    cell = np.asarray(out.values)[:, 0, 3, 3, 3]
    assert cell == pytest.approx(expected, rel=0.02, abs=2e-3)
