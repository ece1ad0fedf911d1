"""Parsing plans from JSON and dicts (gonio.plans.models)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gonio.plans.models import (
    CalibrationPlan,
    PlanError,
    parse_plan,
)


def test_parse_plan_messages() -> None:
    with pytest.raises(PlanError, match="kind"):
        parse_plan({"kind": "spiral"})
    with pytest.raises(PlanError, match="exposure_s"):
        parse_plan('{"kind": "uniform", "exposure": {"exposure_s": -1}}')
    p = parse_plan({"kind": "calibration", "reference_albedo": 0.99})
    assert isinstance(p, CalibrationPlan)
    assert parse_plan(p.model_dump_json()) == p


def test_the_first_round_of_an_adaptive_plan_defaults_by_rule() -> None:
    """4 angles for the posterior rule (docs/science.md 7.3), V&F's 8 for theirs, from JSON as
    from Python; a number given is kept, and a stored plan keeps what it was stored with."""
    from gonio.plans.models import AdaptivePlan

    assert parse_plan('{"kind": "adaptive"}').first_rotations() == 4
    assert parse_plan({"kind": "adaptive", "rule": "vf"}).first_rotations() == 8
    assert parse_plan({"kind": "adaptive", "rule": "vf", "initial_rotations": 5}
                      ).first_rotations() == 5
    stored = AdaptivePlan(rule="vf").model_dump(mode="json")
    assert parse_plan({**stored, "rule": "posterior"}).first_rotations() == 8


def test_the_cap_on_stage_angles_defaults_by_rule() -> None:
    """16 angles in all for the posterior rule (the budget it was chosen for, docs/science.md
    7.3), no cap for V&F's; a number given (or null) is kept, as is a stored plan's."""
    from gonio.plans.models import AdaptivePlan

    assert parse_plan('{"kind": "adaptive"}').max_rotations == 16  # type: ignore[union-attr]
    assert parse_plan({"kind": "adaptive", "rule": "vf"}).max_rotations is None  # type: ignore[union-attr]
    assert parse_plan({"kind": "adaptive", "rule": "vf", "max_rotations": 24}
                      ).max_rotations == 24  # type: ignore[union-attr]
    assert parse_plan({"kind": "adaptive", "max_rotations": None}
                      ).max_rotations is None  # type: ignore[union-attr]
    stored = AdaptivePlan(rule="vf").model_dump(mode="json")
    assert parse_plan({**stored, "rule": "posterior"}).max_rotations is None  # type: ignore[union-attr]
    for bad in (0, -4, 3601, 2.5):
        with pytest.raises(PlanError, match="max_rotations"):
            parse_plan({"kind": "adaptive", "max_rotations": bad})


def test_a_plan_stored_before_the_cap_existed_keeps_its_meaning(tmp_path: Path) -> None:
    """A posterior-rule job queued by a version without ``max_rotations`` (its stored plan is a
    full dump lacking the key) runs uncapped, as submitted, after an upgrade; a new request
    gets today's default of 16; a stored plan with the key keeps its value."""
    from gonio.plans.models import AdaptivePlan, parse_stored_plan
    from gonio.store import JobStore

    old = AdaptivePlan().model_dump(mode="json")
    del old["max_rotations"]  # what the older version wrote
    capped = {**old, "max_rotations": 12}
    store = JobStore(tmp_path / "gonio.sqlite")
    ids = [store.create_job(kind="adaptive", specimen="s", plan=p, rig={}).id
           for p in (old, capped)]
    store.close()
    again = JobStore(tmp_path / "gonio.sqlite")  # the upgraded daemon's store
    plans = [parse_stored_plan(again.get_job(i).plan) for i in ids]
    again.close()
    assert plans[0].max_rotations is None  # type: ignore[union-attr]
    assert plans[1].max_rotations == 12  # type: ignore[union-attr]
    assert parse_plan(old).max_rotations == 16  # type: ignore[union-attr]
    with pytest.raises(PlanError, match="max_rotations"):
        parse_stored_plan({**old, "max_rotations": 0})


def test_the_arc_of_the_angles_defaults_to_half_a_turn() -> None:
    """Uniform and posterior-rule plans cover half a turn unless told otherwise, V&F's rule a
    full turn (its protocol); the plans' default is the numerical core's; other arcs are
    refused with what the two arcs mean."""
    from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG
    from gonio.plans.models import DEFAULT_SPAN_DEG as PLAN_DEFAULT

    assert PLAN_DEFAULT == DEFAULT_SPAN_DEG == 180.0
    assert parse_plan('{"kind": "uniform"}').first_span_deg() == 180.0
    assert parse_plan('{"kind": "adaptive"}').first_span_deg() == 180.0
    assert parse_plan({"kind": "adaptive", "rule": "vf"}).first_span_deg() == 360.0
    assert parse_plan({"kind": "uniform", "span_deg": 360}).first_span_deg() == 360.0
    assert parse_plan({"kind": "calibration", "reference_albedo": 0.9}).first_span_deg() == 360.0
    for bad in (90, 0, 720, "half"):
        with pytest.raises(PlanError, match=r"span_deg.*180.*360"):
            parse_plan({"kind": "uniform", "span_deg": bad})


def test_a_plan_stored_before_the_arc_existed_keeps_its_full_turn(tmp_path: Path) -> None:
    """Jobs queued by a version whose angles always covered a full turn (stored plans without
    ``span_deg``) run over a full turn after an upgrade; new requests get half a turn."""
    from gonio.plans.models import AdaptivePlan, UniformPlan, parse_stored_plan
    from gonio.store import JobStore

    olds = []
    for plan in (UniformPlan(), AdaptivePlan()):
        d = plan.model_dump(mode="json")
        del d["span_deg"]  # what the older version wrote
        olds.append(d)
    store = JobStore(tmp_path / "gonio.sqlite")
    ids = [store.create_job(kind=d["kind"], specimen="s", plan=d, rig={}).id for d in olds]
    store.close()
    again = JobStore(tmp_path / "gonio.sqlite")
    plans = [parse_stored_plan(again.get_job(i).plan) for i in ids]
    again.close()
    assert [p.first_span_deg() for p in plans] == [360.0, 360.0]
    assert [parse_plan(d).first_span_deg() for d in olds] == [180.0, 180.0]


def test_a_calibration_is_listed_under_its_reference_name() -> None:
    """A calibration queued with reference_name "spectralon" and no specimen was listed as
    "specimen" in the job list; a specimen given is kept, and none given at all names the
    white reference."""
    from gonio.plans.models import parse_plan

    named = parse_plan({"kind": "calibration", "reference_albedo": 0.99,
                        "reference_name": "spectralon"})
    assert named.specimen == "spectralon"
    assert parse_plan({"kind": "calibration", "reference_albedo": 0.99}).specimen == \
        "white reference"
    assert parse_plan({"kind": "calibration", "reference_albedo": 0.99,
                       "reference_name": "spectralon", "specimen": "tile 3"}).specimen == \
        "tile 3"
