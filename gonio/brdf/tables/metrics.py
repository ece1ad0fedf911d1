"""Error metrics between a reconstructed and a reference BRDF (math.md 10).

Every metric runs over the valid cells of all 72 ``ph`` slices and all channels, weighting each
grid cell by its share of the 4-D half/difference volume ``wV = 4 cos td sin td sin th``
(math.md 10, :func:`geometry.volume_weight`), so the densely gridded region near the pole does not
dominate. Cells where either table is NaN (unmeasured) are left out.

Inputs are :class:`BRDFTable` objects or arrays of shape ``(C, 72, 18, 18, 36)`` in 1/sr.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]
TableLike = BRDFTable | NDArray[Any]

#: Floor of the log in :func:`log_psnr`, 1/sr.
LOG_FLOOR = 1e-5
#: Floor of the denominators of :func:`rel_mse` and :func:`mape`, 1/sr: values darker than
#: this are compared in absolute terms.
REL_FLOOR = 1e-3


class MetricError(ValueError):
    """The two BRDFs cannot be compared (shape or channel mismatch)."""


def _values(t: TableLike, what: str) -> NDArray[Any]:
    """A table's values as stored (float32 or float64), shape checked: (C, 72, 18, 18, 36)."""
    v = np.asarray(t.values if isinstance(t, BRDFTable) else t)
    if v.ndim != 5 or v.shape[1:] != geo.TABLE_SHAPE:
        raise MetricError(
            f"{what} has shape {v.shape}; expected (C, {', '.join(map(str, geo.TABLE_SHAPE))})"
        )
    return v


def _valid_values(f_hat: TableLike, f_ref: TableLike) -> tuple[FloatArray, FloatArray]:
    """Both tables at the grid's valid cells, float64: (C, 72, valid cells) each.

    Only the valid cells are converted to float64 (a 31-band table holds 26 million values,
    a third of them outside the valid region)."""
    a = _values(f_hat, "reconstruction")
    b = _values(f_ref, "reference")
    if a.shape != b.shape:
        raise MetricError(
            f"reconstruction has {a.shape[0]} channels and reference {b.shape[0]}; compare "
            "tables with the same channels"
        )
    mask = geo.valid_mask()
    return (np.asarray(a[:, :, mask], dtype=np.float64),
            np.asarray(b[:, :, mask], dtype=np.float64))


def _pair(f_hat: TableLike, f_ref: TableLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Flattened valid values of both tables and their volume weights, all (N,)."""
    return _pair_valid(*_valid_values(f_hat, f_ref))


def _pair_valid(av: FloatArray, bv: FloatArray, ok: NDArray[np.bool_] | None = None
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`_pair` of values already at the valid cells, (C, 72, valid cells) each;
    ``ok``: the cells to keep, if not those where both are finite."""
    if ok is None:
        ok = np.isfinite(av) & np.isfinite(bv)
    if not ok.any():
        raise MetricError("the two tables share no finite valid cell")
    wv = np.broadcast_to(geo.volume_weight()[geo.valid_mask()], av.shape)
    return av[ok], bv[ok], np.asarray(wv[ok])


def cell_cos_ti() -> FloatArray:
    """(18, 18, 36) ``cos theta_i`` of each cell (the metric of Löw et al. uses it)."""
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    return ci




def log_rmse(f_hat: TableLike, f_ref: TableLike) -> float:
    """Cosine-weighted log RMSE of Löw et al. 2012 on the 4-D domain (lower is better).

    ``sqrt(sum wV (ln(1 + f^ cos ti) - ln(1 + f cos ti))^2 / sum wV)``.

    Parameters
    ----------
    f_hat, f_ref : BRDFTable or (C, 72, 18, 18, 36) array, 1/sr

    Returns
    -------
    float, dimensionless
    """
    a, b = _valid_values(f_hat, f_ref)
    # Cells where either table is not finite are left out, as by every metric here.
    ok = np.isfinite(a) & np.isfinite(b)
    cos_ti = cell_cos_ti()[geo.valid_mask()]
    la = np.log1p(np.maximum(a, 0.0) * cos_ti)
    lb = np.log1p(np.maximum(b, 0.0) * cos_ti)
    x, y, w = _pair_valid(la, lb, ok)
    return float(np.sqrt(np.sum(w * (x - y) ** 2) / np.sum(w)))


def log_rmse_to_cap(f: TableLike, cap: float | ArrayLike) -> float:
    """:func:`log_rmse` of a table against itself capped at ``cap``, ``min(f, cap)``, without
    building the capped copy: only the cells above ``cap`` add to the sum, over the weights of
    every finite valid cell (the cells the full metric would compare).

    Parameters
    ----------
    f : BRDFTable or (C, 72, 18, 18, 36) array, 1/sr (or any unit: the metric is not
        unit-free, ``ln(1 + f cos ti)``)
    cap : float or (18, 18, 36) array
        The cap, in ``f``'s units: one value for every cell, or one per slice cell ``(th, td,
        pd)``, the same for every ``ph`` and channel (the physical peak bound's cap is
        ``PEAK_RATIO_LIMIT`` times the largest projected reading over ``cos ti cos to``,
        :func:`gonio.brdf.tables.bounds.peak_cap`).

    Returns
    -------
    float, dimensionless; 0 when no finite value is above ``cap``.
    """
    v = _values(f, "table")
    mask = geo.valid_mask()
    per_cell = np.ndim(cap) > 0
    cap_v = (np.broadcast_to(np.asarray(cap, dtype=float), geo.SLICE_SHAPE)[mask] if per_cell
             else np.full(int(mask.sum()), float(np.asarray(cap, dtype=float))))
    # The common case, nothing above the cap, is settled by one pass over the stored values
    # (fmax skips NaN; every fit asks this): no copy of the valid cells. With a cap per cell
    # the pass compares each cell's largest value over the channels and ph with its cap.
    if per_cell:
        peak_cells = np.fmax.reduce(v, axis=(0, 1))[mask]  # (valid cells,)
        if np.isfinite(peak_cells).any() and not np.any(peak_cells > cap_v):
            return 0.0
    else:
        peak = float(np.fmax.reduce(v, axis=None))
        if not np.isnan(peak) and not peak > cap_v[0]:
            return 0.0
    valid = v[:, :, mask]  # (C, 72, valid cells), the stored dtype: no float64 copy of it all
    finite = np.isfinite(valid)
    if not finite.any():
        raise MetricError("the table has no finite valid cell")
    wv = geo.volume_weight()[mask]
    total = float(np.sum(finite.sum(axis=(0, 1)) * wv))
    above = finite & (valid > cap_v)
    if not above.any():
        return 0.0
    _, _, cell = np.nonzero(above)
    x = np.asarray(valid[above], dtype=np.float64)
    c = cell_cos_ti()[mask][cell]
    d = np.log1p(x * c) - np.log1p(cap_v[cell] * c)
    return float(np.sqrt(np.sum(wv[cell] * d * d) / total))


def log_psnr(f_hat: TableLike, f_ref: TableLike) -> float:
    """Log-domain PSNR in dB (higher is better).

    With ``L = ln(max(f, 1e-5))``:
    ``20 log10((max L_ref - min L_ref) / sqrt(sum wV (L^ - L_ref)^2 / sum wV))``, maximum and
    minimum over the valid cells of the reference. This follows the spirit of the log PSNR
    V&F report (after Aydin et al. 2008): an HDR-aware error whose peak is the reference's
    dynamic range in log units. Identical tables give ``inf``.
    """
    x, y, w = _pair(f_hat, f_ref)
    lx = np.log(np.maximum(x, LOG_FLOOR))
    ly = np.log(np.maximum(y, LOG_FLOOR))
    rmse = float(np.sqrt(np.sum(w * (lx - ly) ** 2) / np.sum(w)))
    peak = float(ly.max() - ly.min())
    if rmse == 0:
        return float("inf")
    return float(20 * np.log10(max(peak, np.finfo(float).tiny) / rmse))


def rel_mse(f_hat: TableLike, f_ref: TableLike) -> float:
    """Volume-weighted relative mean squared error ``sum wV (f^ - f)^2 / max(f, floor)^2 / sum wV``.

    ``floor`` is :data:`REL_FLOOR`; a fraction squared (0.01 means a 10 % typical error).
    """
    x, y, w = _pair(f_hat, f_ref)
    d = np.maximum(y, REL_FLOOR)
    return float(np.sum(w * ((x - y) / d) ** 2) / np.sum(w))


def mape(f_hat: TableLike, f_ref: TableLike) -> float:
    """Volume-weighted mean absolute percentage error ``sum wV |f^ - f| / max(f, floor) / sum wV``.

    Returned as a fraction (0.05 means 5 %); ``floor`` is :data:`REL_FLOOR`.
    """
    x, y, w = _pair(f_hat, f_ref)
    return float(np.sum(w * np.abs(x - y) / np.maximum(y, REL_FLOOR)) / np.sum(w))


def psnr(f_hat: TableLike, f_ref: TableLike) -> float:
    """Linear-domain PSNR in dB: ``20 log10(max f_ref / RMSE)``, volume-weighted RMSE."""
    x, y, w = _pair(f_hat, f_ref)
    rmse = float(np.sqrt(np.sum(w * (x - y) ** 2) / np.sum(w)))
    if rmse == 0:
        return float("inf")
    return float(20 * np.log10(max(float(y.max()), np.finfo(float).tiny) / rmse))


def all_metrics(f_hat: TableLike, f_ref: TableLike) -> dict[str, float]:
    """Every metric of this module by name."""
    return {
        "log_rmse": log_rmse(f_hat, f_ref),
        "log_psnr": log_psnr(f_hat, f_ref),
        "rel_mse": rel_mse(f_hat, f_ref),
        "mape": mape(f_hat, f_ref),
        "psnr": psnr(f_hat, f_ref),
    }
