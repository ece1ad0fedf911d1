"""From basis coefficients to a BRDF table: the remap inverted at every valid cell.

Both fits (the joint fit and V&F's path) end here, and the posterior uses the same table for
its ``log_rmse`` weights. The table (C x 72 x 11,664 values) dominates a reconstruction's
cost, so it is computed at the valid rows only, with the remap's per-row constants folded into
one scale and one offset.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.reconstruction.basis import Basis, row_weight
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import VALID_ROWS

FloatArray = NDArray[np.float64]


@functools.lru_cache(maxsize=4)
def _valid_row_weight(eps: float) -> FloatArray:
    """(p_valid,) remap weight ``w`` of the valid rows (read-only; depends only on ``eps``)."""
    w = row_weight(eps)[VALID_ROWS]
    w.setflags(write=False)
    return w


@functools.lru_cache(maxsize=1)
def _valid_runs() -> tuple[tuple[int, int, int, int], ...]:
    """The valid rows as contiguous runs: ``(start, stop)`` in a slice's 11,664 rows and
    ``(start, stop)`` in the valid rows' own order (169 runs).

    Copying the valid values into the table run by run is a set of strided block copies;
    a fancy-indexed assignment of the same 7,861 columns cost as much as the whole product
    for a 31-band table.
    """
    rows = np.asarray(VALID_ROWS)
    breaks = np.flatnonzero(np.diff(rows) != 1) + 1
    starts = np.concatenate([[0], breaks])
    stops = np.concatenate([breaks, [rows.size]])
    return tuple((int(rows[a]), int(rows[b - 1]) + 1, int(a), int(b))
                 for a, b in zip(starts, stops, strict=True))


#: ``exp`` overflows float64 above about 709; a remapped value this large means a diverged fit.
_MAX_EXPONENT = 700.0
#: Tables of more channels than this (spectral sensors: 11, 18, 31 bands) are expanded in
#: float32, the precision the result file stores them in: a 31-band float64 table is 230 MB
#: and its expansion dominates the reconstruction. RGB tables keep float64.
FLOAT32_ABOVE_CHANNELS = 4


def expand_table(basis: Basis, coef: FloatArray) -> FloatArray:
    """BRDF values of every slice from the coefficients (step 4 of both fits).

    Parameters
    ----------
    basis : Basis
    coef : (C, K, S) coefficients of S slices (the 72 grid slices; fewer when only some are
        needed, as the posterior's weights need every third)

    Returns
    -------
    (C, S, 18, 18, 36) float64 (float32 above :data:`FLOAT32_ABOVE_CHANNELS` channels), 1/sr
        ``max((exp(Q C + mu) (f_med w + eps) - eps) / w, 0)`` at the valid cells, NaN at the
        invalid ones. The per-row constants fold into ``exp(Q C) * scale - offset`` with
        ``scale = exp(mu) (f_med w + eps) / w`` and ``offset = eps / w``, so the big array
        sees one product, then ``exp``, multiply, subtract and clamp in place.
    """
    eps = basis.eps
    w = _valid_row_weight(eps)
    scale = np.exp(basis.mu[VALID_ROWS]) * (basis.f_med[VALID_ROWS] * w + eps) / w
    offset = eps / w
    n_ch, K, n_s = coef.shape
    dtype = np.float32 if n_ch > FLOAT32_ABOVE_CHANNELS else np.float64
    X = np.ascontiguousarray(np.swapaxes(coef, 1, 2), dtype=dtype).reshape(n_ch * n_s, K) @ (
        basis.Q[VALID_ROWS].T.astype(dtype, copy=False))  # (C 72, p_valid)
    top = float(X.max())
    if not top < _MAX_EXPONENT:  # also catches NaN
        raise ReconstructionError(
            f"the fit diverged (remapped value {top:.3g}); the samples are far outside what "
            "the basis can represent: check their units (1/sr) and the dark subtraction"
        )
    np.exp(X, out=X)
    X *= scale.astype(dtype, copy=False)
    X -= offset.astype(dtype, copy=False)
    np.maximum(X, 0.0, out=X)
    out = np.full((n_ch * n_s, geo.N_ROWS), np.nan, dtype=dtype)
    for lo, hi, a, b in _valid_runs():
        out[:, lo:hi] = X[:, a:b]
    return out.reshape(n_ch, n_s, *geo.TABLE_SHAPE[1:])
