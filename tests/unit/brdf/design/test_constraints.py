"""Tests of rig constraints, exclusions and candidate filtering (gonio.brdf.design.constraints)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.design.constraints import (
    BoxExclusion,
    ConeExclusion,
    RigConstraints,
    angular_distance,
    candidate_rows,
    feasible_mask,
    parse_exclusion,
)
from gonio.brdf.design.errors import FeasibilityError
from gonio.brdf.tables import geometry as geo


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


def test_angular_distance_is_accurate_for_close_vectors() -> None:
    a = geo.spherical_to_direction(0.3, 0.1)
    b = geo.spherical_to_direction(0.3 + 1e-9, 0.1)
    assert angular_distance(a, b) == pytest.approx(1e-9, rel=1e-6)
