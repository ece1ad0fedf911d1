"""How long a plan takes: move times along a route, settles, exposures, adaptive bounds.

The engine's own backlash overshoot and the stage driver's approach overshoot are both
replayed with the rules of :mod:`gonio.motion`, so an estimate counts every leg the hardware
will travel, timed with the profile the drivers poll by.
"""

from __future__ import annotations

from collections.abc import Sequence

from gonio.brdf.reconstruction.periodic import arc_angle, arc_gaps
from gonio.motion import approach_waypoints, move_time, plan_overshoot_legs
from gonio.plans.models import MAX_ROTATIONS, AdaptivePlan, AnyPlan
from gonio.plans.route import order_for_travel
from gonio.rigdescription import RigDescription


def travel(positions: Sequence[float], start_deg: float, rig: RigDescription,
           backlash_deg: float) -> tuple[float, int, float]:
    """Moves of the engine visiting ``positions`` in order from ``start_deg``.

    Per position the engine overshoots below it by ``backlash_deg`` when coming from above
    (one more ``move_to``), and the driver adds its own approach overshoot inside each
    ``move_to``; each ``move_to`` waits the stage's settle time once.

    Returns
    -------
    motion_s : float
        Trapezoidal move time of every leg, seconds.
    moves : int
        ``move_to`` calls (each followed by the stage's settle time).
    end_deg : float
        Where the stage ends, degrees.
    """
    motion = 0.0
    moves = 0
    here = float(start_deg)
    for target in positions:
        for leg in plan_overshoot_legs(here, target, backlash_deg, rig.stage_min_deg):
            moves += 1
            for wp in approach_waypoints(here, leg, rig.approach, rig.approach_backlash_deg):
                motion += move_time(wp - here, rig.speed_dps, rig.accel_dps2)
                here = wp
    return motion, moves, here


def estimate_angles(
    positions: Sequence[float], start_deg: float, n_lights: int,
    plan: AnyPlan, rig: RigDescription, first_dark: bool,
) -> tuple[float, float, float]:
    """(motion, settle, exposure) seconds to visit ``positions`` from ``start_deg``."""
    ex = plan.exposure
    motion, moves, _ = travel(positions, start_deg, rig, plan.backlash_deg)
    settle = moves * rig.settle_s + len(positions) * n_lights * ex.light_settle_s
    per_exposure = ex.exposure_s * ex.averages
    darks = len(positions) if ex.dark == "every_angle" else (1 if first_dark else 0)
    exposure = (len(positions) * n_lights + darks) * per_exposure
    return motion, settle, exposure


def adaptive_bound(plan: AdaptivePlan, rig: RigDescription, n_pairs: int, n_lights: int,
                   first_angles: Sequence[float], end_deg: float) -> tuple[int, float]:
    """Most stage angles and seconds the refinement rounds after the first can add.

    The worst case of math.md 9: every round plans the midpoint of every gap (each measured
    angle's two neighbours) within the plan's arc (``first_span_deg``: over half a turn the
    last gap runs to the first angle plus 180 deg, and its midpoint stays in the arc, as the
    refinement rules plan it), as long as half a gap is at least ``min_step_deg``, for
    ``max_rounds - 1`` rounds, within the sample budget, the plan's ``max_rotations`` and
    :data:`MAX_ROTATIONS`. A subset
    of those midpoints travels no further along the same increasing route (move time is
    subadditive) and costs fewer settles and exposures, so the time is a bound too.

    Returns
    -------
    (extra_angles, extra_seconds)
    """
    min_step = plan.min_step_deg or rig.resolution_deg
    limit = MAX_ROTATIONS if plan.max_rotations is None else plan.max_rotations
    if plan.max_samples is not None:
        limit = min(limit, plan.max_samples // max(n_pairs, 1))
    period, arc_start = plan.first_span_deg(), plan.start_deg
    angles = [float(a) for a in first_angles]
    here = end_deg
    extra_angles = 0
    extra_s = 0.0
    ex = plan.exposure
    for _round in range(plan.max_rounds - 1):
        room = limit - len(angles)
        if room <= 0:
            break
        pos, gaps = arc_gaps(angles, period, arc_start)
        mids = [float(m) for m in arc_angle(pos + gaps / 2.0, period, arc_start)[
            gaps / 2.0 >= min_step]]
        if not mids:
            break
        route = order_for_travel(mids, here, rig, plan.backlash_deg)
        motion, moves, here = travel(route, here, rig, plan.backlash_deg)
        m = min(len(mids), room)
        per_angle = n_lights * (ex.light_settle_s + ex.exposure_s * ex.averages) + (
            ex.exposure_s * ex.averages if ex.dark == "every_angle" else 0.0)
        extra_s += motion + moves * rig.settle_s + m * per_angle
        extra_angles += m
        angles = angles + mids
    return extra_angles, extra_s
