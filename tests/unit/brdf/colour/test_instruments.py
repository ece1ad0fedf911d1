"""Instrument aspecular geometries against the design presets (V&F Table 1)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.colour.conditions import ColourError
from gonio.brdf.colour.instruments import INSTRUMENTS, Geometry, canonical_instrument, geometries
from gonio.brdf.design.presets import get_preset


@pytest.mark.parametrize("name", list(INSTRUMENTS))
def test_instrument_geometries_are_the_presets_in_plane_pairs(name: str) -> None:
    preset = get_preset(name).lab_deg
    in_plane = preset[np.isin(preset[:, 3], (0.0, 180.0))]
    wanted = set()
    for ti, _, tv, pv in in_plane:
        signed = tv if pv == 180.0 else -tv  # elevation on the specular side
        wanted.add((float(ti), float(ti - signed)))
    assert set(INSTRUMENTS[name]) == wanted


def test_ma98_and_bykmac_hold_the_issue_angles() -> None:
    for name in ("MA98", "BYK-mac"):
        at45 = {a for i, a in INSTRUMENTS[name] if i == 45}
        assert at45 == {-15, 15, 25, 45, 75, 110}


def test_directions_place_the_sensor_by_aspecular_angle() -> None:
    light, view = Geometry("x", 45, 0).directions()
    specular = np.array([-light[0], -light[1], light[2]])
    assert view == pytest.approx(specular)
    for a in (-15.0, 25.0, 110.0):
        light, view = Geometry("x", 45, a, azimuth_deg=30).directions()
        spec = np.array([-light[0], -light[1], light[2]])
        assert np.degrees(np.arccos(np.clip(view @ spec, -1, 1))) == pytest.approx(abs(a))
        # Positive angles turn from the specular direction toward the light.
        assert (view @ light > spec @ light) == (a > 0)
        assert np.linalg.norm(view) == pytest.approx(1.0)


def test_geometries_and_names() -> None:
    g = geometries(["ma 98", "MA98"], [0, 90])
    assert len(g) == 2 * 11 and g[11].azimuth_deg == 90
    # An azimuth given twice is one (its rows were repeated: the CSV, kept as a standard,
    # then held two rows per geometry), as an instrument given twice is.
    again = geometries(["MA98"], [0, 90, 0.0, 90])
    assert again == g and len(set(again)) == len(again)
    assert canonical_instrument("byk mac") == "BYK-mac"
    assert g[0].name == "45as-15"
    with pytest.raises(ColourError, match="known instruments are MA68"):
        geometries(["MA99"])
    with pytest.raises(ColourError, match="at least one"):
        geometries([])
