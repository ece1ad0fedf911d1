"""Scan plans as serializable data, their validation against a rig, and their expansion.

A plan says *what* to measure (which pairs, at which stage angles, with which exposure); the
engine (:mod:`gonio.engine`) says *how*. Plans are pydantic models, so they travel unchanged
through the REST API, the job store (as JSON) and result files.

Three kinds, told apart by ``kind``:

``uniform``
    The rig's pairs at ``rotations`` stage angles ``start_deg + k 360 / rotations``.
``adaptive``
    V&F Sec. 6 / MATH 7: start with ``initial_rotations`` uniform angles, then add the midpoints
    around every angle where leave-one-out periodic PCHIP mispredicts a pair's value by more
    than ``threshold``; repeat until nothing exceeds it, the sample budget is spent, or a new
    step would be finer than ``min_step_deg``.
``calibration``
    A white reference of known albedo (a Lambertian reference has ``f = albedo / pi``) at a few
    angles; the result is each pair's factor from sensor counts to BRDF (:mod:`gonio.calibration`).

Angles are degrees here (plans are user-facing). A plan's angles are specimen rotations in
``[0, 360)``; :func:`order_for_travel` maps them to stage positions inside the travel limits,
all approached in the positive direction so backlash cancels.

Every check a plan can fail raises :class:`PlanError` before anything moves.
"""

from __future__ import annotations

import math
import unicodedata
from collections.abc import Sequence
from typing import Annotated, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from gonio import hal


class PlanError(ValueError):
    """A plan that cannot run on this rig; the message says what is wrong and what to do."""


# --------------------------------------------------------------------------- input types
def check_text(value: str) -> str:
    """Refuse text that cannot be stored, written to HDF5 or shown: control characters
    (NUL included) and lone surrogates. Returns ``value`` unchanged.

    Names travel into SQLite, HDF5 attributes (which cannot hold NUL), file names of exports
    and log lines; refusing them at the door means a scan is never measured and then lost.
    """
    for i, ch in enumerate(value):
        cat = unicodedata.category(ch)
        if cat == "Cc":
            raise ValueError(
                f"contains the control character U+{ord(ch):04X} at position {i}; "
                "use printable text only"
            )
        if cat == "Cs":
            raise ValueError(
                f"contains a lone surrogate U+{ord(ch):04X} at position {i} (not valid "
                "Unicode text); send the name as valid UTF-8"
            )
    return value


Text = Annotated[str, AfterValidator(check_text)]
"""A user-supplied name or label: printable Unicode, no control characters."""

Count = Annotated[int, Field(strict=True)]
"""An integer that must be sent as one: JSON ``true`` or ``8.0`` is not a count."""

FINITE = ConfigDict(extra="forbid", allow_inf_nan=False)
"""Config of every request model: unknown keys and NaN / Infinity (JSON 1e999) refused."""


MAX_ROTATIONS = 3600
"""Most stage angles one job may measure (0.1 degree steps; V&F use 8 to 72). Caps the work
a plan costs to check and time, and the readings an adaptive plan can grow to."""


# --------------------------------------------------------------------------- rig description
class SensorInfo(BaseModel):
    """What a plan needs to know about one sensor."""

    model_config = ConfigDict(frozen=True)

    name: str
    theta_deg: float
    phi_deg: float
    channels: tuple[str, ...]
    min_exposure_s: float = 1e-4
    max_exposure_s: float = 10.0


class LightInfo(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    theta_deg: float
    phi_deg: float


class PairSpec(BaseModel):
    """A light/sensor pair by device name."""

    model_config = ConfigDict(frozen=True)

    light: Text
    sensor: Text

    def label(self) -> str:
        return f"{self.light}/{self.sensor}"


class RigDescription(BaseModel):
    """The static facts about a rig that plans are checked and timed against (no hardware).

    Built from a :class:`gonio.hal.Rig` with :meth:`from_rig` (attributes only: nothing is
    connected or moved). Stored with each job as its rig snapshot.
    """

    model_config = ConfigDict(frozen=True)

    stage_min_deg: float
    stage_max_deg: float
    speed_dps: float = Field(gt=0)
    accel_dps2: float = Field(gt=0)
    settle_s: float = Field(default=0.0, ge=0)
    resolution_deg: float = Field(default=0.01, gt=0)
    approach: Literal["positive", "negative", "none"] = Field(
        default="none", description="side the stage driver approaches every target from")
    approach_backlash_deg: float = Field(
        default=0.0, ge=0, description="the driver's overshoot when a move arrives from the "
        "other side, degrees")
    lights: tuple[LightInfo, ...]
    sensors: tuple[SensorInfo, ...]
    pairs: tuple[PairSpec, ...]

    @classmethod
    def from_rig(cls, rig: hal.Rig) -> RigDescription:
        s = rig.stage
        return cls(
            stage_min_deg=s.limits.min_deg,
            stage_max_deg=s.limits.max_deg,
            speed_dps=s.speed_dps,
            accel_dps2=s.accel_dps2,
            settle_s=s.settle_s,
            resolution_deg=s.resolution_deg,
            approach=getattr(s, "approach", "none"),
            approach_backlash_deg=float(getattr(s, "backlash_deg", 0.0)),
            lights=tuple(
                LightInfo(name=n, theta_deg=lt.direction.theta_deg, phi_deg=lt.direction.phi_deg)
                for n, lt in rig.lights.items()
            ),
            sensors=tuple(
                SensorInfo(
                    name=n,
                    theta_deg=se.direction.theta_deg,
                    phi_deg=se.direction.phi_deg,
                    channels=tuple(se.channels),
                    min_exposure_s=se.min_exposure_s,
                    max_exposure_s=se.max_exposure_s,
                )
                for n, se in rig.sensors.items()
            ),
            pairs=tuple(PairSpec(light=p.light, sensor=p.sensor) for p in rig.pairs),
        )

    def sensor(self, name: str) -> SensorInfo:
        for s in self.sensors:
            if s.name == name:
                return s
        raise PlanError(f"the rig has no sensor named {name!r}")

    def light(self, name: str) -> LightInfo:
        for lt in self.lights:
            if lt.name == name:
                return lt
        raise PlanError(f"the rig has no light named {name!r}")


# --------------------------------------------------------------------------- plan models
class ExposureSettings(BaseModel):
    """How each reading is taken.

    ``exposure_s`` is the integration time of one exposure, ``averages`` how many exposures are
    averaged; ``light_settle_s`` is the wait after switching a light on (lamp warm-up and
    stabilisation). ``dark`` chooses when sensors are read with every light off: at every stage
    angle (tracks drifting dark signal, costs one exposure per angle), once at the start, or
    never (the sensors subtract their own dark).
    """

    model_config = FINITE

    exposure_s: float = Field(default=0.01, gt=0, description="seconds per exposure")
    averages: Count = Field(default=1, ge=1, le=1000)
    light_settle_s: float = Field(default=0.05, ge=0, le=60)
    dark: Literal["every_angle", "once", "none"] = "once"


class FaultPolicy(BaseModel):
    """How the engine suspends and retries on recoverable device faults.

    After a fault the engine waits ``retry_delay_s``, tries the device's recovery (clear
    faults, reconnect, re-check the lamp), waits ``resume_settle_s`` and repeats the
    interrupted angle. More than ``max_retries`` consecutive failures at one angle fail the job,
    except for a device that does not answer at all: the job then stays suspended and the
    device is tried every ``retry_delay_s`` until it answers (then the angle is repeated from
    the checkpoint) or ``wait_for_device_s`` have passed since the first fault.
    """

    model_config = FINITE

    max_retries: Count = Field(default=5, ge=0, le=100)
    retry_delay_s: float = Field(default=1.0, ge=0, le=3600)
    wait_for_device_s: float = Field(
        default=600.0, ge=0, le=86400,
        description="when a device stops answering (unplugged cable, power cut) and the "
                    "retries are spent, keep the job suspended and try the device every "
                    "retry_delay_s until it answers again, up to this many seconds from the "
                    "first fault; then the job fails. 0: fail after max_retries",
    )
    resume_settle_s: float = Field(default=0.5, ge=0, le=3600)
    saturation: Literal["suspend", "record"] = Field(
        default="suspend",
        description="'suspend': a saturated reading is a fault and the angle is retried; "
        "'record': keep it, flagged saturated",
    )


def _check_start(value: float) -> float:
    if not 0.0 <= value < 360.0:
        raise ValueError(
            f"start_deg is a specimen angle in [0, 360) degrees; {value:g} is outside (it is "
            f"not wrapped silently). For the same angle write {value % 360.0:g}"
        )
    return value


StartDeg = Annotated[
    float,
    AfterValidator(_check_start),
    Field(description="first specimen angle, degrees in [0, 360); values outside are refused, "
                      "not wrapped"),
]


class _PlanBase(BaseModel):
    model_config = FINITE

    specimen: Text = Field(default="specimen", min_length=1, max_length=200)
    pairs: list[PairSpec] | None = Field(
        default=None, description="pairs to measure; null means every pair of the rig"
    )
    exposure: ExposureSettings = Field(default_factory=ExposureSettings)
    faults: FaultPolicy = Field(default_factory=FaultPolicy)
    backlash_deg: float = Field(
        default=0.0,
        ge=0,
        le=90,
        description="extra overshoot below an angle approached from above (0: rely on the "
        "stage driver's own approach setting)",
    )
    stop_queue_on_failure: bool = False


class UniformPlan(_PlanBase):
    """n pairs x r uniformly spaced stage angles."""

    kind: Literal["uniform"] = "uniform"
    rotations: Count = Field(default=8, description="number of stage angles r")
    start_deg: StartDeg = 0.0


class AdaptivePlan(_PlanBase):
    """Uniform start, then refinement where PCHIP mispredicts (MATH 7)."""

    kind: Literal["adaptive"] = "adaptive"
    initial_rotations: Count = Field(default=8,
                                     description="r0 uniform angles of the first round")
    threshold: float = Field(default=0.1, gt=0, description="relative error e (0.1 = 10 %)")
    max_samples: Count | None = Field(
        default=None, gt=0, description="budget of pair readings (pairs x angles); null = none"
    )
    min_step_deg: float | None = Field(
        default=None, gt=0, description="finest angular step; null = the stage resolution"
    )
    max_rounds: Count = Field(default=6, ge=1, le=20)
    start_deg: StartDeg = 0.0


class CalibrationPlan(_PlanBase):
    """A white reference of known albedo measured at a few angles."""

    kind: Literal["calibration"] = "calibration"
    reference_albedo: float = Field(gt=0, le=1, description="hemispherical albedo of the reference")
    reference_name: Text = Field(default="white reference", min_length=1, max_length=200)
    rotations: Count = Field(default=4, description="angles averaged to even out the reference")
    start_deg: StartDeg = 0.0


Plan = Annotated[UniformPlan | AdaptivePlan | CalibrationPlan, Field(discriminator="kind")]


class _PlanHolder(BaseModel):
    plan: Plan


def parse_plan(data: object) -> UniformPlan | AdaptivePlan | CalibrationPlan:
    """Validate a plan from JSON-like data (``dict`` or JSON ``str``); raises :class:`PlanError`."""
    from pydantic import ValidationError

    try:
        if isinstance(data, str | bytes):
            return _PlanHolder.model_validate_json(b'{"plan": ' + _as_bytes(data) + b"}").plan
        return _PlanHolder.model_validate({"plan": data}).plan
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'][1:]) or 'plan'}: {e['msg']}" for e in exc.errors()
        )
        raise PlanError(f"invalid plan: {problems}") from None


def _as_bytes(s: str | bytes) -> bytes:
    return s.encode() if isinstance(s, str) else s


AnyPlan = UniformPlan | AdaptivePlan | CalibrationPlan


# --------------------------------------------------------------------------- validation
def plan_pairs(plan: AnyPlan, rig: RigDescription) -> list[PairSpec]:
    """The pairs a plan measures, checked against the rig. Raises :class:`PlanError`."""
    pairs = list(rig.pairs) if plan.pairs is None else list(plan.pairs)
    if not pairs:
        raise PlanError(
            "the plan measures no pairs: the rig config defines no light/sensor pairs and the "
            "plan lists none; add pairs to the rig config or to the plan"
        )
    known = set(rig.pairs)
    seen: set[PairSpec] = set()
    for p in pairs:
        if p not in known:
            raise PlanError(
                f"pair {p.label()} is not one of the rig's pairs "
                f"({', '.join(q.label() for q in rig.pairs) or 'none'})"
            )
        if p in seen:
            raise PlanError(f"pair {p.label()} is listed twice in the plan; list each pair once")
        seen.add(p)
    return pairs


def _rotation_count(plan: AnyPlan) -> int:
    if isinstance(plan, AdaptivePlan):
        return plan.initial_rotations
    return plan.rotations


def _uniform(start_deg: float, r: int) -> list[float]:
    return [float((start_deg + k * 360.0 / r) % 360.0) for k in range(r)]


def initial_angles(plan: AnyPlan, rig: RigDescription) -> list[float]:
    """Specimen angles (degrees in [0, 360)) of the plan's first round, validated."""
    validate_plan(plan, rig)
    return _uniform(plan.start_deg, _rotation_count(plan))


def validate_plan(plan: AnyPlan, rig: RigDescription) -> None:
    """Check everything that can be checked without hardware; raise :class:`PlanError`.

    Checks: pairs exist and are unique; at least one rotation; no two angles closer than the
    stage resolution (duplicates); every angle reachable inside the travel limits; exposure
    inside every used sensor's range; adaptive settings consistent.
    """
    pairs = plan_pairs(plan, rig)
    r = _rotation_count(plan)
    name = "initial_rotations" if isinstance(plan, AdaptivePlan) else "rotations"
    if r < 1:
        raise PlanError(f"{name} is {r}; a scan needs at least one stage angle (e.g. {name}=8)")
    if isinstance(plan, AdaptivePlan) and r < 3:
        raise PlanError(
            f"initial_rotations is {r}; adaptive refinement predicts each angle from its "
            "neighbours and needs at least 3 (the paper uses 8)"
        )
    step = 360.0 / r
    if step < rig.resolution_deg:
        raise PlanError(
            f"{r} rotations are {step:.4g} deg apart, finer than the stage resolution "
            f"{rig.resolution_deg:g} deg, so several would land on the same position "
            "(duplicate angles); use fewer rotations"
        )
    if r > MAX_ROTATIONS:
        raise PlanError(
            f"{name} is {r}; a job measures at most {MAX_ROTATIONS} stage angles (0.1 degree "
            f"steps). The paper's scans use 8 to 72; use {MAX_ROTATIONS} or fewer"
        )
    angles = _uniform(plan.start_deg, r)
    for a in angles:
        if not _representatives(a, rig, margin=0.0):
            raise PlanError(
                f"stage angle {a:g} deg (start_deg {plan.start_deg:g} + multiples of "
                f"{step:g} deg) is outside the stage travel [{rig.stage_min_deg:g}, "
                f"{rig.stage_max_deg:g}] deg; choose a start angle or rotation count whose "
                "angles fit the travel, or widen the limits in the rig config"
            )
    ex = plan.exposure
    for sname in sorted({p.sensor for p in pairs}):
        s = rig.sensor(sname)
        if not s.min_exposure_s <= ex.exposure_s <= s.max_exposure_s:
            raise PlanError(
                f"exposure {ex.exposure_s:g} s is outside sensor {sname!r}'s range "
                f"[{s.min_exposure_s:g}, {s.max_exposure_s:g}] s; choose an exposure in range"
            )
    if isinstance(plan, AdaptivePlan):
        min_step = plan.min_step_deg or rig.resolution_deg
        if min_step < rig.resolution_deg:
            raise PlanError(
                f"min_step_deg {min_step:g} is finer than the stage resolution "
                f"{rig.resolution_deg:g} deg; use at least the resolution"
            )
        if plan.max_samples is not None and plan.max_samples < len(pairs) * r:
            raise PlanError(
                f"max_samples {plan.max_samples} is smaller than the first round alone "
                f"({len(pairs)} pairs x {r} angles = {len(pairs) * r}); raise the budget or "
                "lower initial_rotations"
            )


# --------------------------------------------------------------------------- ordering
def _representatives(angle_deg: float, rig: RigDescription, margin: float) -> list[float]:
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


def move_time(distance_deg: float, speed_dps: float, accel_dps2: float) -> float:
    """Duration of a trapezoidal (or triangular) move, seconds.

    Accelerate at ``accel_dps2`` to ``speed_dps``, cruise, decelerate; a short move that
    never reaches full speed is a triangle: ``2 sqrt(d / a)``.
    """
    d = abs(distance_deg)
    if d == 0:
        return 0.0
    d_ramp = speed_dps**2 / accel_dps2  # accelerate + decelerate distance
    if d >= d_ramp:
        return d / speed_dps + speed_dps / accel_dps2
    return 2.0 * math.sqrt(d / accel_dps2)


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
        for first in _representatives(base[s], rig, margin=0.0):
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


# --------------------------------------------------------------------------- adaptive
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


# --------------------------------------------------------------------------- dry run
class DryRun(BaseModel):
    """What a plan will do, without hardware: the first round's stage positions and timing.

    The estimate is the physical time of every move the engine and the stage driver make
    (from the stage's present position, with the engine's and the driver's backlash
    approaches), settling and exposures. For adaptive plans only the first round is known in
    advance; ``estimated_s`` covers it and ``max_estimated_s`` bounds the whole job: every
    refinement round adding a midpoint in every gap, until ``max_rounds``, ``min_step_deg``,
    ``max_samples`` or the cap of stage angles stops it.
    """

    kind: str
    pairs: list[PairSpec]
    lights: list[str]
    angles_deg: list[float] = Field(description="specimen angles of the first round")
    positions_deg: list[float] = Field(description="stage positions in visiting order")
    readings: int = Field(description="pair readings of the first round")
    exposures: int = Field(description="sensor exposures per round, dark included")
    motion_s: float
    settle_s: float
    exposure_s: float
    estimated_s: float
    max_estimated_s: float | None = Field(
        default=None, description="adaptive plans: bound on the whole job's duration, seconds")
    max_angles: int | None = Field(
        default=None, description="adaptive plans: most stage angles the job can measure")
    from_deg: float = Field(default=0.0, description="stage position the estimate starts from")
    from_known: bool = Field(
        default=False, description="false: the stage position is not known yet (no job or "
        "manual move since the daemon started) and 0 deg was assumed")


def lights_in_order(pairs: Sequence[PairSpec]) -> list[str]:
    """Lights of the pairs in first-appearance order (one exposure per light and angle)."""
    out: list[str] = []
    for p in pairs:
        if p.light not in out:
            out.append(p.light)
    return out


def _driver_waypoints(here: float, target: float, rig: RigDescription) -> list[float]:
    """Where the stage driver goes to reach ``target`` from ``here`` (its approach side).

    The same rule as ``gonio.drivers._backlash.approach_waypoints`` (drivers are not imported
    here): a move arriving from the wrong side first overshoots by the driver's backlash.
    """
    delta = target - here
    b = rig.approach_backlash_deg
    if rig.approach == "none" or b <= 0 or abs(delta) < 1e-6:
        return [target]
    if rig.approach == "positive":
        return [target] if delta > 0 else [target - b, target]
    return [target] if delta < 0 else [target + b, target]


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
        legs = []
        if backlash_deg > 0 and target < here - 1e-6:
            legs.append(max(rig.stage_min_deg, target - backlash_deg))
        legs.append(target)
        for leg in legs:
            moves += 1
            for wp in _driver_waypoints(here, leg, rig):
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

    The worst case of MATH 7: every round plans the midpoint of every gap (each measured
    angle's two neighbours), as long as half a gap is at least ``min_step_deg``, for
    ``max_rounds - 1`` rounds, within the sample budget and :data:`MAX_ROTATIONS`. A subset
    of those midpoints travels no further along the same increasing route (move time is
    subadditive) and costs fewer settles and exposures, so the time is a bound too.

    Returns
    -------
    (extra_angles, extra_seconds)
    """
    min_step = plan.min_step_deg or rig.resolution_deg
    limit = MAX_ROTATIONS
    if plan.max_samples is not None:
        limit = min(limit, plan.max_samples // max(n_pairs, 1))
    angles = sorted(a % 360.0 for a in first_angles)
    here = end_deg
    extra_angles = 0
    extra_s = 0.0
    ex = plan.exposure
    for _round in range(plan.max_rounds - 1):
        room = limit - len(angles)
        if room <= 0:
            break
        gaps = [((angles[(j + 1) % len(angles)] - a) % 360.0 or 360.0, a)
                for j, a in enumerate(angles)]
        mids = [(a + g / 2.0) % 360.0 for g, a in gaps if g / 2.0 >= min_step]
        if not mids:
            break
        route = order_for_travel(mids, here, rig, plan.backlash_deg)
        motion, moves, here = travel(route, here, rig, plan.backlash_deg)
        m = min(len(mids), room)
        per_angle = n_lights * (ex.light_settle_s + ex.exposure_s * ex.averages) + (
            ex.exposure_s * ex.averages if ex.dark == "every_angle" else 0.0)
        extra_s += motion + moves * rig.settle_s + m * per_angle
        extra_angles += m
        angles = sorted(angles + mids)
    return extra_angles, extra_s


def dry_run(plan: AnyPlan, rig: RigDescription, current_deg: float | None = None) -> DryRun:
    """Expand ``plan`` on ``rig`` and estimate its duration; raises :class:`PlanError`.

    The estimate is the physical time (see :class:`DryRun`): trapezoidal stage moves at the
    rig's speed and acceleration for every leg (from ``current_deg``, the engine's backlash
    overshoot and the driver's approach), the stage settle time after each move, each
    light's settle time, and one ``exposure_s x averages`` per light and angle (all sensors
    of a light read in parallel), plus dark exposures. Communication overhead is not
    included (a few percent: docs/engine.md).

    Parameters
    ----------
    plan, rig
    current_deg : float, optional
        Present stage position, degrees; None when unknown (0 is assumed and the result says
        so).
    """
    validate_plan(plan, rig)
    pairs = plan_pairs(plan, rig)
    lights = lights_in_order(pairs)
    angles = _uniform(plan.start_deg, _rotation_count(plan))
    start = 0.0 if current_deg is None else float(current_deg)
    route = order_for_travel(angles, start, rig, plan.backlash_deg)
    motion, settle, exposure = estimate_angles(
        route, start, len(lights), plan, rig, plan.exposure.dark != "none"
    )
    total = motion + settle + exposure
    max_total = max_angles = None
    if isinstance(plan, AdaptivePlan):
        _, _, end = travel(route, start, rig, plan.backlash_deg)
        extra_n, extra_s = adaptive_bound(plan, rig, len(pairs), len(lights), angles, end)
        max_total, max_angles = total + extra_s, len(route) + extra_n
    darks = len(route) if plan.exposure.dark == "every_angle" else int(plan.exposure.dark == "once")
    return DryRun(
        kind=plan.kind,
        pairs=pairs,
        lights=lights,
        angles_deg=angles,
        positions_deg=route,
        readings=len(pairs) * len(route),
        exposures=len(route) * len(lights) + darks,
        motion_s=motion,
        settle_s=settle,
        exposure_s=exposure,
        estimated_s=total,
        max_estimated_s=max_total,
        max_angles=max_angles,
        from_deg=start,
        from_known=current_deg is not None,
    )
