"""Adaptive refinement numerics (MATH 7, V&F Sec. 6): where to add stage angles next."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def periodic_pchip(x_deg: NDArray[np.float64], y: NDArray[np.float64],
                   xq_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Periodic PCHIP through ``(x, y)`` with period 360 evaluated at ``xq``.

    scipy's ``extrapolate='periodic'`` only wraps the query, so the samples are padded with
    wrapped copies on both sides (MATH 5 step 1).

    Parameters
    ----------
    x_deg : (m,) distinct angles, degrees in [0, 360)
    y : (m, ...) values
    xq_deg : (q,) query angles, degrees

    Returns
    -------
    (q, ...) interpolated values
    """
    from scipy.interpolate import PchipInterpolator

    order = np.argsort(x_deg)
    x, yy = np.asarray(x_deg, float)[order], np.asarray(y, float)[order]
    xp = np.concatenate([x - 360.0, x, x + 360.0])
    yp = np.concatenate([yy, yy, yy], axis=0)
    return np.asarray(PchipInterpolator(xp, yp, axis=0)(np.mod(xq_deg, 360.0)))


def adaptive_refinement(
    angles_deg: ArrayLike,
    values: ArrayLike,
    threshold: float,
    min_step_deg: float,
    budget_angles: int | None,
) -> list[float]:
    """New angles for the next adaptive round (MATH 7, V&F Sec. 6 steps 2-3).

    For each pair and each measured angle, predict the value from the pair's *other* angles
    with periodic PCHIP; where ``|predicted - measured| / |measured|`` exceeds ``threshold``
    in any channel, plan the midpoints between that angle and both neighbours.

    Parameters
    ----------
    angles_deg : (r,) measured specimen angles, degrees
    values : (n_pairs, r, C) dark-subtracted readings at those angles
    threshold : relative error e (0.1 = 10 %)
    min_step_deg : a midpoint closer than this to a measured angle is not planned, degrees
    budget_angles : how many more angles may be added (None = no limit); the midpoints around
        the worst-predicted samples are kept first

    Returns
    -------
    list of float
        New angles in [0, 360), sorted, none already measured.
    """
    a = np.mod(np.asarray(angles_deg, float), 360.0)
    r = a.size
    if r < 3:
        return []
    order = np.argsort(a)
    a = a[order]
    v = np.asarray(values, float)[:, order, :]
    # Relative error against the pair's own scale at tiny values, so noise near zero does not
    # count as structure to refine.
    scale = np.maximum(np.abs(v), 1e-3 * np.max(np.abs(v), axis=1, keepdims=True) + 1e-300)
    err = np.zeros(r)
    for j in range(r):
        keep = np.arange(r) != j
        pred = periodic_pchip(a[keep], np.moveaxis(v[:, keep, :], 1, 0), a[j : j + 1])[0]
        rel = np.abs(pred - v[:, j, :]) / scale[:, j, :]
        err[j] = float(np.max(rel))
    candidates: dict[float, float] = {}
    for j in np.argsort(-err):
        if err[j] <= threshold:
            break
        for nb in ((j - 1) % r, (j + 1) % r):
            gap = (a[nb] - a[j]) % 360.0 if nb == (j + 1) % r else (a[j] - a[nb]) % 360.0
            if gap / 2.0 < min_step_deg:
                continue
            mid = (a[j] + gap / 2.0) % 360.0 if nb == (j + 1) % r else (a[j] - gap / 2.0) % 360.0
            key = round(mid, 6)
            candidates.setdefault(key, float(err[j]))
    ranked = sorted(candidates, key=lambda k: -candidates[k])
    if budget_angles is not None:
        ranked = ranked[: max(budget_angles, 0)]
    return sorted(ranked)
