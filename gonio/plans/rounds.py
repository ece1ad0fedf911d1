"""The rounds of a scan: after its first round, does a plan measure more angles, and which?

Each plan kind owns its rounds (:func:`rounds_for`), the way a scan specification owns the
points it visits: a uniform or calibration plan has one round (:class:`SingleRound`); an
adaptive plan plans each next round from the readings so far (:class:`AdaptiveRounds`), with
the posterior rule of a :class:`Refiner` when the worker gives one, else V&F's rule
(:func:`gonio.plans.adaptive.adaptive_refinement`); a plan with ``arc = "auto"`` first tests
twofold symmetry on its first round and goes on over the arc that chose (:class:`ArcRounds`).
The engine only measures what a round returns and records its events; it knows no rule.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from gonio.plans.adaptive import adaptive_refinement
from gonio.plans.arc import ARC_TEST_EVENT, arc_test, fill_after
from gonio.plans.checked import CheckedPlan
from gonio.plans.models import MAX_ROTATIONS, AdaptivePlan
from gonio.wording import counted


@dataclass(frozen=True)
class RoundRequest:
    """What a refinement rule is asked before a round.

    Attributes
    ----------
    angles_deg : (r,) measured specimen angles, degrees
    values : (n_pairs, r, C) ``raw - dark`` counts (sensor units, uncalibrated), rows in the
        order of the plan's pairs
    budget_angles : most stage angles the round may add; None: no limit (the rule is asked
        so at the plan's limit, to tell whether it still wanted more)
    min_step_deg : finest step between angles, degrees
    min_gain : the posterior rule's threshold on the drop of the expected error
    arc_deg : ``(start_deg, span_deg)`` of the plan, degrees: new angles lie in the arc
    basis : the basis the job will finish with, which the rule plans with when it has it:
        ``"default"``, or ``"asymmetric"`` once an auto-arc plan's test called the specimen
        not twofold symmetric and the scan went on over the full turn (finishing then
        reconstructs with the basis whose prior holds odd harmonics, docs/science.md 7.4)
    """

    angles_deg: Sequence[float]
    values: NDArray[np.float64]
    budget_angles: int | None
    min_step_deg: float
    min_gain: float
    arc_deg: tuple[float, float]
    basis: str = "default"


class Refiner(Protocol):
    """The posterior rule of adaptive plans (:class:`gonio.refinement.PosteriorRefiner`)."""

    def next_angles(self, request: RoundRequest) -> list[float]:
        """New specimen angles (degrees, sorted) for the next round; empty: stop.

        Raises ValueError, OSError or RuntimeError when the rule cannot run (no basis,
        unusable readings): the round then falls back to V&F's rule.
        """
        ...

    def describe(self) -> dict[str, Any]:
        """What the last :meth:`next_angles` saw, for the round's event (empty before); with
        the basis it planned with (``basis``), when it knows."""
        ...


@dataclass(frozen=True)
class NextRound:
    """A round's plan: ``angles_deg`` to measure next (empty: the job is measured) and the
    job events ``(type, data)`` that say why, in the order they happened."""

    angles_deg: list[float]
    events: list[tuple[str, dict[str, Any]]] = field(default_factory=list)


class Rounds(Protocol):
    """The rounds of one job's plan."""

    async def next_round(self, angles_deg: Sequence[float], values: NDArray[np.float64],
                         planned_angles: int, last_round: int) -> NextRound:
        """The round after ``last_round``, given the measured angles and their ``raw - dark``
        values ``(n_pairs, r, C)`` and the stage angles the job has planned so far."""
        ...


class SingleRound:
    """A plan measured in one round (uniform and calibration plans)."""

    async def next_round(self, angles_deg: Sequence[float], values: NDArray[np.float64],
                         planned_angles: int, last_round: int) -> NextRound:
        return NextRound([])


class AdaptiveRounds:
    """The refinement rounds of an adaptive plan (math.md 9; docs/science.md 7.3).

    Parameters
    ----------
    checked : the job's plan, an :class:`~gonio.plans.models.AdaptivePlan`
    refiner : the posterior rule, or None (then V&F's rule, whatever the plan's ``rule``)
    arc_deg : ``(start_deg, span_deg)`` to refine in, degrees; default the plan's
        (:attr:`CheckedPlan.arc_deg`); an auto-arc plan's is the arc its test chose
    basis : the basis the job will finish with (:attr:`RoundRequest.basis`): ``"default"``,
        or ``"asymmetric"`` after an auto-arc test called the specimen not twofold symmetric
    """

    def __init__(self, checked: CheckedPlan, refiner: Refiner | None = None,
                 arc_deg: tuple[float, float] | None = None, basis: str = "default") -> None:
        plan = checked.plan
        if not isinstance(plan, AdaptivePlan):
            raise TypeError(f"adaptive rounds need an adaptive plan, not {plan.kind!r}")
        self.plan = plan
        self.refiner = refiner
        self.arc_deg = checked.arc_deg if arc_deg is None else arc_deg
        self.basis = basis
        self.min_step_deg = plan.min_step_deg or checked.rig.resolution_deg
        # The sample budget, the plan's cap on stage angles, and in any case the cap per job
        # (so the dry run's bound holds and a job cannot grow without end).
        limit = MAX_ROTATIONS if plan.max_rotations is None else plan.max_rotations
        if plan.max_samples is not None:
            limit = min(limit, plan.max_samples // len(checked.pairs))
        self.limit_angles = limit

    async def next_round(self, angles_deg: Sequence[float], values: NDArray[np.float64],
                         planned_angles: int, last_round: int) -> NextRound:
        plan = self.plan
        budget = self.limit_angles - planned_angles
        limit = ("max_rounds" if last_round + 1 >= plan.max_rounds
                 else "budget" if budget <= 0 else None)
        events: list[tuple[str, dict[str, Any]]] = []
        # At a limit the rule is still asked (without one), so the job can say whether it
        # stopped refined or short of what its rule wanted.
        new, rule, seen = await self._ask(angles_deg, values, None if limit else budget,
                                          last_round, events)
        if limit is not None:
            done: dict[str, Any] = {"reason": limit, "rule": rule, "wanted": len(new), **seen}
            if new:
                done["message"] = limit_message(limit, plan.max_rounds, self.limit_angles,
                                                planned_angles, len(new), rule)
            events.append(("adaptive_done", done))
            return NextRound([], events)
        if not new:
            events.append(("adaptive_done", {"reason": "converged", "rule": rule, **seen}))
            return NextRound([], events)
        events.append(("adaptive_round", {"round": last_round + 1, "rule": rule,
                                          "angles": len(new), **seen}))
        return NextRound(list(new), events)

    async def _ask(self, angles_deg: Sequence[float], values: NDArray[np.float64],
                   budget: int | None, last_round: int,
                   events: list[tuple[str, dict[str, Any]]]
                   ) -> tuple[list[float], str, dict[str, Any]]:
        """The angles the plan's rule would add (at most ``budget``; None: no limit), the rule
        that answered and what it saw; a posterior rule that cannot run leaves an event in
        ``events`` and V&F's rule answers."""
        plan = self.plan
        # Either rule refines within the plan's arc: over half a turn the gaps are those
        # modulo 180 and new angles stay in [start, start + 180) (docs/science.md 7.3).
        start, span = self.arc_deg
        new: list[float] | None = None
        rule = "vf"
        if plan.rule == "posterior" and self.refiner is not None and np.isfinite(values).all():
            # The joint fit's posterior (docs/science.md 7.3): CPU work of a second or so,
            # off the event loop so pause/abort stay responsive. If it cannot run (no basis,
            # unusable readings), the scan goes on with V&F's rule rather than failing.
            request = RoundRequest(angles_deg, values, budget, self.min_step_deg,
                                   plan.min_gain, self.arc_deg, self.basis)
            try:
                new = await asyncio.to_thread(self.refiner.next_angles, request)
                rule = "posterior"
            except (ValueError, OSError, RuntimeError) as exc:
                events.append(("adaptive_round", {"round": last_round + 1, "rule": "vf",
                                                  "posterior_failed": str(exc)[:300]}))
        if new is None:
            new = adaptive_refinement(angles_deg, values, plan.threshold, self.min_step_deg,
                                      budget, period_deg=span, start_deg=start)
        # What the posterior rule saw (the basis it planned with, its rho, offset and drops),
        # so a lab can tell why it went on or stopped.
        seen = self.refiner.describe() if rule == "posterior" and self.refiner else {}
        return list(new), rule, dict(seen)


def limit_message(limit: str, max_rounds: int, limit_angles: int, planned_angles: int,
                  wanted: int, rule: str) -> str:
    """The sentence of an adaptive plan stopped at a limit while its rule still asked for
    ``wanted`` more stage angles (event ``adaptive_done``, the result's ``adaptive_limit``)."""
    what = (f"its {max_rounds} rounds (max_rounds)" if limit == "max_rounds"
            else f"its limit of {counted(limit_angles, 'stage angle')} (max_rotations or "
                  "max_samples)")
    raise_ = "max_rounds" if limit == "max_rounds" else "max_rotations (or max_samples)"
    return (f"the adaptive plan stopped at {what} with {counted(planned_angles, 'angle')} "
            "read, while "
            f"its rule ({rule}) still asked for {wanted} more: the reconstruction is less "
            f"refined than the rule would make it; raise {raise_} to let it finish")


class ArcRounds:
    """The rounds of an auto-arc plan (``arc = "auto"``, :mod:`gonio.plans.arc`).

    Round 0 read the half-turn angles and one or two of their opposites
    (:func:`gonio.plans.arc.first_round_angles`). After it, the twofold symmetry test on its
    readings chooses the arc (event ``arc_test``): symmetric, the plan goes on over half a
    turn as a fixed half-turn plan would (an adaptive plan refines in it); not symmetric, round
    1 reads the remaining opposites (:func:`gonio.plans.arc.fill_angles`), and an adaptive
    plan then refines over the full turn with the posterior of the basis finishing will
    reconstruct with (:func:`refinement_basis`: the one for specimens without twofold
    symmetry). Only round 0's readings are tested, so the choice (the arc and the basis) does
    not depend on what later rounds read, and a resumed job, given its stored test, makes the
    same one.

    Parameters
    ----------
    checked : the job's plan, with ``arc = "auto"``
    refiner : the posterior rule of an adaptive plan, or None
    chosen : the ``arc_test`` event's data when the job already chose (a resumed job: it
        continues on that arc and the test is neither run nor recorded again)
    """

    def __init__(self, checked: CheckedPlan, refiner: Refiner | None = None,
                 chosen: dict[str, Any] | None = None) -> None:
        plan = checked.plan
        if plan.arc_mode() != "auto":
            raise TypeError("arc rounds need a plan with arc 'auto'")
        self.checked = checked
        self.refiner = refiner
        self.chosen = chosen
        self.start_deg = float(plan.start_deg)
        self.rotations = plan.first_rotations()
        self.relative = float(getattr(plan, "arc_noise", 0.01))
        self._then: Rounds | None = None

    @property
    def arc_deg(self) -> float | None:
        """The arc chosen, degrees (180 or 360); None before the test."""
        return None if self.chosen is None else float(self.chosen["arc_deg"])

    def _after(self) -> Rounds:
        """The rounds after the test (and the fill round): the plan kind's, in the arc chosen."""
        if self._then is None:
            arc = (self.start_deg, float(self.chosen["arc_deg"]) if self.chosen else 360.0)
            self._then = (AdaptiveRounds(self.checked, self.refiner, arc,
                                         refinement_basis(self.chosen))
                          if self.checked.plan.refines else SingleRound())
        return self._then

    async def next_round(self, angles_deg: Sequence[float], values: NDArray[np.float64],
                         planned_angles: int, last_round: int) -> NextRound:
        events: list[tuple[str, dict[str, Any]]] = []
        if self.chosen is None:
            # Round 0's readings, all of them: a job resumed after its pairs changed (or stored
            # by another version) may hold an opposite the current first round does not list,
            # and it still tells. Later rounds never reach here untested (the choice is stored
            # before the fill), but only first-round angles would count if they did.
            first = set(round(a, 6) for a in self.checked.angles_deg)
            keep = [j for j, a in enumerate(angles_deg)
                    if last_round == 0 or round(float(a), 6) in first]
            self.chosen = await asyncio.to_thread(
                arc_test, [angles_deg[j] for j in keep], np.asarray(values)[:, keep, :],
                self.relative)
            events.append((ARC_TEST_EVENT, self.chosen))
        if last_round == 0 and not self.chosen["symmetric"]:
            # Every opposite the first round did not read, whatever count its stored route
            # held: a job resumed after its pairs changed (or stored by another version) may
            # have read one opposite where checked.angles_deg now holds two, or the reverse.
            fill = fill_after(self.start_deg, self.rotations, angles_deg)
            if fill:
                return NextRound(fill, events)
        nxt = await self._after().next_round(angles_deg, values, planned_angles, last_round)
        return NextRound(nxt.angles_deg, events + nxt.events)


def refinement_basis(test: dict[str, Any] | None) -> str:
    """The basis an auto-arc plan's refinement plans with, given its ``arc_test`` data:
    ``"asymmetric"`` when the test ran, called the specimen not twofold symmetric and chose
    the full turn (the case in which finishing reconstructs with the basis for such
    specimens, :func:`gonio.finishing._basis_for_test`), else ``"default"``."""
    if test is None or test.get("statistic") is None or test.get("symmetric", True):
        return "default"
    return "asymmetric" if float(test.get("arc_deg", 180.0)) >= 360.0 else "default"


def rounds_for(checked: CheckedPlan, refiner: Refiner | None = None,
               chosen: dict[str, Any] | None = None) -> Rounds:
    """The rounds of ``checked``'s plan kind: an auto-arc plan tests its arc first, adaptive
    plans refine, the others do not. ``chosen``: a resumed auto-arc job's stored
    ``arc_test`` data (:class:`ArcRounds`)."""
    if checked.plan.arc_mode() == "auto":
        return ArcRounds(checked, refiner, chosen)
    if checked.plan.refines:
        return AdaptiveRounds(checked, refiner)
    return SingleRound()
