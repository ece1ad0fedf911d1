"""The rounds a plan kind owns (gonio.plans.rounds): one round, or adaptive refinement."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from gonio.plans.adaptive import adaptive_refinement
from gonio.plans.checked import check_plan
from gonio.plans.models import AdaptivePlan, CalibrationPlan, UniformPlan
from gonio.plans.rounds import (
    AdaptiveRounds,
    NextRound,
    RoundRequest,
    SingleRound,
    rounds_for,
)
from gonio.rigdescription import RigDescription


class FixedRefiner:
    """A refiner that plans the angles it is given (or fails), recording its requests."""

    def __init__(self, angles: list[float] | Exception) -> None:
        self.angles = angles
        self.requests: list[RoundRequest] = []

    def next_angles(self, request: RoundRequest) -> list[float]:
        self.requests.append(request)
        if isinstance(self.angles, Exception):
            raise self.angles
        return list(self.angles)

    def describe(self) -> dict[str, float]:
        return {"rho": 0.5}


def _swing(angles: list[float], n_pairs: int) -> np.ndarray:
    """Readings that swing with cos 2 alpha: V&F's rule refines them."""
    a = np.deg2rad(np.asarray(angles))[None, :, None]
    return np.ones((n_pairs, 1, 1)) * (1.5 + np.cos(2 * a))


def _next(rounds: object, angles: list[float], values: np.ndarray, planned: int,
          last: int) -> NextRound:
    return asyncio.run(rounds.next_round(angles, values, planned, last))  # type: ignore[attr-defined]


def test_fixed_plans_have_one_round(desc: RigDescription) -> None:
    for plan in (UniformPlan(), CalibrationPlan(reference_albedo=0.9)):
        rounds = rounds_for(check_plan(plan, desc))
        assert isinstance(rounds, SingleRound)
        assert _next(rounds, [0.0, 90.0], np.ones((1, 2, 1)), 2, 0) == NextRound([])


def test_vf_rounds_plan_what_the_vf_rule_plans(desc: RigDescription) -> None:
    plan = AdaptivePlan(rule="vf", initial_rotations=8, max_rounds=3)
    checked = check_plan(plan, desc)
    angles = list(checked.angles_deg)
    values = _swing(angles, len(checked.pairs))
    got = _next(rounds_for(checked), angles, values, 8, 0)
    want = adaptive_refinement(angles, values, plan.threshold, desc.resolution_deg, 3600 - 8,
                               period_deg=360.0, start_deg=0.0)
    assert want and got.angles_deg == want
    assert got.events == [("adaptive_round", {"round": 1, "rule": "vf", "angles": len(want)})]


def test_the_last_round_and_the_budget_end_the_job(desc: RigDescription) -> None:
    plan = AdaptivePlan(rule="vf", initial_rotations=8, max_rounds=2, max_rotations=10)
    checked = check_plan(plan, desc)
    rounds = rounds_for(checked)
    angles = [45.0 * k for k in range(8)]
    values = _swing(angles, len(checked.pairs))
    # At a limit the rule is still asked, without one, so the job says whether it stopped
    # short of what the rule wanted: here V&F's rule wants every gap of the swing refined.
    wanted = len(adaptive_refinement(angles, values, plan.threshold, desc.resolution_deg, None,
                                     period_deg=360.0, start_deg=0.0))
    assert wanted > 0
    got = _next(rounds, angles, values, 8, 1)
    assert got.angles_deg == []
    ((kind, data),) = got.events
    assert kind == "adaptive_done" and data["reason"] == "max_rounds"
    assert data["wanted"] == wanted and data["rule"] == "vf"
    assert "stopped at its 2 rounds (max_rounds)" in data["message"]
    assert f"still asked for {wanted} more" in data["message"]
    ((kind, data),) = _next(rounds, angles, values, 10, 0).events
    assert data["reason"] == "budget" and data["wanted"] == wanted
    assert "its limit of 10 stage angles" in data["message"] and "raise max_rotations" in \
        data["message"]
    # Flat readings: the rule wants nothing more, and the limit is not a shortfall.
    flat = np.ones_like(values)
    ((kind, data),) = _next(rounds, angles, flat, 10, 0).events
    assert data == {"reason": "budget", "rule": "vf", "wanted": 0}


def test_the_posterior_rule_is_asked_with_the_plans_settings(desc: RigDescription) -> None:
    plan = AdaptivePlan(initial_rotations=4, min_gain=0.02, max_rotations=16)
    checked = check_plan(plan, desc)
    refiner = FixedRefiner([22.5, 67.5])
    angles = list(checked.angles_deg)
    got = _next(AdaptiveRounds(checked, refiner), angles, _swing(angles, len(checked.pairs)),
                4, 0)
    assert got.angles_deg == [22.5, 67.5]
    assert got.events == [("adaptive_round",
                           {"round": 1, "rule": "posterior", "angles": 2, "rho": 0.5})]
    (req,) = refiner.requests
    assert (req.budget_angles, req.min_gain, req.arc_deg) == (12, 0.02, (0.0, 180.0))
    assert req.min_step_deg == desc.resolution_deg


def test_a_failing_posterior_rule_falls_back_to_vf_and_says_so(desc: RigDescription) -> None:
    plan = AdaptivePlan(initial_rotations=4, max_rotations=16)
    checked = check_plan(plan, desc)
    angles = list(checked.angles_deg)
    values = _swing(angles, len(checked.pairs))
    got = _next(AdaptiveRounds(checked, FixedRefiner(RuntimeError("no basis"))), angles,
                values, 4, 0)
    assert got.events[0] == ("adaptive_round",
                             {"round": 1, "rule": "vf", "posterior_failed": "no basis"})
    assert got.events[-1][1]["rule"] == "vf"


def test_a_posterior_plan_without_refiner_uses_vf(desc: RigDescription) -> None:
    """Without a refiner (the basis could not be had) the rule is V&F's, and it says so."""
    checked = check_plan(AdaptivePlan(initial_rotations=4), desc)
    angles = list(checked.angles_deg)
    got = _next(AdaptiveRounds(checked), angles, _swing(angles, len(checked.pairs)), 4, 0)
    assert got.events and all(e[1].get("rule") == "vf" for e in got.events)


def test_only_adaptive_plans_have_adaptive_rounds(desc: RigDescription) -> None:
    with pytest.raises(TypeError, match="adaptive plan"):
        AdaptiveRounds(check_plan(UniformPlan(), desc))
