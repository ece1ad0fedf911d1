"""The simulated rig's session helpers that need no daemon: the white reference's plan, the
hand that puts the right thing on the stage for each job, and the specimen's recipe beside
its rig config. With a daemon: tests/system/api/test_sim_calibration.py."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from gonio.brdf.models import analytic as bm
from gonio.cli.sim_session import (
    follow_jobs_with_holder,
    sim_calibration_plan,
    sim_specimen_path,
    write_sim_specimen,
)
from gonio.figures import material_from_description
from gonio.plans.models import CalibrationPlan


def test_the_white_reference_plan_names_its_albedo() -> None:
    plan = sim_calibration_plan(0.8)
    assert isinstance(plan, CalibrationPlan)
    assert plan.reference_albedo == 0.8 and plan.specimen == "white reference"
    assert plan.reference_name == "simulated white reference, albedo 0.8"
    assert sim_calibration_plan().reference_albedo == 0.99  # docs/api.md: albedo 0.99


class Hand:
    """A simulated rig's holder: records what is put on the stage."""

    def __init__(self) -> None:
        self.placed: list[object] = []

    def place_white_reference(self, albedo: float) -> None:
        self.placed.append(("white reference", albedo))

    def load(self, what: str) -> None:
        self.placed.append(what)


def test_each_job_gets_what_it_measures_on_the_stage() -> None:
    service, hand = SimpleNamespace(on_job_start=None), Hand()
    follow_jobs_with_holder(service, hand)
    service.on_job_start(SimpleNamespace(kind="calibration", plan={"reference_albedo": 0.9}))
    service.on_job_start(SimpleNamespace(kind="uniform", plan={}))
    assert hand.placed == [("white reference", 0.9), "specimen"]


def test_the_recipe_is_written_beside_the_rig_config(tmp_path: Path) -> None:
    config = tmp_path / "lab-sim.toml"
    # docs/file-formats.md: <rig>.sim-specimen.json beside a rig config
    assert sim_specimen_path(config) == tmp_path / "lab-sim.sim-specimen.json"
    red = bm.Lambert((0.6, 0.1, 0.1), name="red card")
    sim = SimpleNamespace(specimen=SimpleNamespace(brdf=red), config_path=config)
    path = write_sim_specimen(sim)
    assert path == sim_specimen_path(config)
    again = material_from_description(json.loads(path.read_text()))
    assert again.name == "red card" and again.albedo == red.albedo


def test_no_recipe_without_a_config_or_a_describable_specimen(tmp_path: Path) -> None:
    red = bm.Lambert((0.6, 0.1, 0.1))
    assert write_sim_specimen(SimpleNamespace(specimen=SimpleNamespace(brdf=red),
                                              config_path=None)) is None
    odd = SimpleNamespace(specimen=SimpleNamespace(brdf=object()),
                          config_path=tmp_path / "r.toml")
    assert write_sim_specimen(odd) is None
    assert list(tmp_path.iterdir()) == []
