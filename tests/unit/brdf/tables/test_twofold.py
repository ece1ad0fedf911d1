"""A table's distance from twofold symmetry (gonio.brdf.tables.twofold)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.metrics import log_rmse
from gonio.brdf.tables.table import BRDFTable
from gonio.brdf.tables.twofold import half_turn_average, twofold_asymmetry


@pytest.fixture(scope="module")
def base() -> BRDFTable:
    """An anisotropic GGX lobe: twofold symmetric, since D(h) depends on ph only through
    cos^2 ph and sin^2 ph."""
    return bm.tabulate(bm.LobeSum((bm.Lambert((0.1, 0.2, 0.3)), bm.GGX(
        0.1, 0.4, bm.SchlickFresnel(0.04), "separable"))), np.float64)


def _times(table: BRDFTable, factor: np.ndarray) -> BRDFTable:
    return BRDFTable.trusted(np.asarray(table.values) * factor[None, :, None, None, None],
                             table.channels, table.name)


def test_a_symmetric_table_is_its_own_half_turn_average(base: BRDFTable) -> None:
    np.testing.assert_allclose(half_turn_average(base).values, base.values, rtol=1e-9,
                               equal_nan=True)
    assert twofold_asymmetry(base) < 1e-9
    # An even harmonic (cos 2 ph) is unchanged by a half turn.
    even = _times(base, 1.0 + 0.5 * np.cos(2 * geo.PH_GRID))
    assert twofold_asymmetry(even) < 1e-9


def test_an_odd_harmonic_is_averaged_away(base: BRDFTable) -> None:
    # cos(ph + pi) = -cos ph, so the average of f (1 + a cos ph) over a half turn is f.
    odd = _times(base, 1.0 + 0.6 * np.cos(geo.PH_GRID))
    np.testing.assert_allclose(half_turn_average(odd).values, base.values, rtol=1e-9,
                               equal_nan=True)
    assert twofold_asymmetry(odd) == pytest.approx(log_rmse(base, odd), rel=1e-12)
    assert twofold_asymmetry(odd) > 0.01
    # A stronger odd harmonic is further from symmetry.
    assert twofold_asymmetry(_times(base, 1.0 + 0.9 * np.cos(geo.PH_GRID))) > \
        twofold_asymmetry(odd)


def test_summed_by_channel_it_is_the_metric_of_the_average_with_damaged_cells(
        base: BRDFTable) -> None:
    # Summed one channel at a time (a 31-band table's whole-table temporaries took 1.6 GB):
    # the same number as log_rmse of the half-turn average, which leaves out the cells where
    # either table is not finite, here a damaged stretch of one channel.
    values = np.array(_times(base, 1.0 + 0.6 * np.cos(geo.PH_GRID)).values)
    values[1, 3, 2:5, :, 10:20] = np.nan
    values[2, 40, 7] = np.inf
    odd = BRDFTable.trusted(values, base.channels, base.name)
    assert twofold_asymmetry(odd) == pytest.approx(log_rmse(half_turn_average(odd), odd),
                                                   rel=1e-12)
