"""Tests of the error metrics (math.md 10)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable


def constant(value: float, channels: int = 3) -> BRDFTable:
    v = np.full((channels, *geo.TABLE_SHAPE), value)
    return BRDFTable(v, tuple("RGB"[:channels]))


def test_identical_tables() -> None:
    t = constant(0.3)
    assert metrics.log_rmse(t, t) == 0.0
    assert metrics.log_psnr(t, t) == float("inf")
    assert metrics.rel_mse(t, t) == 0.0
    assert metrics.mape(t, t) == 0.0
    assert metrics.psnr(t, t) == float("inf")


def test_constant_ratio_has_known_errors() -> None:
    ref, hat = constant(0.2), constant(0.22)  # 10 % too bright everywhere
    assert metrics.mape(hat, ref) == pytest.approx(0.1)
    assert metrics.rel_mse(hat, ref) == pytest.approx(0.01)
    assert metrics.psnr(hat, ref) == pytest.approx(20 * np.log10(0.2 / 0.02))
    # log_rmse: volume-weighted RMS of ln(1 + f cos ti) differences, computed independently.
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    m = geo.valid_mask()
    wv = geo.volume_weight()[m]
    d = np.log1p(0.22 * ci[m]) - np.log1p(0.2 * ci[m])
    assert metrics.log_rmse(hat, ref) == pytest.approx(np.sqrt(np.sum(wv * d**2) / np.sum(wv)))


def test_log_psnr_uses_the_reference_dynamic_range() -> None:
    rng = np.random.default_rng(0)
    ref_v = rng.uniform(0.01, 10.0, (3, *geo.TABLE_SHAPE))
    ref = BRDFTable(ref_v, ("R", "G", "B"))
    hat = BRDFTable(ref_v * np.e**0.1, ("R", "G", "B"))  # log error exactly 0.1 everywhere
    m = geo.valid_mask()
    lv = np.log(ref_v[:, :, m])
    expect = 20 * np.log10((lv.max() - lv.min()) / 0.1)
    assert metrics.log_psnr(hat, ref) == pytest.approx(expect, rel=1e-9)
    # Worse reconstructions score lower.
    worse = BRDFTable(ref_v * np.e**0.3, ("R", "G", "B"))
    assert metrics.log_psnr(worse, ref) < metrics.log_psnr(hat, ref)
    assert metrics.log_rmse(worse, ref) > metrics.log_rmse(hat, ref)


def test_volume_weight_emphasises_large_th() -> None:
    """An error confined to the th = 0 row costs less than the same error at th = 45 deg."""
    ref = constant(0.5)
    v0 = np.array(ref.values)
    v0[:, :, 0] *= 2
    v9 = np.array(ref.values)
    v9[:, :, 9] *= 2
    assert metrics.log_rmse(v0, ref) < metrics.log_rmse(v9, ref)


def test_arrays_and_nan_cells_accepted() -> None:
    ref = constant(0.2)
    hat = np.array(constant(0.25).values)
    hat[:, 3, 4, 4, 4] = np.nan  # an unmeasured cell is left out, not an error
    assert np.isfinite(metrics.log_rmse(hat, ref))
    assert metrics.all_metrics(hat, ref)["mape"] == pytest.approx(0.25)


def test_mismatched_inputs_are_clear_errors() -> None:
    with pytest.raises(metrics.MetricError, match="channels"):
        metrics.log_rmse(constant(0.2, 3), constant(0.2, 1))
    with pytest.raises(metrics.MetricError, match="expected"):
        metrics.psnr(np.zeros((3, 10)), constant(0.2))


def test_log_rmse_to_a_cap_is_the_metric_against_the_capped_table() -> None:
    """One cell above the cap: the weighted squared log difference of that cell over the
    weights of every finite valid cell, written out from the metric's definition; and the
    same as log_rmse against the capped copy on a table with several cells above it and
    unmeasured (NaN) cells."""
    mask = geo.valid_mask()
    v = np.full((3, *geo.TABLE_SHAPE), 0.1)
    th, td, pd = (int(i[0]) for i in np.nonzero(mask))
    v[0, 5, th, td, pd] = 1e6
    wv = geo.volume_weight()
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    c = ci[th, td, pd]
    num = wv[th, td, pd] * (np.log(1 + 1e6 * c) - np.log(1 + 100.0 * c)) ** 2
    den = 3 * 72 * wv[mask].sum()
    assert metrics.log_rmse_to_cap(v, 100.0) == pytest.approx(np.sqrt(num / den), rel=1e-12)
    rng = np.random.default_rng(11)
    w = rng.uniform(0.0, 50.0, v.shape)
    w[:, :, mask] = np.where(rng.random(w[:, :, mask].shape) < 0.01, 5e3, w[:, :, mask])
    w[1, 7] = np.nan  # an unmeasured slice: left out of both
    capped = np.minimum(w, 200.0)
    assert metrics.log_rmse_to_cap(w, 200.0) == pytest.approx(metrics.log_rmse(w, capped),
                                                               rel=1e-12)
    assert metrics.log_rmse_to_cap(w, 1e4) == 0.0
    with pytest.raises(metrics.MetricError, match="no finite valid cell"):
        metrics.log_rmse_to_cap(np.full_like(v, np.nan), 1.0)
