"""Plan validation, ordering, timing and adaptive refinement (no hardware)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gonio.plans import (
    AdaptivePlan,
    CalibrationPlan,
    ExposureSettings,
    PairSpec,
    PlanError,
    RigDescription,
    UniformPlan,
    adaptive_refinement,
    dry_run,
    move_time,
    order_for_travel,
    parse_plan,
    validate_plan,
)
from tests.unit.engine.memrig import MemRig


@pytest.fixture
def desc() -> RigDescription:
    return RigDescription.from_rig(MemRig(speed_dps=30.0))


def _limited(desc: RigDescription, lo: float, hi: float) -> RigDescription:
    return desc.model_copy(update={"stage_min_deg": lo, "stage_max_deg": hi})


def test_uniform_dry_run_counts_and_times(desc: RigDescription) -> None:
    plan = UniformPlan(rotations=6, exposure=ExposureSettings(exposure_s=0.1, averages=2,
                                                              light_settle_s=0.05, dark="once"))
    d = dry_run(plan, desc)
    assert d.angles_deg == [0, 60, 120, 180, 240, 300]
    assert d.readings == 3 * 6  # three pairs
    assert d.lights == ["L1", "L2"]
    assert d.exposures == 6 * 2 + 1  # one per light and angle, one dark
    assert d.exposure_s == pytest.approx(13 * 0.2)
    assert d.motion_s == pytest.approx(5 * move_time(60, 30.0, 300.0))
    assert d.estimated_s == pytest.approx(d.motion_s + d.settle_s + d.exposure_s)


def test_move_time_trapezoid_and_triangle() -> None:
    assert move_time(90, 30, 60) == pytest.approx(90 / 30 + 30 / 60)
    assert move_time(1, 30, 60) == pytest.approx(2 * math.sqrt(1 / 60))
    assert move_time(0, 30, 60) == 0


@pytest.mark.parametrize(
    ("plan", "match"),
    [
        (UniformPlan(rotations=0), "at least one stage angle"),
        (UniformPlan(rotations=100000), "duplicate angles"),
        (UniformPlan(pairs=[]), "no pairs"),
        (UniformPlan(pairs=[PairSpec(light="L2", sensor="S2")]), "not one of the rig's pairs"),
        (UniformPlan(pairs=[PairSpec(light="L1", sensor="S1")] * 2), "listed twice"),
        (UniformPlan(exposure=ExposureSettings(exposure_s=20.0)), "outside sensor"),
        (AdaptivePlan(initial_rotations=2), "at least 3"),
        (AdaptivePlan(max_samples=5), "smaller than the first round"),
        (AdaptivePlan(min_step_deg=0.001), "finer than the stage resolution"),
    ],
)
def test_bad_plans_refused(desc: RigDescription, plan: object, match: str) -> None:
    with pytest.raises(PlanError, match=match):
        validate_plan(plan, desc)  # type: ignore[arg-type]


def test_angles_beyond_travel_refused(desc: RigDescription) -> None:
    small = _limited(desc, 0.0, 180.0)
    with pytest.raises(PlanError, match=r"outside the stage travel \[0, 180\]"):
        validate_plan(UniformPlan(rotations=4), small)
    validate_plan(UniformPlan(rotations=1, start_deg=90), small)


def test_parse_plan_messages() -> None:
    with pytest.raises(PlanError, match="kind"):
        parse_plan({"kind": "spiral"})
    with pytest.raises(PlanError, match="exposure_s"):
        parse_plan('{"kind": "uniform", "exposure": {"exposure_s": -1}}')
    p = parse_plan({"kind": "calibration", "reference_albedo": 0.99})
    assert isinstance(p, CalibrationPlan)
    assert parse_plan(p.model_dump_json()) == p


def test_order_is_increasing_and_starts_near_the_stage(desc: RigDescription) -> None:
    angles = [0, 90, 180, 270]
    route = order_for_travel(angles, 100.0, desc)
    assert all(b > a for a, b in itertools.pairwise(route))
    # Back 10 deg to 90, then up to 360 (280 deg) beats 180 -> 450 (350 deg).
    assert route == pytest.approx([90.0, 180.0, 270.0, 360.0])
    # From 175 the route starting ahead at 180 is shorter.
    assert order_for_travel(angles, 175.0, desc)[0] == pytest.approx(180.0)
    assert sorted(a % 360 for a in route) == angles
    # A stage that cannot pass 360 must go back to the lowest angle first.
    route = order_for_travel(angles, 100.0, _limited(desc, 0.0, 300.0))
    assert route == [0, 90, 180, 270]


def test_adaptive_refines_where_pchip_fails() -> None:
    a = np.arange(8) * 45.0
    smooth = 1 + 0.1 * np.cos(np.deg2rad(a))
    values = np.stack([smooth, smooth], axis=0)[:, :, None]
    assert adaptive_refinement(a, values, 0.1, 0.5, None) == []
    spiky = smooth.copy()
    spiky[2] = 3.0  # a narrow highlight at 90 deg
    values = np.stack([smooth, spiky], axis=0)[:, :, None]
    new = adaptive_refinement(a, values, 0.1, 0.5, None)
    assert 67.5 in new and 112.5 in new
    assert all(x not in a for x in new)
    assert len(adaptive_refinement(a, values, 0.1, 0.5, 1)) == 1
    assert adaptive_refinement(a, values, 0.1, 30.0, None) == []  # min step stops refinement
