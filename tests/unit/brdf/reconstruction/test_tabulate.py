"""Coefficients to a table: the folded fast path equals the remap inverted cell by cell."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.reconstruction.basis import EPS, row_weight
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.tabulate import FLOAT32_ABOVE_CHANNELS, expand_table
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis

BASIS = random_basis(4, seed=3)


def reference(coef: np.ndarray) -> np.ndarray:
    """math.md's inverse remap, written plainly: per slice s and row r,
    ``max(((f_med w + eps) exp(Q c + mu) - eps) / w, 0)``, NaN at invalid rows."""
    valid = geo.valid_mask().ravel()
    w = row_weight(BASIS.eps)
    out = np.full((coef.shape[0], coef.shape[2], geo.N_ROWS), np.nan)
    for c in range(coef.shape[0]):
        for s in range(coef.shape[2]):
            x = BASIS.Q @ coef[c, :, s] + BASIS.mu
            a = ((BASIS.f_med * w + BASIS.eps) * np.exp(x) - BASIS.eps) / w
            out[c, s, valid] = np.maximum(a[valid], 0.0)
    return out.reshape(coef.shape[0], *geo.TABLE_SHAPE)


def test_the_table_is_the_inverse_remap_at_every_valid_cell() -> None:
    coef = np.random.default_rng(0).normal(0, 0.1, (2, BASIS.K, geo.N_PH))
    table = expand_table(BASIS, coef)
    assert table.shape == (2, *geo.TABLE_SHAPE) and table.dtype == np.float64
    np.testing.assert_allclose(table, reference(coef), rtol=1e-9, atol=1e-12, equal_nan=True)
    assert BASIS.eps == EPS


def test_spectral_tables_are_expanded_in_float32() -> None:
    n = FLOAT32_ABOVE_CHANNELS + 1
    coef = np.random.default_rng(1).normal(0, 0.1, (n, BASIS.K, geo.N_PH))
    table = expand_table(BASIS, coef)
    assert table.dtype == np.float32
    np.testing.assert_allclose(table[:1], reference(coef[:1]), rtol=1e-4, atol=1e-6,
                               equal_nan=True)


@pytest.mark.parametrize("bad", [1e6, np.nan])
def test_a_diverged_fit_is_refused_with_advice(bad: float) -> None:
    coef = np.zeros((1, BASIS.K, geo.N_PH))
    coef[0, 0, 3] = bad
    with pytest.raises(ReconstructionError, match=r"the fit diverged .* check their units"):
        expand_table(BASIS, coef)
