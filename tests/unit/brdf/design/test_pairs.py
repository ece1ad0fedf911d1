"""Tests of pair designs that can be mounted (gonio.brdf.design.pairs)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.brdf.design.conditioning import (
    condition_number,
)
from gonio.brdf.design.pairs import PairDesign
from gonio.brdf.design.search import optimize_rows
from gonio.brdf.reconstruction.basis import Basis


def _grid_basis(K: int = 6) -> Basis:
    from gonio.brdf.tables import geometry as geo

    rng = np.random.default_rng(0)
    th, td, pd = (a.ravel() for a in geo.grid_angles())
    feats = np.stack([th, td, np.cos(2 * pd), np.sin(2 * pd)], axis=1)
    Q = np.cos(feats @ rng.normal(size=(4, K)) * 2.0 + rng.uniform(0, 6, size=K))
    return Basis(Q, np.ones(K), np.ones(geo.N_ROWS), np.zeros(geo.N_ROWS),
                 geo.valid_mask().ravel())


def test_design_pairs_places_the_optimized_cells() -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    basis = _grid_basis()
    d = design_pairs(basis, 4, RigConstraints(), h=3, starts=1, descents=1, seed=2)
    assert d.search is not None and d.kappa == pytest.approx(d.search.kappa)
    assert d.min_distance_deg >= 10.0 - 1e-6
    assert d.lab_deg.shape == (4, 4)


def _devices_of(design: PairDesign) -> np.ndarray:
    from gonio.brdf.tables import geometry as geo

    lab = np.deg2rad(design.lab_deg)
    wi = geo.spherical_to_direction(lab[:, 0], lab[:, 1])
    wo = geo.spherical_to_direction(lab[:, 2], lab[:, 3])
    return np.concatenate([wi, wo])


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 16),
       limit=st.sampled_from([8.0, 12.0, 18.0]))
def test_designs_under_a_device_distance_always_mount(seed: int, n: int, limit: float) -> None:
    from gonio.brdf.design.constraints import RigConstraints, min_pairwise_distance
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.tables import geometry as geo

    basis = _grid_basis(K=8)
    c = RigConstraints(max_elevation_deg=70.0, min_device_distance_deg=limit)
    d = design_pairs(basis, n, c, h=3, starts=1, descents=2, seed=seed)
    dev = _devices_of(d)
    # Checked from the written lab directions, not from the design's own report.
    assert np.degrees(min_pairwise_distance(dev)) >= limit - 1e-6
    assert d.min_distance_deg >= limit - 1e-6
    assert (np.degrees(np.arccos(np.clip(dev[:, 2], -1, 1))) <= 70.0 + 1e-6).all()
    # The lab directions measure exactly the optimized cells (pd is defined mod pi), so the
    # geometry read back from them has the reported kappa.
    th, _, td, pd = geo.directions_to_half_diff(dev[:n], dev[n:])
    np.testing.assert_allclose(th, d.cells[:, 0], atol=1e-9)
    np.testing.assert_allclose(td, d.cells[:, 1], atol=1e-9)
    np.testing.assert_allclose(np.sin(2.0 * (pd - d.cells[:, 2])), 0.0, atol=1e-9)
    assert d.kappa == pytest.approx(condition_number(basis.Q[_rows_of(d.cells)]))
    assert d.kappa == pytest.approx(condition_number(basis.rows_at(th, td, pd)), rel=1e-6)


def _rows_of(cells: np.ndarray) -> np.ndarray:
    from gonio.brdf.tables import geometry as geo

    idx = [np.rint((cells[:, k] - g[0]) / (g[1] - g[0])).astype(int)
           for k, g in enumerate((geo.TH_GRID, geo.TD_GRID, geo.PD_GRID))]
    return np.ravel_multi_index(tuple(idx), geo.SLICE_SHAPE)


def test_design_that_cannot_be_mounted_is_a_clear_error() -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.pairs import design_pairs

    crowded = RigConstraints(max_elevation_deg=20.0, min_device_distance_deg=15.0)
    with pytest.raises(FeasibilityError,
                       match=r"cannot mount 12 pairs.*lower min_device_distance_deg"):
        design_pairs(_grid_basis(), 12, crowded, h=3, starts=1, descents=1)


@pytest.fixture(scope="module")
def library_basis() -> Basis:
    """K = 16 basis of one library material per family (built in ~2 s)."""
    from gonio.brdf.materials.library import library_specs
    from gonio.brdf.models import analytic as bm
    from gonio.brdf.reconstruction.basis import build_basis

    first: dict[str, bm.BRDFModel] = {}
    for spec in library_specs():
        first.setdefault(spec.family, spec.model)
    return build_basis([bm.tabulate(m) for m in first.values()], 16)


def test_twenty_pairs_mount_with_default_limits_on_a_library_basis(library_basis: Basis) -> None:
    from gonio.brdf.design.constraints import (
        RigConstraints,
        candidate_rows,
        min_pairwise_distance,
        rows_to_cells,
    )
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.placement import place_pairs

    c = RigConstraints()  # 80 deg elevation, 10 deg separation, 10 deg between devices
    # The failure this guards against: a cells-only search crowds pairs near the zenith, so
    # its designs mostly cannot be mounted (4 of seeds 0-4 when this was written).
    cand = candidate_rows(c, library_basis.valid)
    collided, blind_kappas = 0, []
    for seed in (1, 2, 3):
        blind = optimize_rows(library_basis.Q, cand, 20, starts=1, descents=2, seed=seed)
        blind_kappas.append(blind.kappa)
        try:
            place_pairs(rows_to_cells(blind.rows), c, orderings=4)
        except FeasibilityError as exc:
            assert "cannot mount 20 pairs" in str(exc)
            collided += 1
    assert collided >= 1
    d = design_pairs(library_basis, 20, c, starts=1, descents=2, seed=1)
    assert d.n_pairs == 20 and np.isfinite(d.kappa)
    assert np.degrees(min_pairwise_distance(_devices_of(d))) >= 10.0 - 1e-6
    # Collision-awareness costs little conditioning against the blind search.
    assert d.kappa < 2.0 * float(np.median(blind_kappas))
