"""Dry run: what a plan will do on a rig, and how long it will take, without hardware."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from pydantic import BaseModel, Field

from gonio.brdf.mirrorgap import gap_note, mirror_gap_deg
from gonio.brdf.reconstruction.samples import HALF_TURN_DEG
from gonio.hal import PairSpec
from gonio.plans.arc import FULL_TURN_DEG, branch_bounds
from gonio.plans.checked import CheckedPlan, check_plan
from gonio.plans.models import AdaptivePlan, AnyPlan
from gonio.plans.timing import adaptive_bound, estimate_angles, travel
from gonio.rigdescription import RigDescription

BASIS_BUILD_S = 120.0
"""Time to build the default basis on an install that has none yet (the synthetic training
library, then the basis), seconds: about two minutes measured on a busy 2-core machine
(README); slower machines take longer. An adaptive plan with the posterior rule waits for it
before its first reading."""

ASYMMETRIC_BASIS_BUILD_S = 240.0
"""Time to build the basis for specimens without twofold symmetry
(``default_basis(asymmetric=True)``: the library's 65 asymmetric materials tabulated, the
basis learnt from them and the default library, the measured materials folded in), seconds,
once per install, on an install whose default library is tabulated: 190 s measured on the busy
2-core machine (load average 11; docs/science.md 7.4), rounded up. A job whose auto-arc test
finds its specimen asymmetric waits for it at finishing."""


@dataclass(frozen=True)
class BasisSymmetry:
    """What a reconstruction basis' prior says about a specimen turned by half a turn.

    Parameters
    ----------
    half_turn_periodic : bool
        :attr:`gonio.brdf.reconstruction.basis.Basis.half_turn_periodic`.
    without_twofold_symmetry : tuple of str
        The training materials known to lack the twofold symmetry
        (:attr:`~gonio.brdf.reconstruction.basis.Basis.without_twofold_symmetry`; may be empty
        when the basis does not record them).
    """

    half_turn_periodic: bool
    without_twofold_symmetry: tuple[str, ...] = ()

    @classmethod
    def of(cls, basis: object) -> BasisSymmetry:
        """From a :class:`~gonio.brdf.reconstruction.basis.Basis` (or anything with its two
        attributes; a missing one reads as periodic, names unknown)."""
        return cls(bool(getattr(basis, "half_turn_periodic", True)),
                   tuple(getattr(basis, "without_twofold_symmetry", ())))


def arc_may_apply(plan: AnyPlan) -> bool:
    """Whether :func:`arc_warning` can concern ``plan`` at all (a reconstruction over half a
    turn): callers skip looking at the basis otherwise."""
    return (plan.finishing == "reconstruction" and plan.first_span_deg() == HALF_TURN_DEG
            and plan.arc_mode() == "fixed")


def arc_warning(plan: AnyPlan, basis: BasisSymmetry | None) -> str | None:
    """The warning for a half-turn plan reconstructed with a basis that is not half-turn
    periodic (docs/science.md 7.4), or None.

    None as well when nothing is known of the basis (``basis`` None: not built yet; the job
    says it when it has the basis) and for plans that reconstruct nothing (calibrations).
    The joint fit still takes such a scan, so this is a warning, not a refusal.
    """
    if basis is None or basis.half_turn_periodic or not arc_may_apply(plan):
        return None
    names = _names(basis.without_twofold_symmetry)
    return (f"the plan reads the stage over half a turn (span_deg 180), but the reconstruction "
            f"basis holds materials without twofold symmetry{names}, so readings over half a "
            "turn leave the other half turn to its prior: set span_deg 360 (gonio scan --span "
            "360) to measure a full turn")


def _names(names: Sequence[str], most: int = 5) -> str:
    """`` (a, b, c)`` or `` (a, b, c, d, e and 3 more)``; empty for no names."""
    if not names:
        return ""
    shown = ", ".join(names[:most])
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return f" ({shown}{more})"


class ArcBranch(BaseModel):
    """An auto-arc plan's job for one verdict of its twofold symmetry test (bounds)."""

    arc_deg: float = Field(description="the arc the job continues on: 180 (the specimen "
                           "reads twofold symmetric) or 360 (it does not)")
    angles: int = Field(description="most stage angles the job measures, the first round's "
                        "included")
    readings: int = Field(description="most pair readings (pairs x angles)")
    estimated_s: float = Field(description="bound on the job's duration, seconds (a uniform "
                               "plan's is its duration; an adaptive plan's includes a basis "
                               "build when one is needed)")
    basis: str = Field(default="default", description="the basis the job is reconstructed "
                       "with: 'default', or (360, the specimen is not twofold symmetric) "
                       "'asymmetric', the basis whose prior holds odd harmonics "
                       "(docs/science.md 7.4)")
    basis_build_s: float | None = Field(
        default=None, description="seconds the job waits at finishing for that basis to be "
        "built (once per install; not in estimated_s); null: ready, or not needed")


class DryRun(BaseModel):
    """What a plan will do, without hardware: the first round's stage positions and timing.

    The estimate is the physical time of every move the engine and the stage driver make
    (from the stage's present position, with the engine's and the driver's backlash
    approaches), settling and exposures. For adaptive plans only the first round is known in
    advance; ``estimated_s`` covers it and ``max_estimated_s`` bounds the whole job: every
    refinement round adding a midpoint in every gap of the plan's arc (over half a turn, the
    gaps modulo 180), until ``max_rounds``, ``min_step_deg``, ``max_samples`` or the cap of
    stage angles stops it.
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
    basis_build_s: float | None = Field(
        default=None, description="adaptive plans with the posterior rule on an install "
        "without the default basis: the job builds it before its first reading, about this "
        "many seconds (once; not in estimated_s, included in max_estimated_s); null: the "
        "basis is ready or not needed while measuring")
    finishing_s: float | None = Field(
        default=None, description="seconds the job takes after its last reading (reconstruction "
        "and export fits, as they took on this store's last scans: finishing_source), plus a "
        "basis build when the default basis is not built yet and the job does not build it "
        "before its first reading (basis_build_s); not in estimated_s; null for a plan that "
        "reconstructs nothing (a calibration) or when no estimate was asked for")
    finishing_source: str | None = Field(
        default=None, description="what finishing_s rests on, in words")
    arc_branches: list[ArcBranch] | None = Field(
        default=None, description="plans with arc 'auto': the job when the first round's test "
        "finds the specimen twofold symmetric (180) and when it does not (360), each bounded; "
        "max_estimated_s and max_angles are the larger. null for a fixed arc")
    mirror_gap_deg: float | None = Field(
        default=None, description="plans that reconstruct: the least tilt of a pair's half "
        "vector from the specimen normal, degrees (the layout's mirror gap; turning the stage "
        "keeps it, docs/science.md 7.1.1.2); null for a plan that reconstructs nothing")
    mirror_gap: str | None = Field(
        default=None, description="when mirror_gap_deg is above 1: what it means for a glossy "
        "specimen (a highlight narrower than the gap is neither measured nor in the result's "
        "predicted_log_rmse), in words; the result records the same. A fact of the rig's "
        "layout, not a warning: most specimens have no highlight that narrow")
    warnings: list[str] = Field(
        default_factory=list, description="what may make the result poorer than the plan "
        "suggests, and what to do; the plan runs as it is. E.g. a half-turn plan (span_deg "
        "180) while the reconstruction basis holds materials without twofold symmetry (checked "
        "only when the basis is built: a dry run never builds it)")


def dry_run(plan: AnyPlan | CheckedPlan, rig: RigDescription, current_deg: float | None = None,
            basis_ready: bool = True, basis: BasisSymmetry | None = None,
            asymmetric_build_s: float | None = None, asymmetric_basis: bool = True,
            finishing_s: float | None = None, finishing_source: str | None = None) -> DryRun:
    """Expand ``plan`` on ``rig`` and estimate its duration; raises :class:`PlanError`.

    The estimate is the physical time (see :class:`DryRun`): trapezoidal stage moves at the
    rig's speed and acceleration for every leg (from ``current_deg``, the engine's backlash
    overshoot and the driver's approach), the stage settle time after each move, each
    light's settle time, and one ``exposure_s x averages`` per light and angle (all sensors
    of a light read in parallel), plus dark exposures. Communication overhead is not
    included (a few percent: docs/engine.md).

    Parameters
    ----------
    plan : the plan, or the plan already checked on ``rig`` (:func:`check_plan`: its checks
        are not made again)
    rig : RigDescription
    current_deg : float, optional
        Present stage position, degrees; None when unknown (0 is assumed and the result says
        so).
    basis_ready : bool
        False when the reconstruction basis would have to be built first (see
        :meth:`gonio.basis_supply.BasisSupply.build_needed`); an adaptive plan with the
        posterior rule then reports :data:`BASIS_BUILD_S` as ``basis_build_s``.
    basis : BasisSymmetry, optional
        What the basis the job would reconstruct with says about half a turn, when that basis
        is at hand (built or loaded); None when it is not (nothing is said then). A half-turn
        plan with a basis that is not half-turn periodic gets a warning (:func:`arc_warning`).
    asymmetric_build_s : float, optional
        Auto-arc plans: seconds the full-turn branch waits at finishing for the basis for
        specimens without twofold symmetry to be built
        (:meth:`gonio.basis_supply.BasisSupply.asymmetric_build_s`); None when it is ready.
    asymmetric_basis : bool
        Whether the full-turn branch reconstructs with that basis (False: the process has
        none, or its basis already holds odd harmonics, so the job keeps its basis).
    finishing_s, finishing_source : float and str, optional
        The store's finishing estimate (:func:`gonio.timeleft.finishing_estimate`: seconds
        and what they rest on). Given, a plan that reconstructs reports ``finishing_s``: these
        seconds plus :data:`BASIS_BUILD_S` when ``basis_ready`` is False and the job does not
        build the basis before its first reading. The dry run's measuring estimate never
        held the reconstruction, which can take longer than the measuring.
    """
    start = 0.0 if current_deg is None else float(current_deg)
    checked = check_plan(plan, rig, from_deg=start)
    plan = checked.plan
    pairs, lights = list(checked.pairs), list(checked.lights)
    angles, route = list(checked.angles_deg), list(checked.route_deg)
    motion, settle, exposure = estimate_angles(
        route, start, len(lights), plan, rig, plan.exposure.dark != "none"
    )
    total = motion + settle + exposure
    max_total = max_angles = build = None
    if isinstance(plan, AdaptivePlan):
        _, _, end = travel(route, start, rig, plan.backlash_deg)
        extra_n, extra_s = adaptive_bound(plan, rig, len(pairs), len(lights), angles, end)
        # The posterior rule waits for the basis before the first reading (gonio.worker).
        build = BASIS_BUILD_S if plan.rule == "posterior" and not basis_ready else None
        max_total, max_angles = total + extra_s + (build or 0.0), len(route) + extra_n
    branches = None
    if plan.arc_mode() == "auto":
        _, _, end = travel(route, start, rig, plan.backlash_deg)
        build = BASIS_BUILD_S if (isinstance(plan, AdaptivePlan) and plan.rule == "posterior"
                                  and not basis_ready) else None
        switch = asymmetric_basis and (basis is None or basis.half_turn_periodic)
        branches = [ArcBranch(arc_deg=arc, angles=len(route) + n,
                              readings=len(pairs) * (len(route) + n),
                              estimated_s=total + extra_s + (build or 0.0),
                              basis="asymmetric" if switch and arc == FULL_TURN_DEG
                              else "default",
                              basis_build_s=asymmetric_build_s
                              if switch and arc == FULL_TURN_DEG else None)
                    for arc, (n, extra_s) in branch_bounds(
                        plan, rig, len(lights), len(pairs), angles, end).items()]
        max_total = max(b.estimated_s for b in branches)
        max_angles = max(b.angles for b in branches)
    finish = None
    if finishing_s is not None and plan.finishing == "reconstruction":
        finish = finishing_s
        if not basis_ready and build is None:
            # A job that did not build the basis before measuring builds it at finishing.
            finish += BASIS_BUILD_S
            finishing_source = (f"{finishing_source}; and about {BASIS_BUILD_S:.0f} s to build "
                                "the reconstruction basis, once on this install")
        if branches is None and asymmetric_build_s is not None and asymmetric_basis and (
                basis is None or basis.half_turn_periodic):
            # A fixed full turn is tested as it finishes (its readings at opposite angles): a
            # specimen called asymmetric waits there for that basis. A bound, like a branch.
            finish += asymmetric_build_s
            finishing_source = (f"{finishing_source}; and up to {asymmetric_build_s:.0f} s to "
                                "build the basis for specimens without twofold symmetry, once "
                                "on this install, if the readings at opposite stage angles "
                                "call the specimen so")
    gap = None
    if plan.finishing == "reconstruction":
        gap = mirror_gap_deg(*rig.pair_directions(pairs))
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
        basis_build_s=build,
        finishing_s=finish,
        finishing_source=finishing_source if finish is not None else None,
        arc_branches=branches,
        mirror_gap_deg=gap,
        mirror_gap=gap_note(gap) if gap is not None else None,
        warnings=[w for w in (arc_warning(plan, basis),) if w is not None],
    )
