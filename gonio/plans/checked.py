"""A plan checked once against a rig, with what the check found, for everyone after it.

The service checks a plan when it is submitted; the worker checks a stored plan again only
when it did not come from this process's submission (a restart, another process's queue); the
engine, the adaptive rounds and the finishing take the :class:`CheckedPlan` they are given and
ask it for the pairs, lights and first angles instead of deriving them again.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

from gonio.hal import PairSpec
from gonio.plans.arc import branch_bounds, fill_after, first_round_angles, opposites_needed
from gonio.plans.models import AdaptivePlan, AnyPlan, PlanError
from gonio.plans.route import order_for_travel
from gonio.plans.timing import adaptive_bound, estimate_angles
from gonio.plans.validation import lights_in_order, uniform_angles, validate_plan
from gonio.rigdescription import RigDescription


@dataclass(frozen=True)
class CheckedPlan:
    """A plan that passed every check that needs no hardware on ``rig``.

    Build it with :func:`check_plan` (which raises :class:`~gonio.plans.models.PlanError`);
    a CheckedPlan is never made of an unchecked plan.

    Attributes
    ----------
    plan : the plan as submitted
    rig : the rig description it was checked against
    pairs : the pairs the plan measures, in order (the rows of every values array)
    lights : their lights in first-appearance order (one exposure per light and angle)
    angles_deg : (r,) specimen angles of the first round, degrees in [0, 360) (an auto-arc
        plan's: its half-turn angles and one or two opposites,
        :func:`gonio.plans.arc.first_round_angles`)
    route_deg : stage positions visiting ``angles_deg`` from ``from_deg``, degrees (proof
        that the first round can be visited in one direction inside the travel; the engine
        routes again from where the stage is)
    from_deg : where ``route_deg`` starts, degrees
    """

    plan: AnyPlan
    rig: RigDescription
    pairs: tuple[PairSpec, ...]
    lights: tuple[str, ...]
    angles_deg: tuple[float, ...]
    route_deg: tuple[float, ...] = field(repr=False)
    from_deg: float = 0.0

    @property
    def arc_deg(self) -> tuple[float, float]:
        """``(start_deg, span_deg)`` of the plan's arc, degrees: the first round's uniform
        angles and every refinement round lie in it. An auto-arc plan's first round is over
        half a turn (plus one or two opposites); the arc it continues on is its rounds' choice
        (:class:`gonio.plans.rounds.ArcRounds`)."""
        return (float(self.plan.start_deg), self.plan.first_span_deg())

    @cached_property
    def sensors_of(self) -> dict[str, tuple[str, ...]]:
        """The sensors read under each light, in pair order."""
        return {lt: tuple(p.sensor for p in self.pairs if p.light == lt) for lt in self.lights}

    @cached_property
    def per_angle_s(self) -> float:
        """Physical time of one stage angle of the first round, seconds (move of one uniform
        step, settles, exposures): the engine's ETA before it has measured an angle."""
        step = self.plan.first_span_deg() / max(len(self.angles_deg), 1)
        motion, settle, exposure = estimate_angles(
            [step], 0.0, len(self.lights), self.plan, self.rig,
            self.plan.exposure.dark == "every_angle")
        return motion + settle + exposure

    @cached_property
    def max_angles(self) -> int | None:
        """Most stage angles the job can measure: an adaptive plan's bound over all its
        rounds (:func:`gonio.plans.timing.adaptive_bound`), an auto-arc plan's over either
        arc (:func:`gonio.plans.arc.branch_bounds`); None for a fixed plan."""
        if self.plan.arc_mode() == "auto":
            branches = branch_bounds(self.plan, self.rig, len(self.lights), len(self.pairs),
                                     self.angles_deg, 0.0)
            return len(self.angles_deg) + max(n for n, _ in branches.values())
        if not isinstance(self.plan, AdaptivePlan):
            return None
        extra, _ = adaptive_bound(self.plan, self.rig, len(self.pairs), len(self.lights),
                                  self.angles_deg, 0.0)
        return len(self.angles_deg) + extra


def check_plan(plan: AnyPlan | CheckedPlan, rig: RigDescription,
               from_deg: float = 0.0) -> CheckedPlan:
    """Check ``plan`` on ``rig`` once; raises :class:`~gonio.plans.models.PlanError`.

    The checks are those of :func:`~gonio.plans.validation.validate_plan` and the first
    round's route from ``from_deg`` (degrees; the angles can be visited in one direction
    inside the travel), as a dry run makes them; an auto-arc plan's fill round too (the full
    turn an asymmetric specimen goes on to). A plan already checked on this very rig
    description is returned as it is, its route taken again only from another ``from_deg``.
    """
    if isinstance(plan, CheckedPlan):
        if plan.rig is not rig and plan.rig != rig:
            plan = plan.plan
        elif plan.from_deg == from_deg:
            return plan
        else:
            route = order_for_travel(plan.angles_deg, from_deg, rig, plan.plan.backlash_deg)
            return replace(plan, route_deg=tuple(route), from_deg=from_deg)
    pairs = validate_plan(plan, rig)
    if plan.arc_mode() == "auto":
        # One opposite stage angle when the pairs' planes spread, else two (gonio.plans.arc).
        angles = first_round_angles(plan.start_deg, plan.first_rotations(),
                                    opposites_needed(*rig.pair_directions(pairs)))
    else:
        angles = uniform_angles(plan.start_deg, plan.first_rotations(), plan.first_span_deg())
    route = order_for_travel(angles, from_deg, rig, plan.backlash_deg)
    if plan.arc_mode() == "auto":
        # The fill round an asymmetric specimen reads must fit the travel too: refused now,
        # not after the first round (a first round of one opposite no longer reaches 270).
        fill = fill_after(plan.start_deg, plan.first_rotations(), angles)
        try:
            if fill:
                order_for_travel(fill, route[-1], rig, plan.backlash_deg)
        except PlanError as exc:
            raise PlanError(f"arc 'auto' reads the full turn when the specimen is not twofold "
                            f"symmetric, and the stage cannot: {exc} (or use arc 'fixed' "
                            "with span_deg 180)") from None
    return CheckedPlan(plan=plan, rig=rig, pairs=tuple(pairs),
                       lights=tuple(lights_in_order(pairs)), angles_deg=tuple(angles),
                       route_deg=tuple(route), from_deg=from_deg)
