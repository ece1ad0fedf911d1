"""Adaptive refinement numerics (MATH 7, V&F Sec. 6): where to add stage angles next.

The prediction is the reconstruction's own periodic PCHIP
(:mod:`gonio.brdf.reconstruction.periodic`), in degrees.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from gonio.brdf.reconstruction.periodic import periodic_pchip_rows


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
    n = v.shape[0]
    for j in range(r):
        keep = np.arange(r) != j
        pred = periodic_pchip_rows(a[keep], v[:, keep, :], np.full((n, 1), a[j]),
                                   period=360.0)[:, 0, :]
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
