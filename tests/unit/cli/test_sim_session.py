"""The simulated rig's session helpers that need no daemon: the white reference's plan, the
hand that puts the right thing on the stage for each job, and the specimen's recipe beside
its rig config. With a daemon: tests/system/api/test_sim_calibration.py."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from gonio.brdf.models import analytic as bm
from gonio.calibration import Calibration, PairCalibration
from gonio.cli.sim_session import (
    calibration_covers_rig,
    follow_jobs_with_holder,
    sim_calibration_plan,
    sim_specimen_path,
    write_sim_specimen,
)
from gonio.figures import material_from_description
from gonio.hal import PairSpec
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


def test_a_calibration_of_other_channels_does_not_cover_the_rig() -> None:
    """The simulated rig's data directory kept the RGB material's calibration (3 factors a
    pair) when the rig came back with a spectral material's 31-band sensors of the same names:
    it counted as covering, no white reference was measured, and the scan failed at its end."""
    def service(n_factors: int, n_channels: int) -> SimpleNamespace:
        cal = Calibration(pairs=(PairCalibration(light="L1", sensor="S1",
                                                 factor=(1e-5,) * n_factors),))
        sensor = SimpleNamespace(name="S1", channels=[f"c{i}" for i in range(n_channels)])
        return SimpleNamespace(calibration=lambda: cal,
                               desc=SimpleNamespace(pairs=[PairSpec(light="L1", sensor="S1")]),
                               rig_config=SimpleNamespace(sensors=[sensor]))

    assert calibration_covers_rig(service(31, 31))
    assert not calibration_covers_rig(service(3, 31))
    assert not calibration_covers_rig(service(31, 3))
