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
from gonio.brdf.design.placement import (
    _closest_two,
    _distances_to,
    _nearest_angles,
    check_devices,
    place_pairs,
)
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


# The placement's nearest-device searches (dot-product preselection, exact angle for the few
# nearest) must give what the full matrix of angles gives, bit for bit: the greedy and the
# repair compare these values and take argmax/argmin of them, so any difference could change
# a design. The reference is the atan2 angle of every pair, written out here.


def _angle_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(m, k) angle between every ``a`` (m, 3) and ``b`` (k, 3): atan2(|a x b|, a . b)."""
    cross = np.linalg.norm(np.cross(a[:, None, :], b[None, :, :]), axis=-1)
    return np.arctan2(cross, np.sum(a[:, None, :] * b[None, :, :], axis=-1))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _hard_devices(rng: np.random.Generator, queries: np.ndarray) -> np.ndarray:
    """Devices that tie or nearly tie as the nearest of ``queries``, plus antipodes."""
    base = _unit(rng.standard_normal((6, 3)))
    normal = _unit(np.cross(queries[:3], rng.standard_normal((3, 3))))  # planes through queries
    near = [
        queries[:2],  # at distance 0
        -queries[2:4],  # antipodal
        _unit(base[:3] + 1e-13 * rng.standard_normal((3, 3))),  # near copies of base
        base[:3] - 2.0 * np.sum(base[:3] * normal, axis=1, keepdims=True) * normal,  # mirrors
        base,
    ]
    return np.concatenate(near)


def _ring(m: int, tilt_deg: float) -> np.ndarray:
    """``m`` unit vectors evenly around a cone: every neighbour is the same angle away."""
    return geo.spherical_to_direction(
        np.full(m, np.deg2rad(tilt_deg)), np.arange(m) * 2.0 * np.pi / m)


def test_nearest_angles_equal_the_full_angle_matrix() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        a = _unit(rng.standard_normal((40, 3)))
        b = _hard_devices(rng, a)
        np.testing.assert_array_equal(_nearest_angles(a, b), _angle_matrix(a, b).min(axis=1))
        only_antipode = -a[:1]
        np.testing.assert_array_equal(_nearest_angles(a, only_antipode),
                                      _angle_matrix(a, only_antipode).min(axis=1))
    # Queries midway between ring neighbours tie to rounding between two devices.
    ring, mid = _ring(24, 50.0), geo.spherical_to_direction(
        np.full(24, np.deg2rad(50.0)), (np.arange(24) + 0.5) * 2.0 * np.pi / 24)
    np.testing.assert_array_equal(_nearest_angles(mid, ring), _angle_matrix(mid, ring).min(axis=1))


def test_distances_to_equal_the_full_angle_matrix() -> None:
    # Pair devices over the same 1-degree azimuth grid place_pairs uses.
    c = RigConstraints()
    rng = np.random.default_rng(8)
    cells = rows_to_cells(rng.choice(candidate_rows(c), 5, replace=False))
    ph = np.deg2rad(np.arange(360.0))
    wi, wo = geo.half_diff_to_directions(cells[:, None, 0], ph[None, :], cells[:, None, 1],
                                         cells[:, None, 2])
    for k in range(5):
        dev = np.concatenate([wi[k, ::37], wo[(k + 1) % 5, ::23], _hard_devices(rng, wi[k])])
        want = np.minimum(_angle_matrix(wi[k], dev).min(axis=1),
                          _angle_matrix(wo[k], dev).min(axis=1))
        np.testing.assert_array_equal(_distances_to(wi, wo, k, dev), want)
    assert (_distances_to(wi, wo, 0, np.zeros((0, 3))) == math.inf).all()


@pytest.mark.parametrize("kind", ["random", "hard", "ring", "two"])
def test_closest_two_is_the_first_argmin_of_the_full_angle_matrix(kind: str) -> None:
    rng = np.random.default_rng(9)
    for _ in range(10):
        if kind == "random":
            dirs = _unit(rng.standard_normal((24, 3)))
        elif kind == "hard":
            dirs = _hard_devices(rng, _unit(rng.standard_normal((4, 3))))
        elif kind == "ring":  # every neighbour ties to rounding; the first one must win
            dirs = _ring(int(rng.integers(3, 40)), float(rng.uniform(5.0, 85.0)))
        else:
            dirs = _unit(rng.standard_normal((2, 3)))
        full = _angle_matrix(dirs, dirs)
        np.fill_diagonal(full, math.inf)
        a, b = np.unravel_index(int(np.argmin(full)), full.shape)
        assert _closest_two(dirs) == (full[a, b], a, b)


def test_design_is_the_one_the_full_angle_matrices_give(monkeypatch: pytest.MonkeyPatch) -> None:
    """A whole default-objective design, once as shipped and once with the nearest-device
    searches replaced by the full matrices, gives the same pairs at the same azimuths."""
    from gonio.brdf.design import placement
    from gonio.brdf.design.pairs import design_pairs
    from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
    from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

    basis = _with_prior(random_basis(6), {0: 1.0, 2: 0.5})
    c = RigConstraints(min_device_distance_deg=15.0)
    fast = design_pairs(basis, 8, c)

    def full_nearest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return _angle_matrix(a, b).min(axis=1)

    def full_closest(dirs: np.ndarray) -> tuple[float, int, int]:
        d = _angle_matrix(dirs, dirs)
        np.fill_diagonal(d, math.inf)
        a, b = np.unravel_index(int(np.argmin(d)), d.shape)
        return float(d[a, b]), int(a), int(b)

    monkeypatch.setattr(placement, "_nearest_angles", full_nearest)
    monkeypatch.setattr(placement, "_closest_two", full_closest)
    slow = design_pairs(basis, 8, c)
    assert fast.objective == slow.objective == "posterior"
    np.testing.assert_array_equal(fast.cells, slow.cells)
    np.testing.assert_array_equal(fast.ph_lab, slow.ph_lab)
    assert fast.min_distance_deg == slow.min_distance_deg
