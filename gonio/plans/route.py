"""Route ordering: the stage positions that visit a set of specimen angles with least travel.

Specimen angles are periodic; stage positions are not (travel limits, cables). Every angle is
approached in the positive direction so gear backlash is taken up the same way each time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from gonio.plans.models import PlanError
from gonio.rigdescription import RigDescription


def stage_positions(angle_deg: float, rig: RigDescription, margin: float) -> list[float]:
    """Stage positions ``angle + 360 m`` inside the limits (keeping ``margin`` below them free)."""
    lo, hi = rig.stage_min_deg + margin, rig.stage_max_deg
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = max(lo, -3600.0), min(hi, 3600.0)
    m0 = math.ceil((lo - angle_deg) / 360.0 - 1e-9)
    out = []
    pos = angle_deg + 360.0 * m0
    while pos <= hi + 1e-9:
        out.append(pos)
        pos += 360.0
    return out


def order_for_travel(
    angles_deg: Sequence[float],
    current_deg: float,
    rig: RigDescription,
    backlash_deg: float = 1.0,
) -> list[float]:
    """Stage positions for ``angles_deg`` visited in increasing order with the least travel.

    Every angle is reached moving in the positive direction, so gear backlash is always taken
    up the same way. The specimen angles are periodic, so any cyclic rotation of the sorted
    angles, shifted by whole turns, is a candidate route; the one with the least total travel
    from ``current_deg`` (including an overshoot of ``backlash_deg`` below the first position
    when approaching it from above) that stays inside the limits wins.

    Parameters
    ----------
    angles_deg : sequence of float, degrees (any range; taken modulo 360)
    current_deg : float, present stage position, degrees
    rig : RigDescription
    backlash_deg : float, degrees

    Returns
    -------
    list of float
        Stage positions, strictly increasing, inside the travel limits.

    Raises
    ------
    PlanError
        When no ordering fits the limits.
    """
    base = sorted({round(a % 360.0, 9) for a in angles_deg})
    if not base:
        return []
    # Each candidate route is a cyclic shift s of the sorted angles starting at one stage
    # position of base[s]; its last position is first + span(s), span(s) the forward distance
    # from base[s] to base[s - 1]. So its cost is O(1) and the search is linear in the number
    # of angles (plus the sort), not quadratic: only the winning route is built.
    n = len(base)
    best: tuple[float, int, float] | None = None  # (cost, shift, first position)
    for s in range(n):
        span = (base[s - 1] - base[s]) % 360.0 if n > 1 else 0.0
        for first in stage_positions(base[s], rig, margin=0.0):
            if abs(first - current_deg) > 720.0 + backlash_deg:
                continue  # far-away turns only add travel
            last = first + span
            if last > rig.stage_max_deg + 1e-9:
                continue
            if current_deg <= first:
                cost = last - current_deg
            else:
                pre = first - backlash_deg
                if pre < rig.stage_min_deg - 1e-9:
                    pre = max(rig.stage_min_deg, pre)
                cost = (current_deg - pre) + (last - pre)
            if best is None or cost < best[0] - 1e-9:
                best = (cost, s, first)
    if best is None:
        raise PlanError(
            f"the angles {', '.join(f'{a:g}' for a in base)} deg cannot all be visited in one "
            f"direction inside the stage travel [{rig.stage_min_deg:g}, {rig.stage_max_deg:g}] "
            "deg; use fewer or different angles, or widen the limits"
        )
    _, shift, first = best
    return [first + (base[(shift + j) % n] - base[shift]) % 360.0 for j in range(n)]
