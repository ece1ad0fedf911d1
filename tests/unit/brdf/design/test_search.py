"""Tests of the design search over grid rows (gonio.brdf.design.search), blind and
collision-aware."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.design.conditioning import condition_number
from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.search import neighbourhood, optimize_rows
from tests.unit.brdf.design.test_pairs import _grid_basis

SMALL_GRID = (6, 5, 8)


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
