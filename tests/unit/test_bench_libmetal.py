"""The band measures of ``bench/bench_libmetal.py`` (docs/science.md 7.1.1.3, last paragraph)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from tests.unit.bench_import import import_bench

bl = import_bench("bench_libmetal")

th_rad, td_rad, _PD = geo.grid_angles()


def _full(slice_values: np.ndarray) -> np.ndarray:
    """A (1, 72, 18, 18, 36) table whose slice is ``slice_values`` at every ph."""
    return np.broadcast_to(slice_values, (1, geo.N_PH, *slice_values.shape)).copy()


def test_band_bias_is_the_log_ratio_put_on_the_flank_per_band() -> None:
    truth = np.full(geo.SLICE_SHAPE, 0.3)
    lib = truth.copy()
    flank = (th_rad >= np.deg2rad(10.0)) & (th_rad < np.deg2rad(30.0))
    shifts = (0.1, -0.2, 0.4, -0.5)  # one per band of TD_BANDS_DEG
    for (lo, hi), c in zip(bl.TD_BANDS_DEG, shifts, strict=True):
        band = (td_rad >= np.deg2rad(lo)) & (td_rad < np.deg2rad(hi))
        lib[flank & band] *= np.exp(c)
    lib[th_rad < np.deg2rad(10.0)] *= 50.0  # the peak is off the flank: must not count
    lib[th_rad >= np.deg2rad(30.0)] *= 0.01
    got = bl.band_bias(_full(lib), _full(truth))
    assert got == pytest.approx(shifts, abs=1e-9)


def test_read_error_sees_only_theta_d_below_the_read_limit() -> None:
    truth = np.full(geo.SLICE_SHAPE, 0.3)
    beyond = truth.copy()
    beyond[td_rad >= np.deg2rad(50.0)] *= 4.0
    assert bl.read_error(_full(beyond), _full(truth)) == pytest.approx(0.0, abs=1e-12)

    below = truth.copy()
    below[td_rad < np.deg2rad(50.0)] *= 4.0
    # The full metric averages the same squared errors over every valid cell's weight; the
    # read error over the read cells' weight only.
    mask = geo.valid_mask()
    w = geo.volume_weight()[mask]
    read = td_rad[mask] < np.deg2rad(50.0)
    full = metrics.log_rmse(_full(below), _full(truth))
    expected = full * np.sqrt(np.sum(w) / np.sum(w[read]))
    assert bl.read_error(_full(below), _full(truth)) == pytest.approx(expected, rel=1e-9)
