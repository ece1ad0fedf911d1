"""Reconstruction of many channels at once (a spectral sensor's bands) equals each alone.

Every channel shares the design, so :func:`reconstruct` solves them in one factorisation and
expands the table once; these tests pin down that this is the same as the fit of each band on
its own, and that the scan's own prior factor is chosen as from the whole table of the first
fit (the posterior's weights are computed from only the slices they read).
"""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.reconstruction.posterior import ScanPosterior
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.tabulate import FLOAT32_ABOVE_CHANNELS
from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs, random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

N_BANDS = FLOAT32_ABOVE_CHANNELS + 5  # a spectral table: expanded in float32
HARMONICS = {0: 1.0, 2: 1.0, 4: 0.5, 36: 0.2}


def _spectral_scan(seed: int = 5) -> tuple[object, np.ndarray, np.ndarray, np.ndarray,
                                             np.ndarray]:
    b = _with_prior(random_basis(6, seed=1), HARMONICS)
    cells, ph = grid_pairs(10, seed=4)
    alpha = np.deg2rad(np.arange(8) * 22.5)
    rng = np.random.default_rng(seed)
    # A smooth spectrum per pair times a pattern along the stage angle, plus noise: bands
    # that differ but are correlated, as a specimen's are.
    spectrum = 0.3 + 0.2 * np.sin(np.linspace(0, 3, N_BANDS))[None, None, :]
    pattern = 1 + 0.3 * np.cos(2 * alpha)[None, :, None] * rng.uniform(0, 1, (10, 1, 1))
    vals = spectrum * pattern * np.abs(rng.normal(1.0, 0.05, (10, 8, N_BANDS)))
    return b, cells, ph, alpha, vals


@pytest.mark.parametrize("rho", [0.5, None, (0.25, 2.0)])
def test_bands_together_equal_each_band_alone(rho: object) -> None:
    b, cells, ph, alpha, vals = _spectral_scan()
    names = tuple(f"{400 + 10 * k}" for k in range(N_BANDS))
    together = reconstruct(b, cells, ph, alpha, vals, channels=names, rho=rho)  # type: ignore[arg-type]
    assert together.table.values.dtype == np.float32
    for k in range(N_BANDS):
        alone = reconstruct(b, cells, ph, alpha, vals[..., k:k + 1], channels=names[k:k + 1],
                            rho=rho)  # type: ignore[arg-type]
        want = alone.table.values[0]
        got = together.table.values[k]
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        # float32 table against a float64 one: float32's precision on exp(Q c + mu).
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.nanmax(want))
        np.testing.assert_allclose(together.coefficients[k], alone.coefficients[0],
                                   rtol=1e-10, atol=1e-12)


def test_scan_factor_is_chosen_as_from_the_whole_first_table() -> None:
    """rho="scan": the posterior of the first fit (learnt prior as it is), weighted from its
    whole table, picks the factor; the result is the fit under that factor."""
    b, cells, ph, alpha, vals = _spectral_scan(seed=6)
    names = tuple(str(k) for k in range(N_BANDS))
    first = reconstruct(b, cells, ph, alpha, vals, channels=names, rho=None)
    post = ScanPosterior(b, cells, ph, alpha, vals, table=first.table.values)
    assert post.rho < 1.0  # the scan's own factor is adopted, so the fit is redone
    want = reconstruct(b, cells, ph, alpha, vals, channels=names, rho=post.rho)
    got = reconstruct(b, cells, ph, alpha, vals, channels=names)
    assert got.settings["prior_rho"] == post.rho
    np.testing.assert_array_equal(got.table.values, want.table.values)
    assert got.expected_log_rmse == pytest.approx(post.expected_log_rmse, rel=1e-9)
    assert got.mahalanobis == pytest.approx(post.mahalanobis, rel=1e-9)
