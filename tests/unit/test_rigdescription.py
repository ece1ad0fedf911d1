"""A rig's static facts, read from a rig without touching it, and their JSON form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from gonio.hal import PairSpec
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig


@pytest.fixture
def desc() -> RigDescription:
    return RigDescription.from_rig(MemRig(speed_dps=90.0))


def test_from_rig_reads_the_rig_as_its_documentation_describes_it(desc: RigDescription) -> None:
    # MemRig: L1 (45, 0), L2 (30, 90); S1 (45, 180), S2 (60, 200); pairs L1/S1, L1/S2, L2/S1;
    # limits -720..720, acceleration ten times the speed
    assert (desc.stage_min_deg, desc.stage_max_deg) == (-720.0, 720.0)
    assert (desc.speed_dps, desc.accel_dps2, desc.settle_s) == (90.0, 900.0, 0.0)
    assert desc.approach == "none" and desc.approach_backlash_deg == 0.0
    assert [(lt.name, lt.theta_deg, lt.phi_deg) for lt in desc.lights] == [
        ("L1", 45.0, 0.0), ("L2", 30.0, 90.0)]
    assert [(s.name, s.theta_deg, s.phi_deg, s.channels) for s in desc.sensors] == [
        ("S1", 45.0, 180.0, ("R", "G", "B")), ("S2", 60.0, 200.0, ("R", "G", "B"))]
    assert [p.label() for p in desc.pairs] == ["L1/S1", "L1/S2", "L2/S1"]


def test_the_json_form_round_trips(desc: RigDescription) -> None:
    assert RigDescription.model_validate_json(desc.model_dump_json()) == desc


def test_lookup_by_name(desc: RigDescription) -> None:
    assert desc.light("L2").phi_deg == 90.0
    assert desc.sensor("S2").theta_deg == 60.0
    with pytest.raises(KeyError, match="L9"):
        desc.light("L9")
    with pytest.raises(KeyError, match="S9"):
        desc.sensor("S9")


def test_pair_directions_are_lab_unit_vectors(desc: RigDescription) -> None:
    light, sensor = desc.pair_directions([PairSpec(light="L2", sensor="S1"),
                                          PairSpec(light="L1", sensor="S2")])
    s = math.sqrt(0.5)
    # (sin t cos p, sin t sin p, cos t) by hand
    np.testing.assert_allclose(light, [[0.0, 0.5, math.sqrt(3) / 2], [s, 0.0, s]], atol=1e-12)
    np.testing.assert_allclose(sensor[0], [-s, 0.0, s], atol=1e-12)
    assert light.shape == sensor.shape == (2, 3)


def test_an_impossible_stage_is_refused(desc: RigDescription) -> None:
    data = desc.model_dump()
    for field, bad in (("speed_dps", 0.0), ("accel_dps2", -1.0), ("settle_s", -0.1),
                       ("approach", "sideways")):
        with pytest.raises(ValidationError, match=field):
            RigDescription.model_validate({**data, field: bad})
