"""Periodic PCHIP along an angle: each row's samples around the circle, interpolated.

Readings along the stage rotation are periodic, and shape-preserving cubic interpolation (PCHIP)
neither overshoots between samples nor invents extrema. scipy's ``extrapolate='periodic'`` only
wraps the query point, so the samples are padded with copies one period below and above before
the interpolant is built (math.md 5 step 1). Used by the reconstruction (resampling each pair onto
the slices, and back) and by adaptive plans (leave-one-out prediction of a reading, math.md 9).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

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
    # scipy loads with the first interpolation, not with the plans (the daemon's start path
    # imports this module for the arc helpers below).
    from scipy.interpolate import PchipInterpolator

    xp = np.concatenate([x - period, x, x + period])
    yp = np.tile(np.moveaxis(y, 1, 0).reshape(r, n * C), (3, 1))  # (3r, n C)
    pp = PchipInterpolator(xp, yp, axis=0)
    coef = pp.c.reshape(4, 3 * r - 1, n, C)  # highest power first
    u = np.mod(xq, period)
    piece = np.clip(np.searchsorted(xp, u, side="right") - 1, 0, 3 * r - 2)  # (n, m)
    c = coef[:, piece, np.arange(n)[:, None], :]  # (4, n, m, C)
    dx = (u - xp[piece])[..., None]
    return np.asarray(((c[0] * dx + c[1]) * dx + c[2]) * dx + c[3])


def arc_positions(angles_deg: ArrayLike, period_deg: float = 360.0,
                  start_deg: float = 0.0) -> tuple[FloatArray, NDArray[np.intp]]:
    """Measured stage angles as distinct points of one period of the plan's arc.

    A scan over half a turn (``period_deg = 180``) of a twofold-symmetric specimen reads the
    same at ``a`` and ``a + 180``: both are one position.

    Parameters
    ----------
    angles_deg : (r,) stage (specimen) angles, degrees, any range
    period_deg : float
        The arc the scan covers, degrees in (0, 360]: 180 or 360.
    start_deg : float
        Where the arc starts, degrees (the plan's ``start_deg``): positions are measured
        from it.

    Returns
    -------
    positions : (k,) float64
        Distinct positions ``(a - start_deg) mod period_deg``, sorted, in [0, period_deg),
        degrees (angles a period apart, up to float error, count once).
    first : (k,) intp
        Index in ``angles_deg`` of the first angle at each position.
    """
    if not 0.0 < period_deg <= 360.0:
        raise ValueError(f"period_deg must be in (0, 360] degrees, got {period_deg:g}")
    a = np.asarray(angles_deg, dtype=float).ravel()
    # Rounded so that angles a period apart, up to float error, are one position.
    pos, first = np.unique(np.mod(np.round(np.mod(a - start_deg, period_deg), 9), period_deg),
                           return_index=True)
    return pos, first


def arc_gaps(angles_deg: ArrayLike, period_deg: float = 360.0,
             start_deg: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """Measured stage angles as distinct points of one period, and the gap after each.

    Over half a turn the last angle's gap runs to the first one plus half a turn, not round
    the full circle (:func:`arc_positions`).

    Parameters
    ----------
    angles_deg, period_deg, start_deg : as for :func:`arc_positions`

    Returns
    -------
    positions : (k,) float64
        :func:`arc_positions`' positions, degrees.
    gaps : (k,) float64
        Gap from each position to the next (the last to the first plus a period), degrees;
        a single position has a gap of one period.
    """
    pos, _ = arc_positions(angles_deg, period_deg, start_deg)
    if pos.size == 0:
        return pos, pos.copy()
    return pos, np.diff(np.concatenate([pos, [pos[0] + period_deg]]))


def arc_angle(positions: ArrayLike, period_deg: float = 360.0,
              start_deg: float = 0.0) -> FloatArray:
    """Stage angles in [0, 360) of positions on the arc ``[start_deg, start_deg + period_deg)``.

    Parameters
    ----------
    positions : (m,) positions from the arc's start, degrees (any range: taken modulo
        ``period_deg``)
    period_deg, start_deg : as for :func:`arc_gaps`

    Returns
    -------
    (m,) float64, degrees in [0, 360): ``(start_deg + positions mod period_deg) mod 360``
    """
    p = np.mod(np.asarray(positions, dtype=float), period_deg)
    return np.asarray(np.mod(start_deg + p, 360.0))
