"""The in-memory rig behaves as its documentation says: readings follow the stage angle and
the lights, calls are logged in order, and armed faults fire."""

from __future__ import annotations

import asyncio
import math

import pytest

from gonio import hal
from gonio.sim.memrig import MemRig


def test_a_reading_follows_the_lit_lights_and_the_stage_angle() -> None:
    rig = MemRig()

    async def go() -> tuple[hal.SensorReading, hal.SensorReading]:
        await rig.stage.move_to(30.0)
        dark = await rig.sensor("S1").read(0.0)
        await rig.light("L1").set_on(True)
        await rig.light("L2").set_on(True)
        return dark, await rig.sensor("S1").read(0.001, averages=2)

    dark, lit = asyncio.run(go())
    assert dark.values == pytest.approx((0.01, 0.01, 0.01))
    # per lit light 1 + 0.5 cos 2(angle - phi): L1 (phi 0) 1.25, L2 (phi 90) 0.75; scaled
    # 1, 0.8, 0.6 per channel over the dark level
    sig = 1 + 0.5 * math.cos(math.radians(60)) + 1 + 0.5 * math.cos(math.radians(-120))
    assert sig == pytest.approx(2.0)
    assert lit.values == pytest.approx((0.01 + sig, 0.01 + 0.8 * sig, 0.01 + 0.6 * sig))
    assert (lit.saturated, lit.exposure_s, lit.averages) == (False, 0.001, 2)
    assert rig.log.calls == [("stage", "move", 30.0), ("S1", "read", 30.0), ("L1", "on", None),
                             ("L2", "on", None), ("S1", "read", 30.0)]


def test_a_move_outside_the_limits_is_refused() -> None:
    rig = MemRig()
    with pytest.raises(ValueError, match=r"721\.0 outside limits"):
        asyncio.run(rig.stage.move_to(721.0))
    assert rig.mstage.moves == []


def test_an_armed_stage_fault_latches_until_cleared() -> None:
    rig = MemRig()
    rig.mstage.fault_next_moves.append(hal.StageFault("stage", "overload", code="overload"))

    async def go() -> hal.StageStatus:
        with pytest.raises(hal.StageFault, match="overload"):
            await rig.stage.move_to(10.0)
        with pytest.raises(hal.StageFault, match="latched"):
            await rig.stage.move_to(10.0)
        status = await rig.stage.status()
        await rig.stage.clear_faults()
        await rig.stage.move_to(10.0)
        return status

    assert asyncio.run(go()).faults == ("overload",)
    assert rig.mstage.moves == [10.0]


def test_a_sticky_fault_does_not_clear() -> None:
    rig = MemRig()
    rig.mstage.sticky_fault = True
    with pytest.raises(hal.StageFault, match="does not clear"):
        asyncio.run(rig.stage.clear_faults())


def test_an_unavailable_light_fails_then_answers() -> None:
    rig = MemRig()
    rig.light("L1").unavailable = 1

    async def go() -> None:
        with pytest.raises(hal.DeviceUnavailable, match="no reply"):
            await rig.light("L1").set_on(True)
        await rig.light("L1").set_on(True)

    asyncio.run(go())
    assert rig.any_light_on()


def test_a_saturation_is_reported_only_with_a_light_on() -> None:
    rig = MemRig()
    rig.sensor("S2").saturate_next = 1

    async def go() -> list[bool]:
        dark = await rig.sensor("S2").read(0.0)
        await rig.light("L1").set_on(True)
        first = await rig.sensor("S2").read(0.0)
        second = await rig.sensor("S2").read(0.0)
        return [dark.saturated, first.saturated, second.saturated]

    assert asyncio.run(go()) == [False, True, False]
