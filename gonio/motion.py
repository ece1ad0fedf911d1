"""How a rotation stage moves: the move-time formula and the approach (backlash) rule.

The stage drivers move by these rules and the plans estimate with them, so a dry run replays
exactly the legs the hardware travels and times them with the profile the drivers poll by.

Gears and lead screws have play: where a stage comes to rest depends on the side it came from.
The stage driver owns that compensation (rig config ``stage.approach`` and
``stage.backlash_deg``, applied to every move, manual ones included): when a move would arrive
from the other side, the stage first overshoots the target by ``backlash_deg`` and then returns
(:func:`approach_waypoints`). A plan's ``backlash_deg`` (default 0) only asks the engine for an
extra overshoot below angles it approaches from above, by the same rule with the positive side.
"""

from __future__ import annotations

import math
from typing import Literal, get_args

Approach = Literal["positive", "negative", "none"]
"""Side a stage arrives at every target from: increasing angle, decreasing, or either."""
APPROACHES: tuple[str, ...] = get_args(Approach)

class StageMoveError(ValueError):
    """A manual stage move that cannot be made: no target angle, or one outside the stage's
    travel limits. Refused before anything moves; the message says what to send instead."""


# Below this distance a target counts as reached: no move, so no direction to correct.
_SAME_POSITION_DEG = 1e-6


def move_time(distance_deg: float, speed_dps: float, accel_dps2: float) -> float:
    """Duration of a rest-to-rest move with a trapezoidal (or triangular) velocity profile.

    Accelerate at ``accel_dps2`` to ``speed_dps``, cruise, decelerate.

    Parameters
    ----------
    distance_deg : float
        Length of the move, degrees (sign ignored).
    speed_dps : float
        Cruise speed, degrees per second (> 0).
    accel_dps2 : float
        Acceleration and deceleration, degrees per second squared (> 0).

    Returns
    -------
    float
        Seconds; a move too short to reach ``speed_dps`` is a triangle, ``2 sqrt(d / a)``.
    """
    d = abs(distance_deg)
    if d == 0.0:
        return 0.0
    if d >= speed_dps * speed_dps / accel_dps2:  # accelerate + decelerate distance
        return d / speed_dps + speed_dps / accel_dps2
    return 2.0 * math.sqrt(d / accel_dps2)


def approach_waypoints(
    current_deg: float, target_deg: float, approach: str, backlash_deg: float
) -> list[float]:
    """Positions to visit in order so that the last move ends on the configured side.

    Parameters
    ----------
    current_deg : float
        Present stage position, degrees.
    target_deg : float
        Requested position, degrees.
    approach : {"positive", "negative", "none"}
        "positive": the final move runs in the increasing-angle direction; "negative": in the
        decreasing direction; "none": go straight.
    backlash_deg : float
        Overshoot used when the direct move would arrive from the wrong side, degrees (>= 0).

    Returns
    -------
    list of float
        One waypoint (the target) or two (overshoot point, then the target), degrees.
    """
    if approach == "none" or backlash_deg <= 0:
        return [target_deg]
    delta = target_deg - current_deg
    if abs(delta) < _SAME_POSITION_DEG:
        return [target_deg]
    if approach == "positive":
        return [target_deg] if delta > 0 else [target_deg - backlash_deg, target_deg]
    return [target_deg] if delta < 0 else [target_deg + backlash_deg, target_deg]


def plan_overshoot_legs(
    current_deg: float, target_deg: float, backlash_deg: float, min_deg: float
) -> list[float]:
    """The engine's ``move_to`` targets for a plan's extra ``backlash_deg`` overshoot.

    The positive-side rule of :func:`approach_waypoints`, with the overshoot point held at the
    lower travel limit ``min_deg`` rather than refused (the driver's own approach still
    applies inside each ``move_to``).

    Returns
    -------
    list of float
        ``[target_deg]``, or ``[overshoot, target_deg]`` when coming from above, degrees.
    """
    legs = approach_waypoints(current_deg, target_deg, "positive", backlash_deg)
    return [max(min_deg, leg) for leg in legs[:-1]] + [target_deg]
