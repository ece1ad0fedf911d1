"""Tests of lab placement of pairs and the device check (gonio.brdf.design.placement)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.design.constraints import (
    BoxExclusion,
    RigConstraints,
    candidate_rows,
    min_pairwise_distance,
    rows_to_cells,
)
from gonio.brdf.design.errors import FeasibilityError
from gonio.brdf.design.mounting import MountPlanner
from gonio.brdf.design.placement import check_devices, place_pairs
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.design.test_mounting import _all_pairwise_deg


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


def test_placement_starts_from_a_given_feasible_placement() -> None:
    c = RigConstraints(min_device_distance_deg=12.0)
    planner = MountPlanner(c)
    got = planner.start(np.random.default_rng(3), candidate_rows(c), 12)
    assert got is not None
    rows, mount = got
    p = place_pairs(rows_to_cells(rows), c, initial_ph=planner.ph[mount.az], orderings=1)
    # Spreading may move pairs but never below the limit or below where it started.
    assert p.min_distance_deg >= max(12.0, _all_pairwise_deg(mount.devices)) - 1e-6
    with pytest.raises(FeasibilityError, match="one azimuth per pair"):
        place_pairs(rows_to_cells(rows), c, initial_ph=np.zeros(3))


def test_on_axis_pairs_stay_at_azimuth_zero() -> None:
    # At th = 0 turning a pair is the same as measuring pd + ph; the lab directions report
    # ph = 0. Keeping such pairs at ph = 0 makes cells, lab directions and kappa agree.
    c = RigConstraints(min_device_distance_deg=10.0)
    on_axis = int(np.ravel_multi_index((0, 4, 3), geo.SLICE_SHAPE))  # th 0, td 20, pd 15
    planner = MountPlanner(c)
    _, _, allowed = planner.azimuth_options(on_axis)
    assert allowed.tolist() == [True] + [False] * (planner.ph.size - 1)
    tilted = int(np.ravel_multi_index((6, 4, 3), geo.SLICE_SHAPE))
    cells = rows_to_cells(np.array([on_axis, tilted]))
    p = place_pairs(cells, c)
    assert p.ph_lab[0] == 0.0
    lab = np.deg2rad(p.lab_deg)
    th, _, td, pd = geo.directions_to_half_diff(
        geo.spherical_to_direction(lab[:, 0], lab[:, 1]),
        geo.spherical_to_direction(lab[:, 2], lab[:, 3]),
    )
    np.testing.assert_allclose(np.stack([th, td, pd], axis=1)[0], cells[0], atol=1e-9)
