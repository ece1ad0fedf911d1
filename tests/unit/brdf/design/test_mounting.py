"""Tests of the mount planner: azimuths per cell and collision-free moves
(gonio.brdf.design.mounting)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.design.constraints import (
    ConeExclusion,
    RigConstraints,
    angular_distance,
    candidate_rows,
    min_pairwise_distance,
    rows_to_cells,
)
from gonio.brdf.design.mounting import Mounting, MountPlanner
from gonio.brdf.tables import geometry as geo


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
