"""A plan checked once, and what the check found (gonio.plans.checked)."""

from __future__ import annotations

import pytest

from gonio.hal import PairSpec
from gonio.plans.checked import CheckedPlan, check_plan
from gonio.plans.dryrun import dry_run
from gonio.plans.models import AdaptivePlan, PlanError, UniformPlan
from gonio.plans.route import order_for_travel
from gonio.rigdescription import RigDescription


def test_the_check_keeps_pairs_lights_and_angles(desc: RigDescription) -> None:
    """The pairs are the plan's, in its order; the lights each once in first-appearance
    order; the first round is start + k span / r (written out from the plan's settings)."""
    pairs = [PairSpec(light="L1", sensor="S2"), PairSpec(light="L2", sensor="S1"),
             PairSpec(light="L1", sensor="S1")]
    got = check_plan(UniformPlan(pairs=pairs, rotations=4, start_deg=10.0, span_deg=180.0), desc)
    assert list(got.pairs) == pairs
    assert got.lights == ("L1", "L2")
    assert got.sensors_of == {"L1": ("S2", "S1"), "L2": ("S1",)}
    assert got.angles_deg == pytest.approx((10.0, 55.0, 100.0, 145.0))
    assert got.arc_deg == (10.0, 180.0)
    assert sorted(p % 360.0 for p in got.route_deg) == pytest.approx(list(got.angles_deg))


def test_a_plan_without_pairs_measures_every_pair_of_the_rig(desc: RigDescription) -> None:
    assert list(check_plan(UniformPlan(), desc).pairs) == list(desc.pairs)


def test_a_checked_plan_is_not_checked_again(desc: RigDescription) -> None:
    """Handing on a checked plan returns it as it is (same object) on the same rig; from
    another stage position only the route is taken again; on another rig it is checked anew
    (and refused there if it does not fit)."""
    checked = check_plan(UniformPlan(rotations=4, span_deg=360.0), desc)
    assert check_plan(checked, desc) is checked
    assert check_plan(checked, desc.model_copy()) is checked  # an equal description
    moved = check_plan(checked, desc, from_deg=100.0)
    assert moved.pairs == checked.pairs and moved.from_deg == 100.0
    assert list(moved.route_deg) == order_for_travel(checked.angles_deg, 100.0, desc)
    assert moved.route_deg != checked.route_deg
    coarse = desc.model_copy(update={"resolution_deg": 100.0})
    with pytest.raises(PlanError, match="finer than the stage resolution"):
        check_plan(checked, coarse)


def test_the_check_refuses_what_the_dry_run_refuses(desc: RigDescription) -> None:
    """A first round that cannot be visited in one direction inside the travel is refused
    by the check, with the dry run's message (the submission relies on it)."""
    tight = desc.model_copy(update={"stage_min_deg": 0.0, "stage_max_deg": 200.0})
    plan = UniformPlan(rotations=4, start_deg=100.0)  # 100, 190, 280, 10: 280 out of travel
    with pytest.raises(PlanError) as by_dry_run:
        dry_run(plan, tight)
    with pytest.raises(PlanError) as by_check:
        check_plan(plan, tight)
    assert str(by_check.value) == str(by_dry_run.value)


def test_the_dry_run_of_a_checked_plan_is_the_plans(desc: RigDescription) -> None:
    plan = AdaptivePlan(initial_rotations=8, rule="vf")
    assert dry_run(check_plan(plan, desc), desc, 37.0) == dry_run(plan, desc, 37.0)


def test_the_engines_facts(desc: RigDescription) -> None:
    """An adaptive plan's bound on its stage angles is the dry run's; a fixed plan has none;
    the ETA of one angle is one uniform step's move, settles and exposures (positive)."""
    plan = AdaptivePlan(initial_rotations=8, rule="vf", max_rounds=3)
    checked = check_plan(plan, desc)
    assert checked.max_angles == dry_run(plan, desc).max_angles
    assert check_plan(UniformPlan(), desc).max_angles is None
    assert checked.per_angle_s > plan.exposure.exposure_s * len(checked.lights)
    assert isinstance(checked, CheckedPlan)
