"""Physics of a simulated rotation stage: trapezoidal velocity profiles in "sim time".

Sim time is wall time multiplied by ``time_scale``, so a test can run a 30 degree move at 30
deg/s in a fraction of a second of wall time while every speed and acceleration keeps its
physical meaning. Everything is evaluated lazily from the current time: there is no physics
thread, a query computes the state of the running profile at that instant.

A move is a list of constant-acceleration phases starting from the state (position, velocity)
at the moment it was commanded, so a new target during a move blends smoothly: the stage keeps
its velocity, and brakes first when the new target lies behind it or too close to stop in time.

Fault hooks: :meth:`StageMotion.arm_stall` makes the next move stop dead part-way (a blockage),
:meth:`StageMotion.arm_overload` makes it trip part-way (the device model then reports a
hardware error and drops torque). Both are abrupt stops at a fraction of the planned distance.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

_EPS = 1e-9


@dataclass(frozen=True)
class _Phase:
    t0: float  # sim time the phase starts, s
    duration: float  # s
    p0: float  # position at t0, deg
    v0: float  # velocity at t0, deg/s
    a: float  # constant acceleration, deg/s^2

    def at(self, t: float) -> tuple[float, float]:
        dt = min(max(t - self.t0, 0.0), self.duration)
        return self.p0 + self.v0 * dt + 0.5 * self.a * dt * dt, self.v0 + self.a * dt


def plan_phases(
    p0: float, v0: float, target: float, vmax: float, amax: float
) -> list[tuple[float, float]]:
    """Constant-acceleration phases that bring a stage from (p0, v0) to rest at ``target``.

    Parameters
    ----------
    p0 : float
        Start position, degrees.
    v0 : float
        Start velocity, degrees per second (signed).
    target : float
        Target position, degrees.
    vmax : float
        Velocity limit, degrees per second (> 0).
    amax : float
        Acceleration and deceleration limit, degrees per second squared (> 0).

    Returns
    -------
    list of (duration_s, acceleration_dps2)
        Phases to run in order; empty when already at rest on the target.
    """
    d = target - p0
    if abs(d) < _EPS and abs(v0) < _EPS:
        return []
    if abs(v0) > _EPS:
        s = math.copysign(1.0, v0)
        stop_d = v0 * v0 / (2.0 * amax)
        # Moving away from the target, unable to stop before it, or faster than the new limit:
        # brake to rest first, then plan from there.
        # No tolerance on the stopping distance: a slow creep whose overshoot is tiny must
        # still brake and come back, or the plan ends with the leftover speed.
        if d * s < 0 or abs(d) < stop_d or abs(v0) > vmax + _EPS:
            brake = (abs(v0) / amax, -s * amax)
            return [brake, *plan_phases(p0 + s * stop_d, 0.0, target, vmax, amax)]
    s = math.copysign(1.0, d) if abs(d) > _EPS else math.copysign(1.0, v0)
    D, u = abs(d), abs(v0)
    vp = min(vmax, math.sqrt(amax * D + 0.5 * u * u))
    t_acc = max(vp - u, 0.0) / amax
    d_acc = (vp * vp - u * u) / (2.0 * amax)
    t_dec = vp / amax
    d_dec = vp * vp / (2.0 * amax)
    d_cruise = max(D - d_acc - d_dec, 0.0)
    t_cruise = d_cruise / vp if vp > _EPS else 0.0
    return [(t_acc, s * amax), (t_cruise, 0.0), (t_dec, -s * amax)]


class StageMotion:
    """Thread-safe trapezoidal-profile model of a rotation stage.

    Parameters
    ----------
    speed_dps : float
        Travel speed limit, degrees per second.
    accel_dps2 : float
        Acceleration and deceleration, degrees per second squared.
    settle_s : float
        Sim time after the profile ends during which the stage still counts as moving
        (mechanical ringing), seconds.
    time_scale : float
        Sim seconds per wall second (e.g. 20 runs physics 20x faster than real time).
    initial_deg : float
        Position at creation, degrees.
    clock : callable
        Wall clock in seconds (tests pass a fake one to step time exactly).
    """

    def __init__(
        self,
        speed_dps: float = 30.0,
        accel_dps2: float = 60.0,
        settle_s: float = 0.05,
        time_scale: float = 1.0,
        initial_deg: float = 0.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if time_scale <= 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self._lock = threading.RLock()
        self._speed = self._check_positive("speed_dps", speed_dps)
        self._accel = self._check_positive("accel_dps2", accel_dps2)
        self.settle_s = float(settle_s)
        self.time_scale = float(time_scale)
        self._clock = clock
        self._wall0 = clock()
        self._rest_pos = float(initial_deg)
        self._phases: list[_Phase] = []
        self._end_t = -math.inf
        self._cut: tuple[str, float] | None = None  # (kind, sim time) of an armed abrupt stop
        self._armed: tuple[str, float] | None = None  # (kind, fraction) for the next move
        self._stalled = False
        self._overloaded = False

    @staticmethod
    def _check_positive(name: str, value: float) -> float:
        if not value > 0:
            raise ValueError(f"{name} must be > 0, got {value}")
        return float(value)

    # ------------------------------------------------------------------ time and state
    def now(self) -> float:
        """Current sim time, seconds since creation."""
        return (self._clock() - self._wall0) * self.time_scale

    def _state(self, t: float) -> tuple[float, float]:
        if self._cut is not None and t >= self._cut[1]:
            return self._eval(self._cut[1])[0], 0.0
        return self._eval(t)

    def _eval(self, t: float) -> tuple[float, float]:
        if not self._phases or t >= self._end_t:
            return self._rest_pos, 0.0
        for ph in self._phases:
            if t < ph.t0 + ph.duration:
                return ph.at(t)
        return self._rest_pos, 0.0

    def _settle_faults(self, t: float) -> None:
        """Turn a passed abrupt stop into the resting state and its fault flag."""
        if self._cut is not None and t >= self._cut[1]:
            kind, t_cut = self._cut
            self._rest_pos = self._eval(t_cut)[0]
            self._phases = []
            self._end_t = t_cut
            self._cut = None
            if kind == "stall":
                self._stalled = True
            else:
                self._overloaded = True

    def position_deg(self) -> float:
        """Present position, degrees."""
        with self._lock:
            t = self.now()
            self._settle_faults(t)
            return self._state(t)[0]

    def velocity_dps(self) -> float:
        """Present velocity, degrees per second (signed)."""
        with self._lock:
            t = self.now()
            self._settle_faults(t)
            return self._state(t)[1]

    def is_moving(self) -> bool:
        """True while a profile runs and until it has settled."""
        with self._lock:
            t = self.now()
            self._settle_faults(t)
            return t < self._end_t + self.settle_s

    def target_deg(self) -> float:
        """Where the running (or last) profile ends, degrees."""
        with self._lock:
            return self._phases[-1].at(math.inf)[0] if self._phases else self._rest_pos

    # ------------------------------------------------------------------ commands
    def set_speed(self, dps: float) -> None:
        """Speed limit for the next move, degrees per second."""
        with self._lock:
            self._speed = self._check_positive("speed_dps", dps)

    def set_accel(self, dps2: float) -> None:
        """Acceleration for the next move, degrees per second squared."""
        with self._lock:
            self._accel = self._check_positive("accel_dps2", dps2)

    @property
    def speed_dps(self) -> float:
        return self._speed

    @property
    def accel_dps2(self) -> float:
        return self._accel

    def move_to(self, deg: float) -> None:
        """Start (or re-target) a move to ``deg`` degrees from the present state."""
        with self._lock:
            t = self.now()
            self._settle_faults(t)
            if self._overloaded:
                return  # no torque: the motor cannot move until the fault is reset
            p, v = self._state(t)
            self._stalled = False
            self._start(t, p, v, float(deg))
            armed, self._armed = self._armed, None
            if armed is not None and self._phases:
                kind, fraction = armed
                self._cut = (kind, self._time_at_fraction(p, float(deg), fraction))

    def _start(self, t: float, p: float, v: float, target: float) -> None:
        self._phases = []
        self._cut = None
        tt, pp, vv = t, p, v
        for duration, a in plan_phases(p, v, target, self._speed, self._accel):
            ph = _Phase(tt, duration, pp, vv, a)
            self._phases.append(ph)
            pp, vv = ph.at(math.inf)
            tt += duration
        self._rest_pos = target
        # A command to where the stage already rests moves nothing, so it starts no ringing
        # (a ringing from the previous move goes on to its end): only a move rings.
        self._end_t = tt if self._phases else min(self._end_t, t)

    def _time_at_fraction(self, start: float, target: float, fraction: float) -> float:
        """Sim time at which the running profile has covered ``fraction`` of the distance."""
        goal = start + fraction * (target - start)
        lo, hi = self._phases[0].t0, self._end_t
        sign = math.copysign(1.0, target - start)
        for _ in range(60):  # bisection: the profile is monotonic once braking is done
            mid = 0.5 * (lo + hi)
            if (self._eval(mid)[0] - goal) * sign < 0:
                lo = mid
            else:
                hi = mid
        return hi

    def stop(self) -> None:
        """Decelerate to rest at the configured acceleration."""
        with self._lock:
            t = self.now()
            self._settle_faults(t)
            p, v = self._state(t)
            if abs(v) < _EPS:
                if self._phases and t < self._end_t:
                    self._rest_pos, self._phases, self._end_t = p, [], t
                return
            self._start(t, p, v, p + math.copysign(v * v / (2.0 * self._accel), v))

    def halt(self) -> None:
        """Stop dead (torque removed); used by device models on emergency stops and trips."""
        with self._lock:
            t = self.now()
            self._settle_faults(t)
            p, _ = self._state(t)
            self._rest_pos, self._phases, self._end_t, self._cut = p, [], t, None

    # ------------------------------------------------------------------ fault hooks
    def arm_stall(self, fraction: float = 0.5) -> None:
        """Make the next move stop dead after ``fraction`` of its distance."""
        with self._lock:
            self._armed = ("stall", fraction)

    def arm_overload(self, fraction: float = 0.5) -> None:
        """Make the next move trip an overload after ``fraction`` of its distance."""
        with self._lock:
            self._armed = ("overload", fraction)

    def overload_now(self) -> None:
        """Trip an overload immediately (the stage stops dead)."""
        with self._lock:
            self.halt()
            self._overloaded = True

    def stalled(self) -> bool:
        """True when the last move stopped short of its target; cleared by the next move."""
        with self._lock:
            self._settle_faults(self.now())
            return self._stalled

    def overloaded(self) -> bool:
        """True after an overload trip, until :meth:`reset_overload`."""
        with self._lock:
            self._settle_faults(self.now())
            return self._overloaded

    def reset_overload(self) -> None:
        """Clear an overload trip (the device was rebooted or its driver re-enabled)."""
        with self._lock:
            self._overloaded = False
