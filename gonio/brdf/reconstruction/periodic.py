"""Periodic PCHIP along an angle: each row's samples around the circle, interpolated.

Readings along the stage rotation are periodic, and shape-preserving cubic interpolation (PCHIP)
neither overshoots between samples nor invents extrema. scipy's ``extrapolate='periodic'`` only
wraps the query point, so the samples are padded with copies one period below and above before
the interpolant is built (MATH 5 step 1). Used by the reconstruction (resampling each pair onto
the slices, and back) and by adaptive plans (leave-one-out prediction of a reading, MATH 7).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

FloatArray = NDArray[np.float64]


def periodic_pchip_rows(
    x: FloatArray, y: FloatArray, xq: FloatArray, period: float = 2 * np.pi
) -> FloatArray:
    """Periodic PCHIP of many rows that share their nodes, each row at its own query points.

    Parameters
    ----------
    x : (r,) sorted, distinct nodes in [0, period), in the unit of ``period``
    y : (n, r, C) values of row ``q`` at the nodes
    xq : (n, m) query points of row ``q``, same unit (any range: taken modulo ``period``)
    period : float
        Length of one turn: ``2 pi`` for radians (the default), 360 for degrees.

    Returns
    -------
    (n, m, C)
        Row ``q`` interpolated at ``xq[q]``. One interpolant is built for all rows (the
        nodes are shared) and evaluated piece by piece, instead of one scipy object per row.
        With a single node every query gets that node's value.
    """
    n, r, C = y.shape
    if r == 1:
        return np.broadcast_to(y[:, :1, :], (n, xq.shape[1], C)).copy()
    xp = np.concatenate([x - period, x, x + period])
    yp = np.tile(np.moveaxis(y, 1, 0).reshape(r, n * C), (3, 1))  # (3r, n C)
    pp = PchipInterpolator(xp, yp, axis=0)
    coef = pp.c.reshape(4, 3 * r - 1, n, C)  # highest power first
    u = np.mod(xq, period)
    piece = np.clip(np.searchsorted(xp, u, side="right") - 1, 0, 3 * r - 2)  # (n, m)
    c = coef[:, piece, np.arange(n)[:, None], :]  # (4, n, m, C)
    dx = (u - xp[piece])[..., None]
    return np.asarray(((c[0] * dx + c[1]) * dx + c[2]) * dx + c[3])
