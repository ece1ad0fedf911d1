"""Adaptive refinement numerics (math.md 9, V&F Sec. 6): where to add stage angles next.

The prediction is the reconstruction's own periodic PCHIP
(:mod:`gonio.brdf.reconstruction.periodic`), in degrees, with the period of the plan's arc: a
scan over half a turn reads a twofold-symmetric specimen, whose readings repeat every 180 deg.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from gonio.brdf.reconstruction.periodic import arc_angle, arc_positions, periodic_pchip_rows


def adaptive_refinement(
    angles_deg: ArrayLike,
    values: ArrayLike,
    threshold: float,
    min_step_deg: float,
    budget_angles: int | None,
    period_deg: float = 360.0,
    start_deg: float = 0.0,
) -> list[float]:
    """New angles for the next adaptive round (math.md 9, V&F Sec. 6 steps 2-3).

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
    period_deg : float
        The plan's arc, degrees: 360 (a full turn, V&F's protocol and the default) or 180 (half
        a turn: the readings are taken to repeat every 180 deg, so PCHIP and the neighbours
        are those of the angles modulo 180).
    start_deg : float
        Where the arc starts (the plan's ``start_deg``), degrees: new angles lie in
        ``[start_deg, start_deg + period_deg)``, modulo 360.

    Returns
    -------
    list of float
        New angles in [0, 360), sorted, none already measured (modulo ``period_deg``).
    """
    # Positions along the arc; angles a period apart are the same reading of the specimen,
    # so a repeat (up to float error) keeps its first reading only.
    a, first = arc_positions(angles_deg, period_deg, start_deg)
    r = a.size
    if r < 3:
        return []
    v = np.asarray(values, float)[:, first, :]
    # Relative error against the pair's own scale at tiny values, so noise near zero does not
    # count as structure to refine.
    scale = np.maximum(np.abs(v), 1e-3 * np.max(np.abs(v), axis=1, keepdims=True) + 1e-300)
    err = np.zeros(r)
    n = v.shape[0]
    for j in range(r):
        keep = np.arange(r) != j
        pred = periodic_pchip_rows(a[keep], v[:, keep, :], np.full((n, 1), a[j]),
                                   period=period_deg)[:, 0, :]
        rel = np.abs(pred - v[:, j, :]) / scale[:, j, :]
        err[j] = float(np.max(rel))
    candidates: dict[float, float] = {}
    for j in np.argsort(-err):
        if err[j] <= threshold:
            break
        nxt, prv = (j + 1) % r, (j - 1) % r
        # Half the gap to each neighbour, the last position's gap running to the first plus
        # one period.
        for half in ((a[nxt] - a[j]) % period_deg / 2.0, -((a[j] - a[prv]) % period_deg) / 2.0):
            if abs(half) < min_step_deg:
                continue
            mid = float(arc_angle([a[j] + half], period_deg, start_deg)[0])
            candidates.setdefault(round(mid, 6) % 360.0, float(err[j]))
    ranked = sorted(candidates, key=lambda k: -candidates[k])
    if budget_angles is not None:
        ranked = ranked[: max(budget_angles, 0)]
    return sorted(ranked)
