"""Core errors advise settings by the core's names; callers (the CLI) word them their way."""

from __future__ import annotations

import pickle

import pytest

from gonio.brdf.advice import AdvisedError
from gonio.brdf.design.constraints import RigConstraints, candidate_rows
from gonio.brdf.design.errors import FeasibilityError
from gonio.cli import CORE_SETTING_FLAGS


def test_message_names_knobs_as_the_core_or_as_the_caller() -> None:
    exc = AdvisedError("too crowded", "lower {gap} or pass {force}", words={"force": "force=True"})
    assert str(exc) == "too crowded; lower gap or pass force=True"
    assert exc.advise({"gap": "--gap", "force": "--force"}) == (
        "too crowded; lower --gap or pass --force"
    )
    # A knob the caller does not name keeps the core's wording.
    assert exc.advise({"gap": "--gap"}) == "too crowded; lower --gap or pass force=True"
    assert str(AdvisedError("just a problem")) == "just a problem"


def test_pickling_keeps_the_advice() -> None:
    exc = FeasibilityError("no room", "lower {min_device_distance_deg}")
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is FeasibilityError
    assert back.advise({"min_device_distance_deg": "--x"}) == "no room; lower --x"


def test_core_feasibility_message_has_no_cli_flags() -> None:
    impossible = RigConstraints(max_elevation_deg=5.0, min_separation_deg=30.0)
    with pytest.raises(FeasibilityError) as info:
        candidate_rows(impossible)
    assert "--" not in str(info.value)
    assert str(info.value).endswith(
        "raise max_elevation_deg or lower min_separation_deg / min_device_distance_deg"
    )
    # The CLI's wording is the one it always printed.
    assert info.value.advise(CORE_SETTING_FLAGS).endswith(
        "raise --max-elevation or lower --min-separation / --min-device-distance"
    )
