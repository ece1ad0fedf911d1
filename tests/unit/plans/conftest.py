"""Fixtures shared by the tests of gonio.plans."""

from __future__ import annotations

import pytest

from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig


@pytest.fixture
def desc() -> RigDescription:
    return RigDescription.from_rig(MemRig(speed_dps=30.0))
