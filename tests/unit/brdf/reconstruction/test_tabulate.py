"""Tests of the table expansion from basis coefficients (step 4 of both fits)."""

from __future__ import annotations

import numpy as np

from gonio.brdf.reconstruction.basis import row_weight
from gonio.brdf.reconstruction.tabulate import FLOAT32_ABOVE_CHANNELS, expand_table
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis


def _by_formula(b: object, coef: np.ndarray) -> np.ndarray:
    """(C, 72, N_ROWS) ``max((exp(Q c + mu) (f_med w + eps) - eps) / w, 0)`` at valid cells,
    NaN elsewhere, written out cell by cell in float64 (the remap's inverse, math.md 4)."""
    Q, mu, fm, eps = b.Q, b.mu, b.f_med, b.eps  # type: ignore[attr-defined]
    w = row_weight(eps)
    X = np.einsum("rk,cks->csr", Q, coef) + mu
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.maximum((np.exp(X) * (fm * w + eps) - eps) / w, 0.0)
    return np.where(geo.valid_mask().ravel(), out, np.nan)


def test_expansion_equals_the_inverse_remap_and_is_nan_exactly_at_invalid_cells() -> None:
    b = random_basis(5, seed=2)
    coef = np.random.default_rng(0).normal(0, 0.2, (3, b.K, geo.N_PH))
    got = expand_table(b, coef)
    assert got.shape == (3, *geo.TABLE_SHAPE) and got.dtype == np.float64
    want = _by_formula(b, coef)
    flat = got.reshape(3, geo.N_PH, geo.N_ROWS)
    np.testing.assert_array_equal(np.isnan(flat), np.isnan(want))
    np.testing.assert_allclose(flat, want, rtol=1e-12, atol=1e-15)


def test_many_channels_expand_in_float32_to_float32_precision() -> None:
    b = random_basis(5, seed=2)
    c = FLOAT32_ABOVE_CHANNELS + 3
    coef = np.random.default_rng(1).normal(0, 0.2, (c, b.K, geo.N_PH))
    got = expand_table(b, coef)
    assert got.dtype == np.float32
    want = _by_formula(b, coef)
    flat = got.reshape(c, geo.N_PH, geo.N_ROWS)
    np.testing.assert_array_equal(np.isnan(flat), np.isnan(want))
    np.testing.assert_allclose(flat, want, rtol=2e-5, atol=1e-6 * np.nanmax(want))


def test_a_subset_of_slices_expands_to_those_slices_of_the_whole_table() -> None:
    b = random_basis(5, seed=3)
    coef = np.random.default_rng(2).normal(0, 0.2, (2, b.K, geo.N_PH))
    whole = expand_table(b, coef)
    part = expand_table(b, coef[:, :, ::3])
    assert part.shape == (2, geo.N_PH // 3, *geo.TABLE_SHAPE[1:])
    np.testing.assert_allclose(part, whole[:, ::3], rtol=1e-13, atol=0)
