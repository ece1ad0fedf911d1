"""The arc from the data: which stage angles test twofold symmetry, and what the test says.

A plan with ``arc = "auto"`` (:mod:`gonio.plans.models`) does not commit to half a turn
before it knows its specimen reads the same turned by half a turn (docs/science.md 7.4). Its
first round reads the plan's uniform angles over half a turn plus the opposite (``+ 180
deg``) of the first of them (:func:`first_round_angles`: 0/180 for a plan starting at 0). A
specimen without twofold symmetry differs between ``a`` and ``a + 180`` by an odd function of
the stage angle; for each pair its first harmonic is ``cos(a - a_p)`` with a phase ``a_p``
set by where the pair's light and sensor sit, so pairs at different azimuths cannot all see
nothing at one stage angle. Pairs that all lie in one plane through the normal (in-plane
instruments) can: a lean across that plane reads the same at ``a`` and ``a + 180``, mirrored.
For them the first round reads a second opposite a quarter turn on (0/180 and 90/270,
:func:`opposites_needed`). :func:`arc_test` compares the opposites pair by pair against the
noise model (:func:`gonio.brdf.reconstruction.symmetry.twofold_test`, math.md 13); the
plan's rounds (:class:`gonio.plans.rounds.ArcRounds`) then continue over half a turn
(symmetric) or read the opposites of the remaining first-round angles and continue over a
full turn (:func:`fill_angles`).

The readings the engine holds are ``raw - dark`` counts, uncalibrated: the test works on
the differences of their logarithms, which a pair's (or a channel's) sensitivity does not
change, so each pair and channel is scaled by its largest reading and the absolute noise is a
fraction of that (:data:`ABSOLUTE_FRACTION`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from gonio.brdf.reconstruction.samples import HALF_TURN_DEG, NoiseModel
from gonio.plans.models import AdaptivePlan, AnyPlan
from gonio.plans.route import order_for_travel
from gonio.plans.timing import adaptive_bound, estimate_angles, travel
from gonio.plans.validation import uniform_angles
from gonio.rigdescription import RigDescription

FULL_TURN_DEG = 360.0
ABSOLUTE_FRACTION = 0.01
"""Absolute noise of a reading as a fraction of its pair's largest reading (per channel) in
the test round. Photon shot noise grows as the reading falls (relative ``1 / sqrt(counts)``):
on the simulated sensors, 1 % at a peak of 5000 counts is 3 % at a tenth of it, which a
relative 1 % alone would take for asymmetry (measured: a retro-reflective library material
called asymmetric at p = 0.0008 with 0.2 %; p = 0.86 with 1 %, docs/science.md 7.4). Readings
below about a tenth of the peak (predicted log deviation above 0.1) are left out."""
FALSE_ALARM = 0.01
"""Probability that the test calls a twofold-symmetric specimen asymmetric (under the noise
model): 1 in 100 such specimens is scanned over a full turn it did not need."""
COPLANAR_TOL_DEG = 2.0
"""Pairs whose lights and sensors all lie within this many degrees of one plane through the
normal count as in-plane (:func:`opposites_needed`): the first round reads two opposites."""
ARC_TEST_EVENT = "arc_test"
"""The job event that records the test and the arc chosen (the store keeps it, so a resumed
job continues on the arc it chose)."""


def opposites_needed(light_dirs: ArrayLike, sensor_dirs: ArrayLike) -> int:
    """How many opposite stage angles the first round needs to see a lean in any direction.

    Parameters
    ----------
    light_dirs, sensor_dirs : (n, 3) lab unit vectors toward each pair's light and sensor

    Returns
    -------
    int
        1 when the directions span more than one plane through the normal (the pairs' own
        phases cover every direction of lean), 2 when they all lie within
        :data:`COPLANAR_TOL_DEG` of one such plane (or on the normal): a lean across that
        plane is mirrored between ``a`` and ``a + 180`` and only a second opposite a quarter
        turn on sees it.
    """
    v = np.concatenate([np.asarray(light_dirs, float).reshape(-1, 3),
                        np.asarray(sensor_dirs, float).reshape(-1, 3)])
    off_normal = np.hypot(v[:, 0], v[:, 1]) > np.sin(np.deg2rad(1.0))
    if not off_normal.any():
        return 2
    # Azimuths modulo half a turn, as points on a circle of doubled angle: one plane through
    # the normal is one point there.
    az2 = 2.0 * np.arctan2(v[off_normal, 1], v[off_normal, 0])
    centre = np.angle(np.exp(1j * az2).mean())
    spread = np.abs(np.angle(np.exp(1j * (az2 - centre)))) / 2.0
    return 2 if np.rad2deg(spread.max()) <= COPLANAR_TOL_DEG else 1


def _opposite_picks(rotations: int, opposites: int) -> list[int]:
    """Indices of the half-turn angles whose opposites the first round reads."""
    if opposites not in (1, 2):
        raise ValueError(f"opposites is {opposites}; the first round reads 1 or 2")
    return sorted({0, rotations // 2}) if opposites == 2 else [0]


def first_round_angles(start_deg: float, rotations: int, opposites: int = 1) -> list[float]:
    """The first round of an auto-arc plan: ``rotations`` uniform angles over half a turn from
    ``start_deg``, then the opposite of the first of them and, when ``opposites`` is 2
    (:func:`opposites_needed`), of the one a quarter turn on (index ``rotations // 2``; just the
    first's when ``rotations`` is 1); degrees in [0, 360)."""
    half = uniform_angles(start_deg, rotations, HALF_TURN_DEG)
    picks = _opposite_picks(rotations, opposites)
    return half + [float((half[k] + HALF_TURN_DEG) % 360.0) for k in picks]


def fill_angles(start_deg: float, rotations: int, opposites: int = 1) -> list[float]:
    """What an asymmetric specimen reads next: the opposites of the first round's half-turn
    angles that :func:`first_round_angles` (with the same ``opposites``) did not read, so that
    the first two rounds hold ``2 rotations`` uniform angles over the full turn; degrees in
    [0, 360)."""
    half = uniform_angles(start_deg, rotations, HALF_TURN_DEG)
    done = set(_opposite_picks(rotations, opposites))
    return [float((a + HALF_TURN_DEG) % 360.0) for k, a in enumerate(half) if k not in done]


def arc_test(angles_deg: Sequence[float], values: ArrayLike, relative: float,
             false_alarm: float = FALSE_ALARM) -> dict[str, Any]:
    """Test readings for twofold symmetry and choose the arc; the ``arc_test`` event's data.

    Parameters
    ----------
    angles_deg : (r,) stage (specimen) angles, degrees; some must be 180 deg apart
    values : (n_pairs, r, C) readings (``raw - dark`` counts or 1/sr; NaN where missing)
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
    # Each pair and channel scaled by its largest reading (log differences do not change).
    positive = np.where(np.isfinite(v) & (v > 0), v, 0.0)
    peak = positive.max(axis=1, keepdims=True) if v.size else np.ones((0, 1, 1))
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
            f"{test['dof']} degrees of freedom, p = {test['p_value']:.3g}, level "
            f"{test['false_alarm']:g}, noise {100 * test['noise']:g} %; "
            f"{test['asymmetric_pairs']} pair(s) differ at opposite angles): scanned over {arc}")


def half_turn_warning(test: dict[str, Any]) -> str | None:
    """The warning for a plan forced over half a turn (``span_deg`` 180, ``arc`` fixed) whose
    readings include opposite angles that the test calls asymmetric; None otherwise."""
    if test.get("statistic") is None or test["symmetric"]:
        return None
    return (f"the plan was forced over half a turn (span_deg 180), but its readings at opposite "
            f"stage angles differ beyond the noise (chi-square {test['statistic']:.1f} on "
            f"{test['dof']} degrees of freedom, p = {test['p_value']:.3g}): the specimen is not "
            "twofold symmetric, and the other half turn rests on the assumption that it is; "
            "scan it again with arc 'auto' or span_deg 360 (gonio scan --arc auto or --span 360)")


def branch_bounds(plan: AnyPlan, rig: RigDescription, n_lights: int, n_pairs: int,
                  first_angles: Sequence[float], end_deg: float, opposites: int = 1
                  ) -> dict[float, tuple[int, float]]:
    """What an auto-arc plan may add after its first round, for either verdict of the test.

    Parameters
    ----------
    plan : the plan (``arc`` auto)
    rig : RigDescription
    n_lights, n_pairs : of the plan
    first_angles : (r + opposites,) the first round's angles (:func:`first_round_angles`),
        degrees
    end_deg : where the stage ends the first round, degrees
    opposites : opposites the first round read (:func:`opposites_needed`)

    Returns
    -------
    dict
        ``{180.0: (angles, seconds), 360.0: (angles, seconds)}``: most stage angles and
        seconds after the first round when the specimen is found twofold symmetric (an
        adaptive plan's refinement over half a turn, :func:`adaptive_bound`; nothing for a
        uniform plan) and when it is not (the fill round of :func:`fill_angles`, timed from
        ``end_deg``, then an adaptive plan's refinement over the full turn, one round fewer).
    """
    out: dict[float, tuple[int, float]] = {HALF_TURN_DEG: (0, 0.0)}
    if isinstance(plan, AdaptivePlan):
        out[HALF_TURN_DEG] = adaptive_bound(plan, rig, n_pairs, n_lights, first_angles, end_deg)
    fill = fill_angles(float(plan.start_deg), plan.first_rotations(), opposites)
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
