"""Parsing plans from JSON and dicts (gonio.plans.models)."""

from __future__ import annotations

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
