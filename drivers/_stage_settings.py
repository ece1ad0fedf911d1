"""Checks of the motion settings and targets every stage driver takes alike.

The motion rules themselves (move time, approach side and backlash overshoot) are
:mod:`gonio.motion`, shared with the plans that estimate a scan's duration.
"""

from __future__ import annotations

import math

from gonio.hal import TravelLimits
from gonio.motion import APPROACHES


def check_motion_settings(
    device: str,
    *,
    limits: TravelLimits,
    speed_dps: float,
    accel_dps2: float,
    approach: str,
    backlash_deg: float,
    move_timeout_s: float,
    retries: int,
    poll_interval_s: float,
) -> None:
    """Validate the settings every stage driver takes alike.

    Raises
    ------
    ValueError
        Naming the device, the setting and the value.
    """
    for what, value in (("speed_dps", speed_dps), ("accel_dps2", accel_dps2)):
        if not math.isfinite(value) or value <= 0:
            raise ValueError(f"{device}: {what} must be > 0, got {value}")
    if limits.min_deg >= limits.max_deg:
        raise ValueError(f"{device}: travel limits need min_deg < max_deg, got {limits}")
    check_approach(device, approach, backlash_deg)
    if not move_timeout_s > 0 or retries < 1:
        raise ValueError(
            f"{device}: move_timeout_s must be > 0 and retries >= 1, got {move_timeout_s} and "
            f"{retries}"
        )
    if not poll_interval_s > 0:
        raise ValueError(f"{device}: poll_interval_s must be > 0 seconds, got {poll_interval_s}")


def check_approach(device: str, approach: str, backlash_deg: float) -> None:
    """Validate the approach settings of a stage config.

    Raises
    ------
    ValueError
        With a message naming the device and the allowed values.
    """
    if approach not in APPROACHES:
        raise ValueError(
            f"{device}: approach must be one of {', '.join(APPROACHES)}, got {approach!r}"
        )
    if not math.isfinite(backlash_deg) or backlash_deg < 0:
        raise ValueError(f"{device}: backlash_deg must be a number >= 0, got {backlash_deg}")


def check_target(
    device: str, limits: TravelLimits, target_deg: float, waypoints: list[float]
) -> None:
    """Refuse a target (or its overshoot point) outside the travel limits, before moving.

    Raises
    ------
    ValueError
        Saying which position is out of range and what the limits are.
    """
    if not math.isfinite(target_deg):
        raise ValueError(f"{device}: target angle must be a finite number, got {target_deg}")
    if not limits.contains(target_deg):
        raise ValueError(
            f"{device}: target {target_deg:g} deg is outside the travel limits "
            f"[{limits.min_deg:g}, {limits.max_deg:g}] deg of the rig config"
        )
    for wp in waypoints:
        if not limits.contains(wp):
            raise ValueError(
                f"{device}: reaching {target_deg:g} deg from the configured approach side needs "
                f"an overshoot to {wp:g} deg, outside the travel limits "
                f"[{limits.min_deg:g}, {limits.max_deg:g}] deg; widen the limits, reduce "
                "backlash_deg or choose a target further from the limit"
            )
