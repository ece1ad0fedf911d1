"""The table expansion of a subset of slices, and the valid cells copied run by run.

The posterior's weights read every third slice of the first fit's table, so reconstruct()
expands only those for it; the values must be those of the whole table's slices. The valid
cells are copied into the table as contiguous runs: NaN exactly at the invalid cells.
"""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.reconstruction.basis import row_weight
from gonio.brdf.reconstruction.tabulate import FLOAT32_ABOVE_CHANNELS, expand_table
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis


@pytest.mark.parametrize("n_channels", [2, FLOAT32_ABOVE_CHANNELS + 3])
def test_a_subset_of_slices_expands_to_those_slices_of_the_whole_table(n_channels: int
                                                                       ) -> None:
    b = random_basis(5, seed=3)
    coef = np.random.default_rng(2).normal(0, 0.2, (n_channels, b.K, geo.N_PH))
    whole = expand_table(b, coef)
    part = expand_table(b, coef[:, :, ::3])
    assert part.shape == (n_channels, geo.N_PH // 3, *geo.TABLE_SHAPE[1:])
    assert part.dtype == whole.dtype
    np.testing.assert_allclose(part, whole[:, ::3], rtol=1e-6, atol=0, equal_nan=True)


def test_spectral_table_is_nan_exactly_at_invalid_cells_and_the_inverse_remap_elsewhere(
) -> None:
    b = random_basis(5, seed=2)
    c = FLOAT32_ABOVE_CHANNELS + 3
    coef = np.random.default_rng(1).normal(0, 0.2, (c, b.K, geo.N_PH))
    got = expand_table(b, coef).reshape(c, geo.N_PH, geo.N_ROWS)
    # The inverse remap written out (math.md 4), float64.
    w = row_weight(b.eps)
    x = np.einsum("rk,cks->csr", b.Q, coef) + b.mu
    want = np.maximum((np.exp(x) * (b.f_med * w + b.eps) - b.eps) / w, 0.0)
    valid = geo.valid_mask().ravel()
    np.testing.assert_array_equal(np.isnan(got), np.broadcast_to(~valid, got.shape))
    np.testing.assert_allclose(got[:, :, valid], want[:, :, valid], rtol=2e-5,
                               atol=1e-6 * want[:, :, valid].max())
