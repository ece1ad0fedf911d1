"""Plan validation against a rig: clear refusals, the rotation cap (gonio.plans.validation)."""

from __future__ import annotations

import pytest

from gonio.hal import PairSpec
from gonio.plans.dryrun import dry_run
from gonio.plans.models import (
    MAX_ROTATIONS,
    AdaptivePlan,
    ExposureSettings,
    PlanError,
    UniformPlan,
)
from gonio.plans.validation import validate_plan
from gonio.rigdescription import RigDescription


def _limited(desc: RigDescription, lo: float, hi: float) -> RigDescription:
    return desc.model_copy(update={"stage_min_deg": lo, "stage_max_deg": hi})


@pytest.mark.parametrize(
    ("plan", "match"),
    [
        (UniformPlan(rotations=0), "at least one stage angle"),
        (UniformPlan(rotations=100000), "at most 3600 stage angles"),
        # An empty list, not null (every pair): said as the plan's, not the rig config's.
        (UniformPlan(pairs=[]), r"the plan's pairs list is empty, so it measures nothing; "
         r"leave pairs out \(or null\) to measure all \d+ of the rig's pairs"),
        (UniformPlan(pairs=[PairSpec(light="L2", sensor="S2")]), "not one of the rig's pairs"),
        (UniformPlan(pairs=[PairSpec(light="L1", sensor="S1")] * 2), "listed twice"),
        (UniformPlan(exposure=ExposureSettings(exposure_s=20.0)),
         "outside the exposure range of sensor"),
        (AdaptivePlan(initial_rotations=2), "at least 3"),
        (AdaptivePlan(max_samples=5), "smaller than the first round"),
        (AdaptivePlan(min_step_deg=0.001), "finer than the stage resolution"),
    ],
)
def test_bad_plans_refused(desc: RigDescription, plan: object, match: str) -> None:
    with pytest.raises(PlanError, match=match):
        validate_plan(plan, desc)  # type: ignore[arg-type]


def test_angles_finer_than_the_stage_resolution_refused(desc: RigDescription) -> None:
    coarse = desc.model_copy(update={"resolution_deg": 0.1})
    # 3600 angles over half a turn are 0.05 deg apart; over a full turn 0.1 deg fits.
    with pytest.raises(PlanError, match="duplicate angles"):
        validate_plan(UniformPlan(rotations=3600), coarse)
    validate_plan(UniformPlan(rotations=3600, span_deg=360), coarse)


def test_angles_beyond_travel_refused(desc: RigDescription) -> None:
    small = _limited(desc, 0.0, 180.0)
    with pytest.raises(PlanError, match=r"outside the stage travel \[0, 180\]"):
        validate_plan(UniformPlan(rotations=4, span_deg=360), small)
    # Half a turn's angles 0, 45, 90, 135 fit this travel.
    validate_plan(UniformPlan(rotations=4), small)
    validate_plan(UniformPlan(rotations=1, start_deg=90), small)


def test_rotation_cap_is_a_clear_error(desc: RigDescription) -> None:
    validate_plan(UniformPlan(rotations=MAX_ROTATIONS), desc)
    with pytest.raises(PlanError, match=f"at most {MAX_ROTATIONS} stage angles"):
        validate_plan(UniformPlan(rotations=MAX_ROTATIONS + 1), desc)
    with pytest.raises(PlanError, match=r"initial_rotations .* at most"):
        validate_plan(AdaptivePlan(initial_rotations=5000), desc)
    # The largest plan is still checked and timed (linear ordering): every angle visited once.
    d = dry_run(UniformPlan(rotations=MAX_ROTATIONS), desc)
    assert len(d.positions_deg) == MAX_ROTATIONS
