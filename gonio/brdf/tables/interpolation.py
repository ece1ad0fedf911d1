"""Interpolation between the grid's nodes for pictures and exports: monotone cubic in log.

A table holds the BRDF at the 5 degree nodes of math.md 3. Between them, the multilinear
lookup of :meth:`gonio.brdf.tables.table.BRDFTable.eval_half_diff` draws a specular peak as a
tent: a highlight narrower than a cell comes out too wide and too dim, with corners
(the "rings" of a rendered sphere). This module interpolates
``L = ln(f + eps)`` instead of ``f``:

* along ``th`` (the half vector's angle from the normal, the axis a highlight falls off
  along) by the monotone piecewise cubic of Fritsch & Carlson (1980) with Fritsch & Butland's
  harmonic-mean slopes: on a uniform grid the slope at a node is ``2 / (1/d0 + 1/d1)`` of
  the secants ``d0, d1`` on either side when they share a sign, 0 otherwise; at an end of the
  axis, or beside an invalid node, the interval's own secant. The cubic is then monotone on
  every interval and stays between its two nodes: no overshoot, no ringing;
* along ``ph``, ``td`` and ``pd`` linearly, with the same periodicity, clamping and handling
  of invalid (NaN) neighbours as the multilinear lookup (their weights are left out and the
  rest renormalised).

In log, a lobe that falls off exponentially between two nodes is followed exactly instead of
being cut by a straight line, and every result is a convex blend of node values of ``L``, so it
lies between the smallest and the largest of its 16 neighbours. ``eps`` (:data:`LOG_EPS` times
the table's mean valid value) keeps zeros finite and sets how far down the log reaches: far
below ``eps`` the blend is linear in ``f``. The mean, not the median: a polished metal is 0 on
most cells, and a vanishing ``eps`` would make every tail next to a 0 node collapse.

Measured in docs/notes/2026-11-26-grid-limit.md: the truth tabulated on the grid and rendered
through this lookup is closer to the truth (HDR-FLIP) than through the multilinear one.

The basis, the reconstruction and the simulators keep the multilinear lookup of math.md 3
(linear in the table's values, which the basis' off-grid rows rely on).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

Interpolation = Literal["log-pchip", "multilinear"]
INTERPOLATIONS: tuple[Interpolation, ...] = ("log-pchip", "multilinear")
DEFAULT_INTERPOLATION: Interpolation = "log-pchip"
"""What pictures, page plots and exports interpolate with (module docstring)."""
LOG_EPS = 1e-3
"""``eps`` of ``ln(f + eps)`` relative to the table's mean valid value."""


def log_offset(values: NDArray[np.floating], valid: NDArray[np.bool_]) -> float:
    """``eps`` for a table: :data:`LOG_EPS` x the mean valid value (1e-12 if that is 0).

    Parameters
    ----------
    values : (cells, C) array, BRDF values (any units)
    valid : (cells,) bool, cells whose values are finite
    """
    mean = float(np.mean(values[valid], dtype=np.float64)) if valid.any() else 0.0
    return max(LOG_EPS * mean, 1e-12)


def harmonic_slope(d_before: FloatArray, d_after: FloatArray) -> FloatArray:
    """Fritsch & Butland's slope at a node of a uniform grid from the secants on either side:
    ``2 / (1/d_before + 1/d_after)`` where they share a sign, 0 otherwise (an extremum)."""
    same = d_before * d_after > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        h = 2.0 / (1.0 / d_before + 1.0 / d_after)
    return np.where(same, h, 0.0)


def node_slopes(logs: FloatArray, valid: NDArray[np.bool_]) -> FloatArray:
    """The monotone cubic's slope along ``th`` at every cell, per step, computed once a table.

    A slope depends only on its node and the two beside it along ``th``: the harmonic mean
    of the secants (:func:`harmonic_slope`) when both neighbours are valid, the secant to the
    one valid neighbour at an end of the axis or beside an invalid node, 0 with none.

    Parameters
    ----------
    logs : (cells, C) float64 array, ``ln(f + eps)`` in C order over ``(ph, th, td, pd)``
    valid : (cells,) bool

    Returns
    -------
    (cells, C) float64 array
    """
    n_c = logs.shape[1]
    y = logs.reshape(geo.N_PH, geo.N_TH, geo.N_TD * geo.N_PD, n_c)
    ok = valid.reshape(geo.N_PH, geo.N_TH, geo.N_TD * geo.N_PD, 1)
    before = np.zeros_like(y)
    after = np.zeros_like(y)
    has_before = np.zeros(ok.shape, dtype=bool)
    has_after = np.zeros(ok.shape, dtype=bool)
    before[:, 1:] = y[:, 1:] - y[:, :-1]
    after[:, :-1] = y[:, 1:] - y[:, :-1]
    has_before[:, 1:] = ok[:, :-1] & ok[:, 1:]
    has_after[:, :-1] = ok[:, 1:] & ok[:, :-1]
    out = _slope_rule(before, after, has_before, has_after)
    return np.ascontiguousarray(out.reshape(logs.shape))


def _slope_rule(before: FloatArray, after: FloatArray, has_before: NDArray[np.bool_],
                has_after: NDArray[np.bool_]) -> FloatArray:
    """A node's slope from its secants and which of them exist (:func:`node_slopes`);
    shared by the whole-table and the gathered slopes so both give the same numbers."""
    return np.where(has_before & has_after, harmonic_slope(before, after),
                    np.where(has_before, before, np.where(has_after, after, 0.0)))


def node_logs(values: NDArray[np.floating], eps: float) -> FloatArray:
    """``ln(f + eps)`` of (cells, C) values (0 at invalid cells, negatives clamped to 0).

    float64: the cubic's differences of nearby logs would lose digits in float32.
    """
    return np.log(np.maximum(values.astype(np.float64), 0.0) + eps)


def table_nodes(values: NDArray[np.floating]) -> tuple[FloatArray, NDArray[np.bool_], float]:
    """A whole table's packed nodes for :func:`log_pchip_lookup`, with its validity and ``eps``.

    For code below the renderer (whose :class:`~gonio.brdf.pictures.render.TableLookup`
    also gathers nodes only where few points read): the tilt fit and the disagreement study
    look up most of a table at once. Negative values are clamped to 0 before ``eps`` is taken.

    Parameters
    ----------
    values : (C, 72, 18, 18, 36) array, a table's values (NaN at invalid cells)

    Returns
    -------
    nodes : (cells, 2 C) float64, :func:`pack_nodes` of the logs and their slopes
    valid : (cells,) bool
    eps : float, :func:`log_offset` of the clamped values
    """
    v = np.asarray(values)
    flat = np.moveaxis(v, 0, -1).reshape(-1, v.shape[0]).astype(np.float64)
    ok: NDArray[np.bool_] = np.asarray(np.isfinite(flat).all(axis=1))
    flat = np.where(ok[:, None], np.maximum(flat, 0.0), 0.0)
    eps = log_offset(flat, ok)
    logs = node_logs(flat, eps)  # flat is float64 and clamped already: the same numbers
    return pack_nodes(logs, node_slopes(logs, ok)), ok, eps


def gathered_cells(th: FloatArray, ph: FloatArray, td: FloatArray, pd: FloatArray
                   ) -> NDArray[np.intp]:
    """The cells :func:`log_pchip_lookup` reads at these points, sorted, each once.

    Parameters
    ----------
    th, ph, td, pd : (N,) arrays, radians

    Returns
    -------
    (M,) intp array of flat cell indices (C order over ``(ph, th, td, pd)``), M <= 16 N
    """
    lo, hi, _t, others, s_th = _lookup_axes(th, ph, td, pd)
    corners = []
    for idx, _w in geo.lattice_corners(others):
        base = idx[0] + idx[1] + idx[2]
        corners += [base + lo * s_th, base + hi * s_th]
    return np.unique(np.concatenate(corners))


def gathered_nodes(values: NDArray[np.floating], valid: NDArray[np.bool_], eps: float,
                   cells: NDArray[np.intp]) -> tuple[FloatArray, int]:
    """:func:`pack_nodes` rows of only some cells, equal to the whole table's rows there.

    A lookup at a few hundred points reads a few thousand of a table's 839,808 cells; the
    logs are taken at those cells and at their neighbours along ``th`` (which their slopes
    need), and the slopes by the same rule and arithmetic as :func:`node_slopes`.

    Parameters
    ----------
    values : (cells, C) array, the whole table's values (0 at invalid cells)
    valid : (cells,) bool
    eps : float, :func:`log_offset` of the whole table
    cells : (M,) sorted intp array, e.g. :func:`gathered_cells`

    Returns
    -------
    nodes : (M, 2 C) float64 array, row k for cell ``cells[k]``
    computed : int, how many cells' logs were taken (M plus their ``th`` neighbours)
    """
    s_th = geo.N_TD * geo.N_PD
    j = (cells // s_th) % geo.N_TH
    first, last = j == 0, j == geo.N_TH - 1
    # Logs once per cell, at the gathered cells and the neighbours their slopes need.
    need = np.unique(np.concatenate([cells, cells[~first] - s_th, cells[~last] + s_th]))
    logs = node_logs(values[need], eps)
    ok = valid[need]
    at = np.searchsorted(need, cells)
    below = np.searchsorted(need, np.where(first, cells, cells - s_th))
    above = np.searchsorted(need, np.where(last, cells, cells + s_th))
    y = logs[at]
    before = np.where(first[:, None], 0.0, y - logs[below])
    after = np.where(last[:, None], 0.0, logs[above] - y)
    has_before = (~first & ok[below] & ok[at])[:, None]
    has_after = (~last & ok[above] & ok[at])[:, None]
    return pack_nodes(y, _slope_rule(before, after, has_before, has_after)), int(need.size)


def pack_nodes(logs: FloatArray, slopes: FloatArray) -> FloatArray:
    """``[logs | slopes]`` side by side, the layout :func:`log_pchip_lookup` reads.

    A lookup fetches a node's value and slope together; one row of ``2 C`` numbers costs one
    memory fetch where two arrays cost two (the gathers are most of a lookup's time).

    Parameters
    ----------
    logs, slopes : (cells, C) float64 arrays (:func:`node_slopes`)

    Returns
    -------
    (cells, 2 C) float64 array, C-contiguous
    """
    return np.ascontiguousarray(np.concatenate([logs, slopes], axis=1))


def hermite(y0: FloatArray, y1: FloatArray, s0: FloatArray, s1: FloatArray,
            t: FloatArray) -> FloatArray:
    """Cubic Hermite between ``y0`` (t = 0) and ``y1`` (t = 1) with slopes per unit ``t``."""
    t2, t3 = t * t, t * t * t
    return ((2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * s0
            + (3 * t2 - 2 * t3) * y1 + (t3 - t2) * s1)


def _axis(a: FloatArray, n: int, period: float) -> tuple[NDArray[np.intp], NDArray[np.intp],
                                                           FloatArray]:
    """Lower and upper node index and fraction along one axis (math.md 3)."""
    if period:
        u = np.mod(a, period) / geo.STEP
        i0 = np.floor(u).astype(np.intp)
        return i0 % n, (i0 + 1) % n, u - i0
    u = np.clip(a / geo.STEP, 0.0, n - 1)
    lo = np.minimum(np.floor(u).astype(np.intp), n - 2)
    return lo, lo + 1, u - lo


def _lookup_axes(th: FloatArray, ph: FloatArray, td: FloatArray, pd: FloatArray
                 ) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray,
                            Sequence[tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]], int]:
    """Where a lookup reads: ``th``'s lower and upper node and fraction, the other axes'
    (lower, upper) flat offsets and fractions, and the flat stride of ``th``."""
    s_ph, s_th, s_td = geo.N_TH * geo.N_TD * geo.N_PD, geo.N_TD * geo.N_PD, geo.N_PD
    lo, hi, t = _axis(th, geo.N_TH, 0.0)
    others: Sequence[tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]] = [
        (a * s, b * s, f) for (a, b, f), s in (
            (_axis(ph, geo.N_PH, 2 * np.pi), s_ph),
            (_axis(td, geo.N_TD, 0.0), s_td),
            (_axis(pd, geo.N_PD, np.pi), 1),
        )
    ]
    return lo, hi, t, others, s_th


def log_pchip_lookup(nodes: FloatArray, valid: NDArray[np.floating],
                     th: FloatArray, ph: FloatArray, td: FloatArray, pd: FloatArray,
                     cells: NDArray[np.intp] | None = None
                     ) -> tuple[FloatArray, FloatArray]:
    """``L = ln(f + eps)`` interpolated at half/difference angles (module docstring).

    Parameters
    ----------
    nodes : (cells, 2 C) float64 array
        :func:`pack_nodes` of ``ln(f + eps)`` at a table's cells (C order over
        ``(ph, th, td, pd)``; any finite value at invalid cells) and their
        :func:`node_slopes`.
    valid : (cells,) array of 0.0 / 1.0
        Whether each cell is valid.
    th, ph, td, pd : (N,) arrays, radians
    cells : (M,) sorted intp array or None
        When ``nodes`` and ``valid`` hold only some cells (:func:`gathered_nodes`), the flat
        cell of each of their rows; it must include every cell these points read
        (:func:`gathered_cells`). None: one row per cell of the table.

    Returns
    -------
    L : (N, C) array
        Interpolated ``ln(f + eps)``; undefined where ``weight`` is 0.
    weight : (N,) array
        The multilinear weight of the valid neighbours (0: no valid neighbour).
    """
    lo, hi, t, others, s_th = _lookup_axes(th, ph, td, pd)
    # The cubic's four basis polynomials in t, the same for every corner: computed once.
    tt, tt2 = t[:, None], (t * t)[:, None]
    tt3 = tt2 * tt
    h00, h10 = 2 * tt3 - 3 * tt2 + 1, tt3 - 2 * tt2 + tt
    h01, h11 = 3 * tt2 - 2 * tt3, tt3 - tt2
    n_c = nodes.shape[1] // 2
    acc = np.zeros((th.size, n_c))
    wsum = np.zeros(th.size)
    for idx, w in geo.lattice_corners(others):
        base = idx[0] + idx[1] + idx[2]
        f0, f1 = base + lo * s_th, base + hi * s_th
        if cells is not None:  # rows of the gathered cells instead of the whole table
            f0, f1 = np.searchsorted(cells, f0), np.searchsorted(cells, f1)
        k0, k1 = valid[f0], valid[f1]
        # np.take gathers rows faster than fancy indexing; each row is a value and its slope.
        n0, n1 = np.take(nodes, f0, axis=0), np.take(nodes, f1, axis=0)
        y0, s0, y1, s1 = n0[:, :n_c], n0[:, n_c:], n1[:, :n_c], n1[:, n_c:]
        # Along th, invalid nodes are left out exactly as the multilinear lookup does; the
        # cubic replaces the straight line only where both ends of the interval are valid.
        a0, a1 = (1 - t) * k0, t * k1
        wl = a0 + a1
        ww = w * wl
        # The cubic (hermite(), its polynomials computed once above), then the straight
        # line where an end of the interval is invalid.
        val = h00 * y0 + h10 * s0 + h01 * y1 + h11 * s1
        one_end = (k0 <= 0) | (k1 <= 0)
        if one_end.any():
            with np.errstate(invalid="ignore", divide="ignore"):
                val[one_end] = ((a0[one_end, None] * y0[one_end] + a1[one_end, None]
                                 * y1[one_end]) / wl[one_end, None])
            # A corner without a valid node along th adds nothing (its line is 0 / 0).
            val[ww <= 0] = 0.0
        acc += ww[:, None] * val
        wsum += ww
    with np.errstate(invalid="ignore", divide="ignore"):
        return acc / wsum[:, None], wsum
