"""Tests of the industrial geometries of V&F Table 1."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.design.presets import UnknownPresetError, get_preset, preset_names
from gonio.brdf.tables import geometry as geo


@pytest.mark.parametrize(("name", "count"), [("MA68", 5), ("MA98", 19), ("BYK-mac", 6),
                                             ("MultiFX10", 10)])
def test_pair_counts_match_table_1(name: str, count: int) -> None:
    p = get_preset(name)
    assert p.name == name and p.n_pairs == count
    assert p.lab_deg.shape == (count, 4)


@pytest.mark.parametrize("name", ["MA68", "MA98", "BYK-mac", "MultiFX10"])
def test_preset_cells_are_valid_and_reproduce_the_directions(name: str) -> None:
    p = get_preset(name)
    cells, ph = p.cells()
    th, td, pd = cells.T
    assert (th >= 0).all() and (th < np.pi / 2).all()
    assert (td >= 0).all() and (td < np.pi / 2).all()
    assert (pd >= 0).all() and (pd < np.pi).all()
    ci, co = geo.cell_cosines(th, td, pd)
    assert (ci > 0).all() and (co > 0).all()
    # Forward map back to directions: the same two devices (light and sensor may swap,
    # which reciprocity allows: pd is folded mod pi).
    wi, wo = p.directions()
    a, b = geo.half_diff_to_directions(th, ph, td, pd)
    same = np.minimum(np.abs(a - wi).max(axis=1) + np.abs(b - wo).max(axis=1),
                      np.abs(a - wo).max(axis=1) + np.abs(b - wi).max(axis=1))
    assert same.max() < 1e-9


def test_first_five_pairs_are_shared_by_all_devices() -> None:
    core = get_preset("MA68").lab_deg
    for name in preset_names():
        np.testing.assert_array_equal(get_preset(name).lab_deg[:5], core)


def test_mirror_geometry_has_th_zero() -> None:
    # 45/0 light with the sensor at 45 deg on the other side would be specular; the
    # 45 deg light with a normal sensor has its half vector at 22.5 deg.
    cells, _ = get_preset("MA68").cells()
    assert np.rad2deg(cells[0, 0]) == pytest.approx(22.5)
    assert np.rad2deg(cells[0, 1]) == pytest.approx(22.5)


def test_names_are_forgiving_and_unknown_names_list_the_known_ones() -> None:
    assert get_preset("byk mac").name == "BYK-mac"
    assert get_preset("multi fx10").name == "MultiFX10"
    with pytest.raises(UnknownPresetError, match="MA68, MA98, BYK-mac, MultiFX10"):
        get_preset("MA99")
