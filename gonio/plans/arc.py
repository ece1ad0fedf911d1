"""The arc from the data: which stage angles test twofold symmetry, and what the test says.

A plan with ``arc = "auto"`` (:mod:`gonio.plans.models`) does not commit to half a turn
before it knows its specimen reads the same turned by half a turn (docs/science.md 7.4). Its
first round reads the plan's uniform angles over half a turn plus the opposites (``+ 180
deg``) of two of them a quarter turn apart (:func:`first_round_angles`: 0/180 and 90/270 for a
plan starting at 0), or, when the plan's pairs lie in planes spread around the normal, of the
first alone (:func:`opposites_needed`). A specimen without twofold symmetry differs between ``a``
and ``a + 180`` by an odd function of the stage angle, whose first harmonic ``cos(a - a0)``
cannot vanish at two angles a quarter turn apart, so the two opposite pairs see any lean,
whatever its direction; and pairs in different planes see a lean at one stage angle through
different phases, so one opposite angle is enough when their planes spread (measured on the
renderer's specimens: the same verdicts, 90 readings instead of 100 at r = 8 and 10 pairs,
docs/science.md 7.4). :func:`arc_test` compares them pair by pair against the noise model
(:func:`gonio.brdf.reconstruction.symmetry.twofold_test`, math.md 13); the plan's rounds
(:class:`gonio.plans.rounds.ArcRounds`) then continue over half a turn (symmetric) or
read the opposites of the remaining first-round angles and continue over a full turn
(:func:`fill_angles`).

The readings the engine holds are ``raw - dark`` counts, uncalibrated: the test works on
the differences of their logarithms, which a pair's (or a channel's) sensitivity does not
change, so each pair is scaled by its largest reading over its channels and the absolute
noise is a fraction of that (:data:`ABSOLUTE_FRACTION`). A finished scan of a fixed arc is
tested on the same counts, not on its calibrated values (:mod:`gonio.finishing`): shot noise
is a matter of counts, and a spectral calibration lifts a dim band's values to its neighbours'
without lowering its noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.arc_wording import p_value_text
from gonio.brdf.reconstruction.samples import HALF_TURN_DEG, NoiseModel
from gonio.plans.models import AdaptivePlan, AnyPlan
from gonio.plans.route import order_for_travel
from gonio.plans.timing import adaptive_bound, estimate_angles, travel
from gonio.plans.validation import uniform_angles
from gonio.rigdescription import RigDescription

FULL_TURN_DEG = 360.0
ABSOLUTE_FRACTION = 0.01
"""Absolute noise of a reading as a fraction of its pair's largest reading in the test round
(the largest over the pair's channels: a channel whose sensor is less sensitive has fewer
counts and more relative noise). Photon shot noise grows as the reading falls (relative
``1 / sqrt(counts)``): on the simulated sensors, 1 % at a peak of 5000 counts is 3 % at a
tenth of it, which a relative 1 % alone would take for asymmetry (measured: a
retro-reflective library material called asymmetric at p = 0.0008 with 0.2 %; p = 0.86 with
1 %, docs/science.md 7.4). Readings below about a tenth of the peak (predicted log deviation
above 0.1) are left out. (Until 2026-11-29 each channel was scaled by its own largest
reading: the dim bands of a 31-band sensor, at 1.6 % shot noise, then called an isotropic
paint asymmetric on 2 of 5 full-turn scans.)"""
FALSE_ALARM = 0.01
"""Probability that the test calls a twofold-symmetric specimen asymmetric (under the noise
model): 1 in 100 such specimens is scanned over a full turn it did not need."""
ARC_TEST_EVENT = "arc_test"
"""The job event that records the test and the arc chosen (the store keeps it, so a resumed
job continues on the arc it chose)."""


def may_switch_basis(plan: AnyPlan | dict[str, Any]) -> bool:
    """Whether a scan's twofold symmetry test may ask for the basis for specimens without
    twofold symmetry (``default_basis(asymmetric=True)``, minutes to build once): an auto-arc
    plan (its first round's test) or a reconstructing plan over a fixed full turn (finishing
    tests the opposite stage angles it reads, :mod:`gonio.finishing`). ``plan`` is a plan or
    a stored plan's JSON. Time estimates count the build for such a scan as a bound; only
    auto-arc plans were counted, and a full-turn scan of an asymmetric-looking specimen said
    "13 s left" through a two-minute build."""
    # A uniform plan of an odd number of angles over a full turn holds no opposite angles,
    # so it is never tested; an adaptive one's midpoints add them.
    if isinstance(plan, dict):
        kind = plan.get("kind")
        if kind not in ("uniform", "adaptive"):
            return False
        if plan.get("arc") == "auto":
            return True
        odd = kind == "uniform" and int(plan.get("rotations", 0)) % 2 == 1
        return float(plan.get("span_deg", 180.0)) >= FULL_TURN_DEG and not odd
    if plan.finishing != "reconstruction":
        return False
    if plan.arc_mode() == "auto":
        return True
    odd = plan.kind == "uniform" and int(getattr(plan, "rotations", 0)) % 2 == 1
    return plan.first_span_deg() >= FULL_TURN_DEG and not odd


SPREAD_DEG = 60.0
"""How far apart (modulo 180 deg) the planes of two of the plan's pairs must lie for one
opposite stage angle to test the specimen (:func:`opposites_needed`). A pair whose light and
sensor lie in one plane through the normal is blind, at one stage angle, to a lean across
that plane (the plane is a mirror of the pair and swaps a lean with its opposite). A pair
sees ``|cos|`` of the angle between the lean and its plane, so a lean across pair 1's plane
reaches a pair whose plane is ``d`` away with ``sin d``, and a lean in any direction reaches
the better of the two with at least ``sin(d / 2)`` of its full first harmonic (the worst lean
lies midway between the two planes' normals): 60 deg keeps half of it (two opposites a
quarter turn apart keep ``sin 45 deg`` = 71 % for any single pair)."""


def pair_planes_deg(light_dirs: ArrayLike, sensor_dirs: ArrayLike) -> NDArray[np.float64]:
    """Each pair's plane in the lab: the azimuth (degrees modulo 180) of the principal axis of
    its light's and sensor's directions projected on the specimen plane; NaN where the axis is
    undefined (both at the pole, or at right angles and equally far from it).

    Parameters
    ----------
    light_dirs, sensor_dirs : (n, 3) lab unit vectors (:meth:`RigDescription.pair_directions`)

    Returns
    -------
    (n,) float array, degrees in [0, 180) or NaN
    """
    u = np.asarray(light_dirs, float).reshape(-1, 3)
    v = np.asarray(sensor_dirs, float).reshape(-1, 3)
    # The axis of the lines through +-u and +-v: the angle of sum (x + iy)^2, halved.
    z = (u[:, 0] + 1j * u[:, 1]) ** 2 + (v[:, 0] + 1j * v[:, 1]) ** 2
    size = np.sum(u[:, :2] ** 2, axis=1) + np.sum(v[:, :2] ** 2, axis=1)
    defined = np.abs(z) > 1e-3 * np.maximum(size, 1e-12)
    out = np.mod(np.rad2deg(np.angle(z)) / 2.0, 180.0)
    out = np.where(out >= 180.0 - 1e-9, 0.0, out)  # -0 rounds to 180 in np.mod
    return np.where(defined & (size > 1e-6), out, np.nan)


def opposites_needed(light_dirs: ArrayLike, sensor_dirs: ArrayLike) -> int:
    """How many opposite stage angles the first round reads for the plan's pairs: 1 when two
    of the pairs' planes (:func:`pair_planes_deg`) lie at least :data:`SPREAD_DEG` apart
    modulo 180 deg, so that some pair sees a lean in any direction at one stage angle; 2 (a
    quarter turn apart, which any single pair suffices for) otherwise."""
    planes = pair_planes_deg(light_dirs, sensor_dirs)
    planes = planes[np.isfinite(planes)]
    if planes.size < 2:
        return 2
    d = np.abs(planes[:, None] - planes[None, :]) % 180.0
    return 1 if float(np.minimum(d, 180.0 - d).max()) >= SPREAD_DEG - 1e-9 else 2


def _picks(rotations: int, opposites: int) -> list[int]:
    """Indices of the half-turn angles whose opposites the first round reads."""
    if opposites not in (1, 2):
        raise ValueError(f"opposites = {opposites}; the first round reads 1 or 2")
    return sorted({0, rotations // 2}) if opposites == 2 else [0]


def first_round_angles(start_deg: float, rotations: int, opposites: int) -> list[float]:
    """The first round of an auto-arc plan: ``rotations`` uniform angles over half a turn from
    ``start_deg``, then the opposite of the first of them and, with ``opposites`` 2 (pairs
    whose planes do not spread, :func:`opposites_needed`), of the one a quarter turn on (index
    ``rotations // 2``; just the first's when ``rotations`` is 1); degrees in [0, 360)."""
    half = uniform_angles(start_deg, rotations, HALF_TURN_DEG)
    return half + [float((half[k] + HALF_TURN_DEG) % 360.0)
                   for k in _picks(rotations, opposites)]


def fill_angles(start_deg: float, rotations: int, opposites: int) -> list[float]:
    """What an asymmetric specimen reads next: the opposites of the first round's half-turn
    angles that :func:`first_round_angles` (with the same ``opposites``) did not read, so that
    the first two rounds hold ``2 rotations`` uniform angles over the full turn; degrees in
    [0, 360)."""
    half = uniform_angles(start_deg, rotations, HALF_TURN_DEG)
    done = set(_picks(rotations, opposites))
    return [float((a + HALF_TURN_DEG) % 360.0) for k, a in enumerate(half) if k not in done]


def fill_after(start_deg: float, rotations: int, read_deg: Sequence[float]) -> list[float]:
    """The fill round after the stage angles ``read_deg`` (degrees): every opposite of the
    half-turn angles not read yet, whatever count of opposites the first round held (one, two,
    or a resumed job's stored round under another count); degrees in [0, 360). The one
    derivation the dry run's bound, the submission check and the rounds share."""
    read = {round(float(a) % 360.0, 6) for a in read_deg}
    opposites = [float((a + HALF_TURN_DEG) % 360.0)
                 for a in uniform_angles(start_deg, rotations, HALF_TURN_DEG)]
    return [a for a in opposites if round(a, 6) not in read]


def arc_test(angles_deg: Sequence[float], values: ArrayLike, relative: float,
             false_alarm: float = FALSE_ALARM) -> dict[str, Any]:
    """Test readings for twofold symmetry and choose the arc; the ``arc_test`` event's data.

    Parameters
    ----------
    angles_deg : (r,) stage (specimen) angles, degrees; some must be 180 deg apart
    values : (n_pairs, r, C) readings, ``raw - dark`` counts (NaN where missing); values
        scaled per pair and channel (calibrated) weigh a dim channel's noise wrongly
    relative : relative noise of one reading (the plan's ``arc_noise``)
    false_alarm : the test's level (:data:`FALSE_ALARM`)

    Returns
    -------
    dict
        ``symmetric`` (bool), ``arc_deg`` (180.0 or 360.0), ``statistic``, ``dof``,
        ``p_value`` (the overall chi-square test), ``opposite_pairs`` (angle pairs compared),
        ``asymmetric_pairs`` (light/sensor pairs whose own test failed), ``rms_log_difference``
        (largest over the pairs), ``noise``, ``false_alarm`` and ``message``. When the
        readings cannot be tested (none usable) the scan takes the full turn and ``error``
        says why (``statistic`` etc. are None).
    """
    # The numerics (scipy) load with the first test, not with the plans.
    from gonio.brdf.reconstruction.symmetry import SymmetryError, twofold_test

    v = np.asarray(values, dtype=float)
    if v.ndim == 2:
        v = v[:, :, None]
    # Each pair scaled by its largest reading over angles and channels (log differences do not
    # change): the absolute noise is a fraction of the sensor's counts, whatever the channel.
    positive = np.where(np.isfinite(v) & (v > 0), v, 0.0)
    peak = positive.max(axis=(1, 2), keepdims=True) if v.size else np.ones((0, 1, 1))
    peak = np.where(peak > 0, peak, 1.0)
    noise = NoiseModel(relative=float(relative), absolute=ABSOLUTE_FRACTION)
    base: dict[str, Any] = {"noise": float(relative), "false_alarm": float(false_alarm)}
    try:
        t = twofold_test(np.deg2rad(np.asarray(angles_deg, float)), v / peak, noise,
                         false_alarm=false_alarm)
    except SymmetryError as exc:
        return {**base, "symmetric": False, "arc_deg": FULL_TURN_DEG, "statistic": None,
                "dof": 0, "p_value": None, "opposite_pairs": 0, "asymmetric_pairs": None,
                "rms_log_difference": None, "error": str(exc),
                "message": f"the twofold symmetry test could not run ({exc}); the scan "
                           "continues over a full turn, which is right for any specimen"}
    symmetric = bool(t.overall_symmetric)
    rms = t.rms_log_difference[np.isfinite(t.rms_log_difference)]
    out = {**base, "symmetric": symmetric,
           "arc_deg": HALF_TURN_DEG if symmetric else FULL_TURN_DEG,
           "statistic": float(t.total_statistic), "dof": int(t.total_dof),
           "p_value": float(t.total_p_value), "opposite_pairs": int(t.opposite.shape[0]),
           "asymmetric_pairs": int((~t.symmetric).sum()),
           "rms_log_difference": float(rms.max()) if rms.size else None}
    out["message"] = describe(out)
    return out


def describe(test: dict[str, Any]) -> str:
    """One sentence on an ``arc_test`` event's data: the verdict, its statistic, the arc."""
    if test.get("statistic") is None:
        return str(test.get("message", "the twofold symmetry test did not run"))
    verdict = ("twofold symmetric" if test["symmetric"]
               else "NOT twofold symmetric")
    arc = "half a turn" if test["arc_deg"] == HALF_TURN_DEG else "a full turn"
    return (f"the specimen reads {verdict} (chi-square {test['statistic']:.1f} on "
            f"{test['dof']} degrees of freedom, {p_value_text(test['p_value'])}, level "
            f"{test['false_alarm']:g}, noise {100 * test['noise']:g} %; "
            f"{test['asymmetric_pairs']} pair(s) differ at opposite angles): scanned over {arc}")


def half_turn_warning(test: dict[str, Any]) -> str | None:
    """The warning for a plan forced over half a turn (``span_deg`` 180, ``arc`` fixed) whose
    readings include opposite angles that the test calls asymmetric; None otherwise."""
    if test.get("statistic") is None or test["symmetric"]:
        return None
    return (f"the plan was forced over half a turn (span_deg 180), but its readings at opposite "
            f"stage angles differ beyond the noise (chi-square {test['statistic']:.1f} on "
            f"{test['dof']} degrees of freedom, {p_value_text(test['p_value'])}): the specimen "
            "is not twofold symmetric, and the other half turn rests on the assumption that it "
            "is; "
            "scan it again with arc 'auto' or span_deg 360 (gonio scan --arc auto or --span 360)")


def branch_bounds(plan: AnyPlan, rig: RigDescription, n_lights: int, n_pairs: int,
                  first_angles: Sequence[float], end_deg: float
                  ) -> dict[float, tuple[int, float]]:
    """What an auto-arc plan may add after its first round, for either verdict of the test.

    Parameters
    ----------
    plan : the plan (``arc`` auto)
    rig : RigDescription
    n_lights, n_pairs : of the plan
    first_angles : (r + 1,) or (r + 2,) the first round's angles (:func:`first_round_angles`),
        degrees
    end_deg : where the stage ends the first round, degrees

    Returns
    -------
    dict
        ``{180.0: (angles, seconds), 360.0: (angles, seconds)}``: most stage angles and
        seconds after the first round when the specimen is found twofold symmetric (an
        adaptive plan's refinement over half a turn, :func:`adaptive_bound`; nothing for a
        uniform plan) and when it is not (the fill round of :func:`fill_after`, timed from
        ``end_deg``, then an adaptive plan's refinement over the full turn, one round fewer).
    """
    out: dict[float, tuple[int, float]] = {HALF_TURN_DEG: (0, 0.0)}
    if isinstance(plan, AdaptivePlan):
        out[HALF_TURN_DEG] = adaptive_bound(plan, rig, n_pairs, n_lights, first_angles, end_deg)
    fill = fill_after(float(plan.start_deg), plan.first_rotations(), first_angles)
    route = order_for_travel(fill, end_deg, rig, plan.backlash_deg) if fill else []
    motion, settle, exposure = estimate_angles(route, end_deg, n_lights, plan, rig, False)
    angles, seconds = len(route), motion + settle + exposure
    if isinstance(plan, AdaptivePlan) and plan.max_rounds > 2:
        here = travel(route, end_deg, rig, plan.backlash_deg)[2] if route else end_deg
        # The refinement over the full turn after the fill round: one round fewer.
        full = plan.model_copy(update={"span_deg": FULL_TURN_DEG,
                                       "max_rounds": plan.max_rounds - 1})
        extra, extra_s = adaptive_bound(full, rig, n_pairs, n_lights,
                                        [*first_angles, *route], here)
        angles, seconds = angles + extra, seconds + extra_s
    out[FULL_TURN_DEG] = (angles, seconds)
    return out
