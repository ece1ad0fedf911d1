"""Tests of rig constraints, candidate filtering and lab placement of pairs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.design.constraints import (
    BoxExclusion,
    ConeExclusion,
    RigConstraints,
    angular_distance,
    candidate_rows,
    feasible_mask,
    min_pairwise_distance,
    parse_exclusion,
    rows_to_cells,
)
from gonio.brdf.design.errors import FeasibilityError
from gonio.brdf.design.mounting import Mounting, MountPlanner
from gonio.brdf.design.placement import check_devices, place_pairs
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


# ------------------------------------------------------------------ MountPlanner
def _all_pairwise_deg(devices: np.ndarray) -> float:
    return math.degrees(min_pairwise_distance(np.asarray(devices).reshape(-1, 3)))


def test_planner_azimuths_are_the_half_diff_map() -> None:
    # Turning ph must rotate both devices about the normal exactly as the forward map does,
    # or the search would check collisions for devices that are not where the pair goes.
    c = RigConstraints(exclusions=(ConeExclusion(40.0, 90.0, 15.0),))
    planner = MountPlanner(c, ph_step_deg=5.0)
    rng = np.random.default_rng(2)
    for row in rng.choice(candidate_rows(c), 5, replace=False):
        wi, wo, allowed = planner.azimuth_options(int(row))
        th, td, pd = rows_to_cells(np.array([row]))[0]
        ri, ro = geo.half_diff_to_directions(th, planner.ph, td, pd)
        np.testing.assert_allclose(wi, ri, atol=1e-12)
        np.testing.assert_allclose(wo, ro, atol=1e-12)
        ex = c.exclusions[0]
        np.testing.assert_array_equal(allowed, ~ex.contains(ri) & ~ex.contains(ro))
        # The cache gives the same answer the second time.
        again = planner.azimuth_options(int(row))
        np.testing.assert_array_equal(again[0], wi)


def test_best_azimuth_keeps_the_distance_or_says_none() -> None:
    c = RigConstraints(min_device_distance_deg=10.0)
    planner = MountPlanner(c)
    row = int(np.ravel_multi_index((8, 6, 0), geo.SLICE_SHAPE))  # th 40, td 30
    wi, wo, _ = planner.azimuth_options(row)
    # Two devices that block some azimuths but not all.
    others = geo.spherical_to_direction(np.deg2rad([40.0, 60.0]), np.deg2rad([0.0, 200.0]))
    j, dev = planner.best_azimuth(row, others)
    assert j >= 0
    np.testing.assert_allclose(dev, [wi[j], wo[j]])
    dist = np.rad2deg(angular_distance(dev[:, None, :], others[None, :, :]))
    assert dist.min() >= 10.0 - 1e-6
    # Maximin: no allowed azimuth keeps its devices farther from the others.
    every = np.minimum(
        angular_distance(wi[:, None, :], others[None]).min(axis=1),
        angular_distance(wo[:, None, :], others[None]).min(axis=1),
    )
    assert math.radians(dist.min()) == pytest.approx(every.max(), abs=1e-9)
    # A ring of devices every 5 deg of azimuth at both of the pair's elevations blocks it.
    t_i, t_o = (math.degrees(a) for a in np.arccos([wi[0, 2], wo[0, 2]]))
    ring_t = np.repeat([t_i, t_o], 72)
    ring_p = np.tile(np.arange(0.0, 360.0, 5.0), 2)
    ring = geo.spherical_to_direction(np.deg2rad(ring_t), np.deg2rad(ring_p))
    assert planner.best_azimuth(row, ring)[0] == -1


def test_planner_start_and_move_stay_collision_free() -> None:
    c = RigConstraints(min_device_distance_deg=15.0)
    planner = MountPlanner(c)
    cand = candidate_rows(c)
    got = planner.start(np.random.default_rng(0), cand, 10)
    assert got is not None
    rows, mount = got
    assert rows.shape == (10,) and len(set(rows.tolist())) == 10
    np.testing.assert_array_equal(mount.rows, rows)
    assert _all_pairwise_deg(mount.devices) >= 15.0 - 1e-6
    # The recorded devices are the rows' devices at the recorded azimuths.
    cells = rows_to_cells(rows)
    wi, wo = geo.half_diff_to_directions(cells[:, 0], planner.ph[mount.az], cells[:, 1],
                                         cells[:, 2])
    np.testing.assert_allclose(mount.devices[:, 0], wi, atol=1e-12)
    np.testing.assert_allclose(mount.devices[:, 1], wo, atol=1e-12)
    # A move that collides at every azimuth is refused and leaves the state alone: the other
    # "pairs" here are a ring of devices every 5 deg of azimuth at the new cell's elevations.
    row = int(np.ravel_multi_index((8, 6, 0), geo.SLICE_SHAPE))
    wi0, wo0, _ = planner.azimuth_options(row)
    t_i, t_o = (math.degrees(a) for a in np.arccos([wi0[0, 2], wo0[0, 2]]))
    ring = geo.spherical_to_direction(np.deg2rad(np.repeat([t_i, t_o], 72)),
                                      np.deg2rad(np.tile(np.arange(0.0, 360.0, 5.0), 2)))
    blocked = Mounting(np.full(73, row, dtype=np.intp), np.zeros(73, dtype=np.intp),
                       np.concatenate([mount.devices[:1], ring.reshape(72, 2, 3)]))
    before = blocked.copy()
    assert not planner.move(blocked, 0, row)
    np.testing.assert_array_equal(blocked.az, before.az)
    np.testing.assert_array_equal(blocked.devices, before.devices)
    # An accepted move keeps every distance, changes no other pair's cell, and every pair's
    # devices stay those of its cell at its azimuth (a nudged neighbour included).
    for r in np.random.default_rng(1).choice(cand, 30, replace=False):
        cells_before = mount.rows.copy()
        if planner.move(mount, 3, int(r)):
            assert _all_pairwise_deg(mount.devices) >= 15.0 - 1e-6
            assert mount.rows[3] == r
            np.testing.assert_array_equal(np.delete(mount.rows, 3), np.delete(cells_before, 3))
            c3 = rows_to_cells(mount.rows)
            wi, wo = geo.half_diff_to_directions(c3[:, 0], planner.ph[mount.az], c3[:, 1],
                                                 c3[:, 2])
            np.testing.assert_allclose(mount.devices[:, 0], wi, atol=1e-12)
            np.testing.assert_allclose(mount.devices[:, 1], wo, atol=1e-12)


def test_planner_start_gives_up_when_there_is_no_room() -> None:
    # Devices within 20 deg of the normal, 15 deg apart: a few pairs at most fit.
    c = RigConstraints(max_elevation_deg=20.0, min_separation_deg=10.0,
                       min_device_distance_deg=15.0)
    planner = MountPlanner(c)
    assert planner.start(np.random.default_rng(0), candidate_rows(c), 12) is None
    assert planner.collisions_possible
    assert not MountPlanner(RigConstraints(min_device_distance_deg=0.0)).collisions_possible


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


def test_a_neighbour_steps_aside_when_only_it_is_in_the_way() -> None:
    # Pair B sits where pair A's new cell wants to go at every free azimuth but one that B
    # alone blocks; with nudging B turns away, without it the move is refused.
    c = RigConstraints(max_elevation_deg=60.0, min_device_distance_deg=20.0)
    cand = candidate_rows(c)
    rng = np.random.default_rng(0)
    found = False
    for _ in range(200):
        got = MountPlanner(c).start(rng, cand, 6)
        assert got is not None
        _, mount = got
        for r in rng.choice(cand, 20, replace=False):
            stiff, nudge = MountPlanner(c, nudges=0), MountPlanner(c, nudges=4)
            a, b = mount.copy(), mount.copy()
            if not stiff.move(a, 0, int(r)) and nudge.move(b, 0, int(r)):
                moved = np.flatnonzero(b.az != mount.az)
                assert set(moved.tolist()) - {0} != set()  # someone else turned
                assert _all_pairwise_deg(b.devices) >= 20.0 - 1e-6
                np.testing.assert_array_equal(b.rows[1:], mount.rows[1:])
                found = True
                break
        if found:
            break
    assert found
