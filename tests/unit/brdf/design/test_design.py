"""Tests of the sampling-design objective, the secular-equation update and the search."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.brdf.design.conditioning import (
    block_width,
    condition_number,
    condition_numbers_fast,
    condition_numbers_svd,
    secular_extremes,
)
from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.pairs import PairDesign
from gonio.brdf.design.search import neighbourhood, optimize_rows
from gonio.brdf.reconstruction.basis import Basis

SMALL_GRID = (6, 5, 8)


def _random_case(
    rng: np.random.Generator, n: int, K: int, rank_deficient: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    m = block_width(n, K)
    scales = np.exp(rng.normal(size=m))
    kept = rng.normal(size=(n - 1, m)) * scales
    if rank_deficient and m > 1 and n > 2:
        kept[:, 0] = kept[:, 1]
    cand = rng.normal(size=(30, m)) * scales
    return kept, cand


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize(("n", "K"), [(1, 4), (2, 6), (5, 12), (8, 8), (12, 5), (20, 9)])
def test_fast_update_matches_svd(seed: int, n: int, K: int) -> None:
    # n <= K: the kept Gram matrix has d_1 = 0 exactly; n > K: a tall, full-rank block.
    rng = np.random.default_rng(seed)
    kept, cand = _random_case(rng, n, K)
    fast = condition_numbers_fast(kept, cand)
    ref = condition_numbers_svd(kept, cand)
    np.testing.assert_allclose(fast, ref, rtol=1e-8)


@pytest.mark.parametrize("seed", range(4))
def test_fast_update_matches_svd_with_repeated_zero_eigenvalues(seed: int) -> None:
    # Two equal columns make the kept Gram matrix singular twice over (d_1 = d_2 = 0): every
    # candidate block is singular unless the new row breaks the tie, and both must agree.
    rng = np.random.default_rng(seed)
    kept, cand = _random_case(rng, 6, 10, rank_deficient=True)
    fast = condition_numbers_fast(kept, cand)
    ref = condition_numbers_svd(kept, cand)
    assert np.array_equal(np.isfinite(fast), np.isfinite(ref))
    finite = np.isfinite(ref)
    np.testing.assert_allclose(fast[finite], ref[finite], rtol=1e-8)


def test_fast_update_handles_zero_and_orthogonal_candidates() -> None:
    rng = np.random.default_rng(3)
    kept = rng.normal(size=(3, 4))  # null vector v: kept @ v = 0
    v = np.linalg.svd(kept)[2][-1]
    in_range = kept[0] - (kept[0] @ v) * v  # no component along the null vector
    cand = np.stack([np.zeros(4), in_range, v])
    fast = condition_numbers_fast(kept, cand)
    ref = condition_numbers_svd(kept, cand)
    assert np.isinf(fast[0]) and np.isinf(ref[0])
    assert np.isinf(fast[1]) and np.isinf(ref[1])
    np.testing.assert_allclose(fast[2], ref[2], rtol=1e-8)


def test_secular_extremes_match_eigvalsh() -> None:
    rng = np.random.default_rng(7)
    d = np.sort(np.concatenate([[0.0], rng.uniform(0.01, 10.0, size=7)]))
    z = rng.normal(size=(50, 8))
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    rho = rng.uniform(0.1, 20.0, size=50)
    lo, hi = secular_extremes(d, z, rho)
    for k in range(50):
        ev = np.linalg.eigvalsh(np.diag(d) + rho[k] * np.outer(z[k], z[k]))
        assert lo[k] == pytest.approx(ev[0], rel=1e-10)
        assert hi[k] == pytest.approx(ev[-1], rel=1e-12)
        # The interlacing brackets of V&F App. B.
        assert d[0] <= lo[k] <= d[1] and d[-1] <= hi[k] <= d[-1] + rho[k]


def test_condition_number_uses_square_block_when_n_le_K() -> None:
    rows = np.array([[1.0, 0.0, 100.0], [0.0, 2.0, -50.0]])
    # Only the first two columns count: diag(1, 2) has kappa 2.
    assert condition_number(rows) == pytest.approx(2.0)
    tall = np.array([[3.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    assert condition_number(tall) == pytest.approx(3.0)
    assert np.isinf(condition_number(np.array([[1.0, 1.0], [2.0, 2.0]])))


def test_condition_number_rejects_empty_rows() -> None:
    with pytest.raises(DesignError, match="non-empty"):
        condition_number(np.zeros((0, 3)))


def test_neighbourhood_clips_th_td_and_wraps_pd() -> None:
    flat = int(np.ravel_multi_index((0, 4, 7), SMALL_GRID))
    idx = np.unravel_index(neighbourhood(flat, 3, SMALL_GRID), SMALL_GRID)
    assert set(idx[0]) == {0, 1}
    assert set(idx[1]) == {3, 4}
    assert set(idx[2]) == {6, 7, 0}
    assert len(idx[0]) == 2 * 2 * 3
    with pytest.raises(DesignError, match="odd"):
        neighbourhood(flat, 4, SMALL_GRID)


def _small_problem(seed: int = 0, K: int = 6) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    p = int(np.prod(SMALL_GRID))
    # Smooth-ish columns over the grid, like a real basis, plus a little noise.
    g = np.stack(np.meshgrid(*[np.linspace(0, 1, s) for s in SMALL_GRID], indexing="ij"), -1)
    g = g.reshape(p, 3)
    freqs = rng.normal(size=(3, K)) * 3.0
    Q = np.cos(g @ freqs + rng.uniform(0, 2 * np.pi, size=K)) + 0.05 * rng.normal(size=(p, K))
    return Q, np.arange(p)


def test_search_improves_on_random_designs_and_is_seeded() -> None:
    Q, cand = _small_problem()
    n = 5
    res = optimize_rows(Q, cand, n, h=3, starts=2, descents=2, seed=11, grid_shape=SMALL_GRID)
    assert res.rows.shape == (n,) and len(set(res.rows.tolist())) == n
    assert res.kappa == pytest.approx(condition_number(Q[res.rows]))
    rng = np.random.default_rng(0)
    random_kappas = [condition_number(Q[rng.choice(cand, n, replace=False)]) for _ in range(50)]
    assert res.kappa < np.median(random_kappas)
    again = optimize_rows(Q, cand, n, h=3, starts=2, descents=2, seed=11, grid_shape=SMALL_GRID)
    np.testing.assert_array_equal(res.rows, again.rows)


def test_search_with_fast_and_svd_methods_finds_the_same_design() -> None:
    Q, cand = _small_problem(seed=2)
    kw = dict(h=3, starts=1, descents=2, seed=5, grid_shape=SMALL_GRID)
    fast = optimize_rows(Q, cand, 4, method="fast", **kw)  # type: ignore[arg-type]
    ref = optimize_rows(Q, cand, 4, method="svd", **kw)  # type: ignore[arg-type]
    np.testing.assert_array_equal(fast.rows, ref.rows)
    assert fast.kappa == pytest.approx(ref.kappa, rel=1e-10)


def test_search_tall_case_uses_all_components() -> None:
    Q, cand = _small_problem(seed=4, K=3)
    res = optimize_rows(Q, cand, 8, h=3, starts=1, descents=1, seed=1, grid_shape=SMALL_GRID)
    assert np.isfinite(res.kappa)
    assert res.kappa == pytest.approx(condition_number(Q[res.rows]))


def test_search_respects_candidates() -> None:
    Q, _ = _small_problem()
    allowed = np.arange(0, Q.shape[0], 3)
    res = optimize_rows(Q, allowed, 4, h=3, starts=1, descents=2, seed=0, grid_shape=SMALL_GRID)
    assert np.isin(res.rows, allowed).all()


@pytest.mark.parametrize(
    ("n", "cands", "match"),
    [(0, 10, "at least 1"), (5, 3, "only 3 feasible cells"), (2, 0, "no candidate cells")],
)
def test_search_errors_say_what_to_do(n: int, cands: int, match: str) -> None:
    Q, _ = _small_problem()
    with pytest.raises(DesignError, match=match):
        optimize_rows(Q, np.arange(cands), n, grid_shape=SMALL_GRID)


def test_search_rejects_q_of_wrong_shape() -> None:
    with pytest.raises(DesignError, match="one row per grid cell"):
        optimize_rows(np.zeros((10, 3)), np.arange(5), 2, grid_shape=SMALL_GRID)


def _grid_basis(K: int = 6) -> Basis:
    from gonio.brdf.tables import geometry as geo

    rng = np.random.default_rng(0)
    th, td, pd = (a.ravel() for a in geo.grid_angles())
    feats = np.stack([th, td, np.cos(2 * pd), np.sin(2 * pd)], axis=1)
    Q = np.cos(feats @ rng.normal(size=(4, K)) * 2.0 + rng.uniform(0, 6, size=K))
    return Basis(Q, np.ones(K), np.ones(geo.N_ROWS), np.zeros(geo.N_ROWS),
                 geo.valid_mask().ravel())


def test_product_rig_respects_constraints_and_reports_its_kappa() -> None:
    from gonio.brdf.design.constraints import ConeExclusion, RigConstraints
    from gonio.brdf.design.pairs import geometry_design
    from gonio.brdf.design.placement import check_devices
    from gonio.brdf.design.product import design_product_rig
    from gonio.brdf.tables import geometry as geo

    basis = _grid_basis()
    c = RigConstraints(max_elevation_deg=70.0, min_device_distance_deg=15.0,
                       exclusions=(ConeExclusion(0.0, 0.0, 12.0),))
    d = design_product_rig(basis, 2, 3, c, h=3, starts=2, seed=0)
    assert d.n_pairs == 6 and d.pairs.tolist() == [[a, b] for a in range(2) for b in range(3)]
    li = geo.spherical_to_direction(*np.deg2rad(d.lights_deg).T)
    se = geo.spherical_to_direction(*np.deg2rad(d.sensors_deg).T)
    assert check_devices(li, se, c) == []
    again = geometry_design(basis, "x", li, se, d.pairs)
    assert again.kappa == pytest.approx(d.kappa, rel=1e-9)
    # Better than where it started: random feasible rigs of the same size, on average.
    rng = np.random.default_rng(5)
    from gonio.brdf.design.product import _random_rig, product_kappa

    grid_t, grid_p = np.meshgrid(np.deg2rad(np.arange(15, 71, 5)), np.deg2rad(np.arange(0, 360, 5)))
    gdirs = geo.spherical_to_direction(grid_t.ravel(), grid_p.ravel())
    kinds = np.array([True, True, False, False, False])
    rigs = [_random_rig(gdirs, kinds, c, rng) for _ in range(10)]
    ks = [product_kappa(basis.rows_at, gdirs[r][None, :2], gdirs[r][None, 2:])[0]
          for r in rigs if r is not None]
    assert d.kappa <= np.median(ks)


def test_product_rig_errors() -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.product import design_product_rig

    basis = _grid_basis()
    with pytest.raises(DesignError, match="at least one light and one sensor"):
        design_product_rig(basis, 0, 3, RigConstraints())
    crowded = RigConstraints(max_elevation_deg=10.0, min_device_distance_deg=15.0)
    with pytest.raises(FeasibilityError, match="could not place 3 lights and 3 sensors"):
        design_product_rig(basis, 3, 3, crowded, starts=1)


def test_design_pairs_places_the_optimized_cells() -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    basis = _grid_basis()
    d = design_pairs(basis, 4, RigConstraints(), h=3, starts=1, descents=1, seed=2)
    assert d.search is not None and d.kappa == pytest.approx(d.search.kappa)
    assert d.min_distance_deg >= 10.0 - 1e-6
    assert d.lab_deg.shape == (4, 4)


# ------------------------------------------------------------------ screening
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize(("n", "K"), [(6, 12), (10, 10), (14, 6)])
def test_screening_never_drops_an_improvement(seed: int, n: int, K: int) -> None:
    # With a cutoff, candidates that provably cannot beat it are skipped (inf); every
    # candidate that does beat it must come back with its exact kappa.
    rng = np.random.default_rng(seed)
    kept, cand = _random_case(rng, n, K)
    ref = condition_numbers_svd(kept, cand)
    for cutoff in np.quantile(ref[np.isfinite(ref)], [0.1, 0.5, 0.9]):
        got = condition_numbers_fast(kept, cand, cutoff)
        better = ref < cutoff * (1.0 - 1e-9)
        np.testing.assert_allclose(got[better], ref[better], rtol=1e-8)
        # Whatever is returned finite is exact, and skipped ones really do not improve.
        finite = np.isfinite(got)
        np.testing.assert_allclose(got[finite], ref[finite], rtol=1e-8)
        assert (ref[~finite] >= cutoff * (1.0 - 1e-9)).all()
        assert (~finite).sum() >= (ref >= cutoff).sum() // 2  # it does screen


# ------------------------------------------------------------------ collision-aware search
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


def test_collision_aware_search_returns_its_placement() -> None:
    from gonio.brdf.design.constraints import (
        RigConstraints,
        candidate_rows,
        min_pairwise_distance,
        rows_to_cells,
    )
    from gonio.brdf.design.mounting import MountPlanner
    from gonio.brdf.tables import geometry as geo

    basis = _grid_basis(K=8)
    c = RigConstraints(min_device_distance_deg=15.0)
    planner = MountPlanner(c)
    res = optimize_rows(basis.Q, candidate_rows(c, basis.valid), 12, h=3, starts=2, descents=2,
                        seed=4, mounts=planner)
    assert res.ph_lab is not None and res.ph_lab.shape == (12,)
    cells = rows_to_cells(res.rows)
    wi, wo = geo.half_diff_to_directions(cells[:, 0], res.ph_lab, cells[:, 1], cells[:, 2])
    assert np.degrees(min_pairwise_distance(np.concatenate([wi, wo]))) >= 15.0 - 1e-6
    with pytest.raises(DesignError, match="standard"):
        optimize_rows(basis.Q[:240], np.arange(10), 2, grid_shape=SMALL_GRID, mounts=planner)


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
