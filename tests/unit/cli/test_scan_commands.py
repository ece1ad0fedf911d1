"""The plan 'gonio scan' builds from its options (no rig needed)."""

from __future__ import annotations

from gonio.cli import build_parser
from gonio.cli.scan_commands import _plan
from gonio.plans.models import CalibrationPlan, UniformPlan


def _parse(*argv: str) -> object:
    return _plan(build_parser().parse_args(["scan", "--rig", "rig.toml", "-o", "x.h5", *argv]))


def test_white_reference_job_is_named_after_the_reference_not_the_specimen() -> None:
    # The calibration's source line ("calibration: job 1: ...") and 'gonio jobs list' show
    # this name; before, an unnamed reference was called "specimen".
    plan = _parse("--white-reference", "0.99")
    assert isinstance(plan, CalibrationPlan) and plan.reference_name == "white reference"
    named = _parse("--white-reference", "0.99", "--specimen", "spectralon-99")
    assert isinstance(named, CalibrationPlan) and named.reference_name == "spectralon-99"


def test_scan_keeps_its_specimen_names() -> None:
    plan = _parse()
    assert isinstance(plan, UniformPlan) and plan.specimen == "specimen"
    felt = _parse("--specimen", "felt")
    assert isinstance(felt, UniformPlan) and felt.specimen == "felt"
