"""The hardware interfaces' own behaviour: fault messages, directions, limits, a rig that
opens all its devices or none, and the default one-range sensor."""

from __future__ import annotations

import asyncio
import math

import pytest

from gonio import hal
from gonio.sim.memrig import MemRig, MemStage


def test_a_fault_names_its_device_and_keeps_its_code() -> None:
    f = hal.StageFault("stage", "overload; lower the load", code="overload")
    assert str(f) == "stage: overload; lower the load"
    assert (f.device, f.code, f.recoverable, f.secondary) == ("stage", "overload", True, False)
    in_use = hal.DeviceInUse("S1", "port held by pid 7")
    assert isinstance(in_use, hal.DeviceUnavailable)
    assert (in_use.code, in_use.recoverable) == ("in_use", False)  # retrying cannot help


@pytest.mark.parametrize(("theta", "phi", "vector"), [
    (0.0, 123.0, (0.0, 0.0, 1.0)),
    (90.0, 0.0, (1.0, 0.0, 0.0)),
    (90.0, 90.0, (0.0, 1.0, 0.0)),
    (60.0, 180.0, (-math.sqrt(3) / 2, 0.0, 0.5)),
])
def test_lab_directions(theta: float, phi: float, vector: tuple[float, float, float]) -> None:
    assert hal.LabDirection(theta, phi).vector() == pytest.approx(vector, abs=1e-12)


def test_travel_limits_are_inclusive() -> None:
    lim = hal.TravelLimits(-10.0, 370.0)
    assert lim.contains(-10.0) and lim.contains(370.0) and lim.contains(0.0)
    assert not lim.contains(-10.001) and not lim.contains(370.001)


def test_a_pair_naming_a_missing_device_is_refused() -> None:
    rig = MemRig()
    with pytest.raises(ValueError, match="pair L9/S1: no light named 'L9' in the rig"):
        hal.Rig(rig.stage, rig.lights, rig.sensors, [hal.PairSpec(light="L9", sensor="S1")])
    with pytest.raises(ValueError, match="pair L1/S9: no sensor named 'S9' in the rig"):
        hal.Rig(rig.stage, rig.lights, rig.sensors, [hal.PairSpec(light="L1", sensor="S9")])
    assert hal.PairSpec(light="L1", sensor="S1").label() == "L1/S1"


class BrokenLight(hal.Light):
    def __init__(self, name: str, log: list[str], fail_close: bool = False) -> None:
        self.name, self.log, self.fail_close = name, log, fail_close
        self.direction = hal.LabDirection(0, 0)

    async def connect(self) -> None:
        raise hal.DeviceUnavailable(self.name, "no reply", code="timeout")

    async def close(self) -> None:
        self.log.append(f"close {self.name}")
        if self.fail_close:
            raise OSError("already gone")

    async def set_on(self, on: bool) -> None: ...

    async def set_level(self, level: float) -> None: ...

    async def status(self) -> hal.LightStatus:
        return hal.LightStatus(False, 0.0)


def test_a_rig_that_cannot_connect_closes_what_it_opened() -> None:
    mem = MemRig()
    log: list[str] = []
    rig = hal.Rig(mem.stage, {"L1": mem.lights["L1"], "LX": BrokenLight("LX", log)},
                  mem.sensors, [])
    with pytest.raises(hal.DeviceUnavailable, match="LX: no reply"):
        asyncio.run(rig.connect())
    # the stage and L1 connected before LX failed; they are closed, newest first; no sensor
    # was touched
    assert mem.log.calls == [("stage", "connect", None), ("L1", "connect", None),
                             ("L1", "close", None), ("stage", "close", None)]


def test_closing_goes_on_past_a_device_that_fails_to_close() -> None:
    mem = MemRig()
    log: list[str] = []
    rig = hal.Rig(mem.stage, {"LX": BrokenLight("LX", log, fail_close=True)},
                  {"S1": mem.sensors["S1"]}, [])
    asyncio.run(rig.close())
    assert log == ["close LX"]
    assert mem.log.calls == [("S1", "close", None), ("stage", "close", None)]


def test_a_one_range_sensor_refuses_another_range() -> None:
    sensor = MemRig().sensors["S1"]
    assert sensor.ranges == (1.0,)
    reading = asyncio.run(sensor.read_in_range(0.0, 1, 0))
    assert reading.range_index == 0 and reading.range_scale == 1.0
    with pytest.raises(ValueError, match="S1: no range 1; this sensor has one range"):
        asyncio.run(sensor.read_in_range(0.0, 1, 1))


def test_status_at_rest_waits_for_the_stage_to_stop_ringing() -> None:
    class Ringing(MemStage):
        polls = 0

        async def status(self) -> hal.StageStatus:
            self.polls += 1
            return hal.StageStatus(self.pos, self.polls < 3, True)

    stage = Ringing(MemRig().log)
    st = asyncio.run(hal.status_at_rest(stage, timeout_s=30, poll_s=0.001))
    assert not st.moving and stage.polls == 3


def test_status_at_rest_reports_a_stage_that_keeps_moving() -> None:
    class Moving(MemStage):
        async def status(self) -> hal.StageStatus:
            return hal.StageStatus(self.pos, True, True)

    assert asyncio.run(hal.status_at_rest(Moving(MemRig().log), timeout_s=0.0)).moving


class LoggedLight(hal.Light):
    """A light with only the abstract methods: what the base class does with them."""

    def __init__(self, in_band: bool) -> None:
        self.name, self.in_band, self.calls = "LX", in_band, []  # type: list[str]
        self.direction = hal.LabDirection(0, 0)

    async def connect(self) -> None: ...

    async def close(self) -> None: ...

    async def set_on(self, on: bool) -> None:
        self.calls.append(f"set_on {on}")

    async def set_level(self, level: float) -> None: ...

    async def status(self) -> hal.LightStatus:
        self.calls.append("status")
        return hal.LightStatus(True, 0.7, self.in_band)


def test_the_base_light_switches_on_by_set_on_and_checks_by_status() -> None:
    light = LoggedLight(in_band=True)
    asyncio.run(light.switch_on(check=False))
    asyncio.run(light.check_output())
    assert light.calls == ["set_on True", "status"]
    bad = LoggedLight(in_band=False)
    with pytest.raises(hal.LampOutOfBand,
                       match=r"LX: output level 0\.7 is outside its allowed band") as err:
        asyncio.run(bad.check_output())
    assert err.value.code == "out_of_band"


def test_a_stage_runs_its_configured_profile_unless_its_driver_knows_better() -> None:
    stage = MemStage(MemRig().log, speed_dps=90.0)
    assert stage.profile_dps == (90.0, stage.accel_dps2)
