"""Checking a plan against a rig before anything moves: its pairs, lights and first angles.

Everything that can be checked without hardware is checked here and raises
:class:`~gonio.plans.models.PlanError` with what is wrong and what to do.
"""

from __future__ import annotations

from collections.abc import Sequence

from gonio.hal import PairSpec
from gonio.plans.models import MAX_ROTATIONS, AdaptivePlan, AnyPlan, PlanError
from gonio.plans.route import stage_positions
from gonio.rigdescription import RigDescription
from gonio.wording import counted


def plan_pairs(plan: AnyPlan, rig: RigDescription) -> list[PairSpec]:
    """The pairs a plan measures, checked against the rig. Raises :class:`PlanError`."""
    if plan.pairs is not None and not plan.pairs and rig.pairs:
        # An empty list is not "every pair" (null is): it was blamed on the rig config.
        raise PlanError(
            "the plan's pairs list is empty, so it measures nothing; leave pairs out (or null) "
            f"to measure all {len(rig.pairs)} of the rig's pairs, or list the ones to measure"
        )
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


def uniform_angles(start_deg: float, r: int, span_deg: float = 360.0) -> list[float]:
    """``r`` specimen angles ``start_deg + k span_deg / r``, degrees in [0, 360)."""
    return [float((start_deg + k * span_deg / r) % 360.0) for k in range(r)]


def validate_plan(plan: AnyPlan, rig: RigDescription) -> list[PairSpec]:
    """Check everything that can be checked without hardware; raise :class:`PlanError`.

    Checks: pairs exist and are unique; at least one rotation; no two angles closer than the
    stage resolution (duplicates); every angle reachable inside the travel limits; exposure
    inside every used sensor's range; adaptive settings consistent. Returns the plan's pairs
    (:func:`plan_pairs`, found on the way). :func:`gonio.plans.checked.check_plan` keeps
    what the check found.
    """
    pairs = plan_pairs(plan, rig)
    r = plan.first_rotations()
    name = plan.rotations_field
    if r < 1:
        raise PlanError(f"{name} is {r}; a scan needs at least one stage angle (e.g. {name}=8)")
    if plan.refines and r < 3:
        raise PlanError(
            f"initial_rotations is {r}; adaptive refinement predicts each angle from its "
            "neighbours and needs at least 3 (the paper uses 8)"
        )
    if r > MAX_ROTATIONS:
        raise PlanError(
            f"{name} is {r}; a job measures at most {MAX_ROTATIONS} stage angles (0.1 degree "
            f"steps over a full turn). The paper's scans use 8 to 72; use {MAX_ROTATIONS} or fewer"
        )
    step = plan.first_span_deg() / r
    if step < rig.resolution_deg:
        raise PlanError(
            f"{r} rotations are {step:.4g} deg apart, finer than the stage resolution "
            f"{rig.resolution_deg:g} deg, so several would land on the same position "
            "(duplicate angles); use fewer rotations"
        )
    angles = uniform_angles(plan.start_deg, r, plan.first_span_deg())
    for a in angles:
        if not stage_positions(a, rig, margin=0.0):
            raise PlanError(
                f"stage angle {a:g} deg (start_deg {plan.start_deg:g} + multiples of "
                f"{step:g} deg) is outside the stage travel [{rig.stage_min_deg:g}, "
                f"{rig.stage_max_deg:g}] deg; choose a start angle or rotation count whose "
                "angles fit the travel, or widen the limits in the rig config"
            )
    ex = plan.exposure
    for sname in sorted({p.sensor for p in pairs}):
        try:
            s = rig.sensor(sname)
        except KeyError:
            raise PlanError(f"the rig has no sensor named {sname!r}") from None
        if not s.min_exposure_s <= ex.exposure_s <= s.max_exposure_s:
            raise PlanError(
                f"exposure {ex.exposure_s:g} s is outside the exposure range of sensor "
                f"{sname!r}, [{s.min_exposure_s:g}, {s.max_exposure_s:g}] s; choose an exposure "
                "in range"
            )
    if isinstance(plan, AdaptivePlan):
        min_step = plan.min_step_deg or rig.resolution_deg
        if min_step < rig.resolution_deg:
            raise PlanError(
                f"min_step_deg {min_step:g} is finer than the stage resolution "
                f"{rig.resolution_deg:g} deg; use at least the resolution"
            )
        if plan.max_rotations is not None and plan.max_rotations < r:
            raise PlanError(
                f"max_rotations {plan.max_rotations} is fewer than the first round's "
                f"{r} angles (initial_rotations); raise max_rotations or lower "
                "initial_rotations")
        if plan.max_samples is not None and plan.max_samples < len(pairs) * r:
            raise PlanError(
                f"max_samples {plan.max_samples} is smaller than the first round alone "
                f"({counted(len(pairs), 'pair')} x {r} angles = {len(pairs) * r}); raise the "
                f"budget or "
                "lower initial_rotations"
            )
    return pairs


def lights_in_order(pairs: Sequence[PairSpec]) -> list[str]:
    """Lights of the pairs in first-appearance order (one exposure per light and angle)."""
    out: list[str] = []
    for p in pairs:
        if p.light not in out:
            out.append(p.light)
    return out
