"""Tests of the condition-number objective and its fast secular-equation update
(gonio.brdf.design.conditioning)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.design.conditioning import (
    block_width,
    condition_number,
    condition_numbers_fast,
    condition_numbers_svd,
    secular_extremes,
)
from gonio.brdf.design.errors import DesignError


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
