"""Tests of rig constraints, candidate filtering and lab placement of pairs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf import geometry as geo
from gonio.brdf.feasibility import (
    BoxExclusion,
    ConeExclusion,
    FeasibilityError,
    RigConstraints,
    angular_distance,
    candidate_rows,
    check_devices,
    feasible_mask,
    min_pairwise_distance,
    parse_exclusion,
    place_pairs,
    rows_to_cells,
)


def _cell_elevations(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    th, td, pd = (a[mask] for a in geo.grid_angles())
    ci, co = geo.cell_cosines(th, td, pd)
    return np.rad2deg(np.arccos(ci)), np.rad2deg(np.arccos(co))


def test_feasible_cells_respect_elevation_and_separation() -> None:
    c = RigConstraints(max_elevation_deg=60.0, min_separation_deg=20.0, min_device_distance_deg=0)
    mask = feasible_mask(c)
    ti, to = _cell_elevations(mask)
    assert ti.max() <= 60.0 + 1e-6 and to.max() <= 60.0 + 1e-6
    td = geo.grid_angles()[1][mask]
    assert np.rad2deg(2 * td).min() >= 20.0 - 1e-9
    # Nothing the limits allow is thrown away: cells just inside the limits stay.
    loose = feasible_mask(RigConstraints(max_elevation_deg=89.0, min_separation_deg=0,
                                         min_device_distance_deg=0))
    assert mask.sum() < loose.sum() <= geo.valid_mask().sum()
    assert not (mask & ~loose).any()


def test_cone_exclusion_removes_cells_that_cannot_avoid_it() -> None:
    # A 30 deg cone around the normal: a pair with th = 0 and small td has both devices
    # near the normal at every azimuth, so it must go; far cells stay.
    c = RigConstraints(min_separation_deg=0, min_device_distance_deg=0,
                       exclusions=(ConeExclusion(0.0, 0.0, 30.0),))
    mask = feasible_mask(c)
    assert not mask[0, 1, 0]  # th = 0, td = 5: both devices 5 deg from the normal
    ti, to = _cell_elevations(mask)
    assert ti.min() > 30.0 - 1e-6 and to.min() > 30.0 - 1e-6


def test_box_exclusion_wraps_in_azimuth() -> None:
    box = BoxExclusion(0.0, 90.0, 350.0, 10.0)
    dirs = geo.spherical_to_direction(np.deg2rad([45, 45, 45]), np.deg2rad([355, 5, 180]))
    assert box.contains(dirs).tolist() == [True, True, False]


def test_candidates_follow_the_basis_valid_mask() -> None:
    valid = geo.valid_mask().copy()
    valid[:, :, 1::2] = False
    rows = candidate_rows(RigConstraints(), valid.ravel())
    assert valid.ravel()[rows].all()


def test_no_feasible_cell_is_a_clear_error() -> None:
    c = RigConstraints(max_elevation_deg=5.0, min_separation_deg=30.0)
    with pytest.raises(FeasibilityError, match="no grid cell is feasible"):
        candidate_rows(c)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_elevation_deg": 95.0}, "max elevation"),
        ({"min_separation_deg": -1.0}, "min separation"),
        ({"min_device_distance_deg": 200.0}, "min device distance"),
    ],
)
def test_bad_constraints_are_refused(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(FeasibilityError, match=match):
        RigConstraints(**kwargs)  # type: ignore[arg-type]


def test_parse_exclusion_forms_and_errors() -> None:
    assert parse_exclusion("cone:10,90,5") == ConeExclusion(10.0, 90.0, 5.0)
    assert parse_exclusion("box:60,90,80,100") == BoxExclusion(60.0, 90.0, 80.0, 100.0)
    for bad in ("cone:1,2", "ring:1,2,3", "box:a,b,c,d", "cone"):
        with pytest.raises(FeasibilityError, match="cone:THETA,PHI,RADIUS"):
            parse_exclusion(bad)
    with pytest.raises(FeasibilityError, match="radius"):
        parse_exclusion("cone:0,0,0")


def test_placement_reproduces_cells_and_keeps_devices_apart() -> None:
    rng = np.random.default_rng(4)
    c = RigConstraints(min_device_distance_deg=12.0)
    rows = rng.choice(candidate_rows(c), 8, replace=False)
    cells = rows_to_cells(rows)
    p = place_pairs(cells, c)
    lab = np.deg2rad(p.lab_deg)
    wi = geo.spherical_to_direction(lab[:, 0], lab[:, 1])
    wo = geo.spherical_to_direction(lab[:, 2], lab[:, 3])
    th, _, td, pd = geo.directions_to_half_diff(wi, wo)
    np.testing.assert_allclose(th, cells[:, 0], atol=1e-9)
    np.testing.assert_allclose(td, cells[:, 1], atol=1e-9)
    # pd is only defined mod pi (reciprocity); compare on the circle of period pi. At th = 0
    # the half vector is the normal, ph is undefined and the inverse map puts the azimuth
    # into pd, so only th > 0 cells keep their pd.
    tilted = cells[:, 0] > 0
    np.testing.assert_allclose(np.sin(2 * (pd - cells[:, 2]))[tilted], 0.0, atol=1e-9)
    dmin = math.degrees(min_pairwise_distance(np.concatenate([wi, wo])))
    assert dmin >= 12.0 - 1e-6
    assert p.min_distance_deg == pytest.approx(dmin)
    assert (lab[:, [0, 2]] <= np.deg2rad(80.0) + 1e-9).all()


def test_placement_avoids_exclusions() -> None:
    ex = BoxExclusion(0.0, 90.0, 0.0, 180.0)  # half of the lab is taken by an arm
    c = RigConstraints(min_device_distance_deg=5.0, exclusions=(ex,))
    rows = np.random.default_rng(1).choice(candidate_rows(c), 4, replace=False)
    p = place_pairs(rows_to_cells(rows), c)
    lab = np.deg2rad(p.lab_deg)
    for cols in ((0, 1), (2, 3)):
        dirs = geo.spherical_to_direction(lab[:, cols[0]], lab[:, cols[1]])
        assert not ex.contains(dirs).any()


def test_placement_errors() -> None:
    c = RigConstraints(min_device_distance_deg=10.0)
    with pytest.raises(FeasibilityError, match="at least one pair"):
        place_pairs(np.zeros((0, 3)), c)
    # Forty pairs sharing one cell cannot all be 60 deg apart.
    cell = rows_to_cells(candidate_rows(c)[:1])
    crowd = RigConstraints(min_device_distance_deg=60.0, min_separation_deg=0.0)
    with pytest.raises(FeasibilityError, match="cannot mount 40 pairs"):
        place_pairs(np.repeat(np.deg2rad([[30.0, 40.0, 0.0]]), 40, axis=0), crowd, orderings=2)
    # A cell whose light and sensor are closer than the limit.
    with pytest.raises(FeasibilityError, match="apart, below the"):
        place_pairs(np.deg2rad([[20.0, 2.0, 0.0]]), c)
    assert cell.shape == (1, 3)


def test_check_devices_reports_each_violation() -> None:
    c = RigConstraints(max_elevation_deg=70.0, min_separation_deg=15.0,
                       min_device_distance_deg=10.0)
    lights = geo.spherical_to_direction(np.deg2rad([30.0, 80.0]), np.deg2rad([0.0, 90.0]))
    sensors = geo.spherical_to_direction(np.deg2rad([35.0]), np.deg2rad([0.0]))
    problems = check_devices(lights, sensors, c)
    assert any("light 1" in p for p in problems)
    assert any("a light and a sensor are 5.0 deg apart" in p for p in problems)
    assert any("two devices are 5.0 deg apart" in p for p in problems)
    ok = check_devices(lights[:1], geo.spherical_to_direction(np.deg2rad([30.0]), np.pi), c)
    assert ok == []


def test_angular_distance_is_accurate_for_close_vectors() -> None:
    a = geo.spherical_to_direction(0.3, 0.1)
    b = geo.spherical_to_direction(0.3 + 1e-9, 0.1)
    assert angular_distance(a, b) == pytest.approx(1e-9, rel=1e-6)
