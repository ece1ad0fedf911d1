"""Modbus lights and sensors end to end: the real drivers against the real pymodbus server.

The register map is checked through an independent raw pymodbus client as well, so an
off-by-one in either the driver or the simulator shows up as a wrong address on the wire.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from pymodbus.client import AsyncModbusTcpClient

from gonio.brdf.models.analytic import Lambert
from gonio.config import (
    LightConfig,
    LightRegisters,
    ModbusTransport,
    Register,
    SensorConfig,
    SensorRegisters,
)
from gonio.drivers.modbus import ModbusLight, ModbusPool, ModbusSensor, decode, encode
from gonio.hal import DeviceFault, DeviceUnavailable, LabDirection, LampOutOfBand
from gonio.sim import modbus_server
from gonio.sim.modbus_server import (
    ModbusRigServer,
    SimLampSpec,
    SimSensorSpec,
    from_words,
    to_words,
)
from gonio.sim.motion import StageMotion
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.sim.specimen import NoiseModel, Specimen

pytestmark = pytest.mark.system

ALBEDO = (0.2, 0.5, 0.8)
IRRADIANCE = 1.0e6
FULL_SCALE = 1.0e5
LIGHT_DIR = (30.0, 0.0)
SENSOR_DIRS = ((40.0, 180.0), (60.0, 90.0))

LIGHT_REGS = LightRegisters(
    on_coil=5,  # deliberately not 0: a shifted coil address must fail the test
    level=Register(table="holding", address=3, type="u16", scale=0.001),
    monitor=Register(table="input", address=7, type="u16", scale=0.001),
    band=0.05,
)
SENSOR_REGS = SensorRegisters(
    values=[
        Register(table="input", address=1, type="u32", word_order="little"),
        Register(table="input", address=3, type="u32", word_order="big"),
        Register(table="input", address=5, type="f32", word_order="big"),
    ],
    exposure=Register(table="holding", address=1, type="u32", scale=1e-6),
    gain=Register(table="holding", address=3, type="f32"),
    trigger=Register(table="holding", address=6, type="u16"),
    sequence=Register(table="input", address=20, type="u16"),
)


class Bench:
    """A server with one lamp and two sensors, and the configs that point at it."""

    def __init__(self, noise: NoiseModel, timeout_s: float = 0.3) -> None:
        self.motion = StageMotion(time_scale=50.0)
        self.server = ModbusRigServer(
            Specimen(Lambert(ALBEDO)),
            self.motion,
            [SimLampSpec("L1", 1, LIGHT_REGS, LabDirection(*LIGHT_DIR).vector(), IRRADIANCE)],
            [
                SimSensorSpec(f"S{k + 1}", 2 + k, SENSOR_REGS, LabDirection(*d).vector(), noise)
                for k, d in enumerate(SENSOR_DIRS)
            ],
            seed=11,
        ).start()
        m = {
            dev: ModbusTransport(
                host="127.0.0.1", port=self.server.port, device_id=dev, timeout_s=timeout_s
            )
            for dev in (1, 2, 3)
        }
        self.light = LightConfig(
            name="L1",
            theta_deg=LIGHT_DIR[0],
            phi_deg=LIGHT_DIR[1],
            modbus=m[1],
            registers=LIGHT_REGS,
            level=0.8,
        )
        self.sensors = [
            SensorConfig(
                name=f"S{k + 1}",
                theta_deg=d[0],
                phi_deg=d[1],
                modbus=m[2 + k],
                channels=["R", "G", "B"],
                registers=SENSOR_REGS,
                saturation_raw=FULL_SCALE,
                gain=2.0,
                min_exposure_s=1e-3,
                max_exposure_s=0.5,
            )
            for k, d in enumerate(SENSOR_DIRS)
        ]

    def expected_counts(self, exposure_s: float, level: float = 0.8, gain: float = 2.0) -> Any:
        """Noise-free counts of a Lambertian specimen, written out from the physics."""
        cos_i = math.cos(math.radians(LIGHT_DIR[0]))
        return IRRADIANCE * level * np.array(ALBEDO) / math.pi * cos_i * gain * exposure_s


@pytest.fixture()
def bench() -> Iterator[Bench]:
    b = Bench(NoiseModel.noiseless(saturation=FULL_SCALE))
    yield b
    b.server.close()


def test_codecs_agree_for_every_type_and_word_order() -> None:
    for type_ in ("u16", "s16", "u32", "s32", "f32"):
        for order in ("big", "little"):
            reg = Register(address=0, type=type_, word_order=order, scale=0.5)
            value = -1234.5 if type_[0] in "sf" else 70000.5 if type_[1:] == "32" else 999.0
            words = to_words(reg, value)
            assert len(words) == reg.width
            assert decode(reg, words) * reg.scale == pytest.approx(value, abs=0.5)
            assert from_words(reg, encode(reg, value, "x")) == pytest.approx(value, abs=0.5)
    big = to_words(Register(address=0, type="u32", word_order="big"), 0x00010002)
    assert big == [0x0001, 0x0002]
    assert to_words(Register(address=0, type="u32", word_order="little"), 0x00010002) == big[::-1]


def test_encode_refuses_values_that_do_not_fit() -> None:
    with pytest.raises(ValueError, match=r"outside the u16 range \[0, 65535\]"):
        encode(Register(address=0, type="u16", scale=1e-6), 0.5, "exposure")


def test_light_register_map_on_the_wire(bench: Bench) -> None:
    async def run() -> tuple[list[bool], list[int], list[int]]:
        light = ModbusLight(bench.light)
        await light.connect()
        await light.set_on(True)
        status = await light.status()
        assert status.on and status.in_band and status.level == pytest.approx(0.8)
        raw = AsyncModbusTcpClient("127.0.0.1", port=bench.server.port)
        await raw.connect()
        try:
            coils = (await raw.read_coils(0, count=8, device_id=1)).bits[:8]
            holding = (await raw.read_holding_registers(0, count=4, device_id=1)).registers
            inputs = (await raw.read_input_registers(0, count=8, device_id=1)).registers
        finally:
            raw.close()
        await light.set_on(False)
        assert not (await light.status()).on
        await light.close()
        return list(coils), list(holding), list(inputs)

    coils, holding, inputs = asyncio.run(run())
    assert coils == [k == 5 for k in range(8)]
    assert holding == [0, 0, 0, 800]  # level 0.8 at scale 0.001, at address 3 only
    assert inputs == [0] * 7 + [800]  # the monitor at address 7 follows the output


def test_sensor_reading_matches_the_physics(bench: Bench) -> None:
    async def run() -> Any:
        pool = ModbusPool()
        light = ModbusLight(bench.light, pool)
        sensor = ModbusSensor(bench.sensors[0], pool)
        for dev in (light, sensor):
            await dev.connect()
        await light.set_on(True)
        reading = await sensor.read(0.02, averages=3)
        await light.set_on(False)
        dark = await sensor.read(0.02)
        for dev in (light, sensor):
            await dev.close()
        return reading, dark

    reading, dark = asyncio.run(run())
    assert reading.averages == 3 and reading.exposure_s == 0.02 and not reading.saturated
    # u32 values are whole counts; the f32 channel is exact to float precision.
    np.testing.assert_allclose(reading.values, bench.expected_counts(0.02), atol=0.51)
    assert dark.values == (0.0, 0.0, 0.0)


def test_all_sensors_read_concurrently_over_one_shared_connection(bench: Bench) -> None:
    async def run() -> list[Any]:
        pool = ModbusPool()
        light = ModbusLight(bench.light, pool)
        sensors = [ModbusSensor(c, pool) for c in bench.sensors]
        for dev in (light, *sensors):
            await dev.connect()
        await light.set_on(True)
        readings = await asyncio.gather(*(s.read(0.01, averages=2) for s in sensors))
        for dev in (light, *sensors):
            await dev.close()
        return readings

    readings = asyncio.run(run())
    for r in readings:
        np.testing.assert_allclose(r.values, bench.expected_counts(0.01), atol=0.51)


def test_exposure_outside_the_sensor_range_is_refused(bench: Bench) -> None:
    async def run() -> None:
        sensor = ModbusSensor(bench.sensors[0])
        await sensor.connect()
        try:
            with pytest.raises(ValueError, match=r"exposure 2 s is outside .*\[0.001, 0.5\] s"):
                await sensor.read(2.0)
            with pytest.raises(ValueError, match="averages must be at least 1"):
                await sensor.read(0.01, averages=0)
        finally:
            await sensor.close()

    asyncio.run(run())


def test_silent_device_times_out_quickly_and_recovers(bench: Bench) -> None:
    async def run() -> float:
        sensor = ModbusSensor(bench.sensors[1])
        await sensor.connect()
        bench.server.silence("S2", None)
        t0 = time.monotonic()
        with pytest.raises(DeviceUnavailable) as info:
            await sensor.read(0.005)
        elapsed = time.monotonic() - t0
        assert info.value.recoverable and info.value.device == "S2"
        # The device id that went silent, and what to check (it named host:port alone).
        text = str(info.value)
        assert f"device_id 3 at 127.0.0.1:{bench.server.port}" in text, text
        assert "modbus.device_id in the rig config" in text, text
        assert not (await sensor.status()).ok
        bench.server.clear_faults()
        reading = await sensor.read(0.005)  # reconnects by itself
        assert len(reading.values) == 3
        await sensor.close()
        return elapsed

    elapsed = asyncio.run(asyncio.wait_for(run(), 60))
    # One request timeout (0.3 s) plus the driver's margin (0.5 s) when idle. Not a speed
    # test: the bound only tells a timeout from a hang (a hang ends in the 60 s wait_for above),
    # with room for a saturated machine.
    assert elapsed < 30.0


def test_unreachable_host_is_unavailable_not_a_hang(bench: Bench) -> None:
    cfg = bench.sensors[0].model_copy(
        update={"modbus": bench.sensors[0].modbus.model_copy(update={"port": 1})}
    )

    async def run() -> None:
        with pytest.raises(DeviceUnavailable, match="no Modbus TCP connection"):
            await ModbusSensor(cfg).connect()

    asyncio.run(asyncio.wait_for(run(), 5))


def test_saturation_is_flagged(bench: Bench) -> None:
    async def run() -> Any:
        light, sensor = ModbusLight(bench.light), ModbusSensor(bench.sensors[0])
        for dev in (light, sensor):
            await dev.connect()
        await light.set_on(True)
        ok = await sensor.read(0.01)
        bench.server.force_saturation("S1")
        bad = await sensor.read(0.01)
        # A long exposure saturates by itself once counts pass full scale.
        bench.server.clear_faults()
        long = await sensor.read(0.5)
        for dev in (light, sensor):
            await dev.close()
        return ok, bad, long

    ok, bad, long = asyncio.run(run())
    assert not ok.saturated
    assert bad.saturated and bad.values[0] == FULL_SCALE
    assert bench.expected_counts(0.5)[2] > FULL_SCALE  # the blue channel overflows
    assert long.saturated and long.values[2] == FULL_SCALE


def test_gain_stages_read_in_a_lower_range_on_the_wire(bench: Bench) -> None:
    """A sensor with gain stages (gain 2, stages 0.2 and 0.02): a reading that saturates at
    gain 2 is not saturated in range 1, whose gain register holds 0.2; its values are the
    physics' counts at that gain, and range 0 writes gain 2 back."""
    cfg = bench.sensors[0].model_copy(update={"gain_stages": [0.2, 0.02]})

    async def run() -> Any:
        light, sensor = ModbusLight(bench.light), ModbusSensor(cfg)
        for dev in (light, sensor):
            await dev.connect()
        assert sensor.ranges == pytest.approx((1.0, 0.1, 0.01))
        await light.set_on(True)
        high = await sensor.read(0.5)
        low = await sensor.read_in_range(0.5, 1, 1)
        gain_in_range_1 = bench.server.sensors["S1"].gain
        back = await sensor.read(0.01)
        gain_back = bench.server.sensors["S1"].gain
        with pytest.raises(ValueError, match="no range 3; it has 3"):
            await sensor.read_in_range(0.01, 1, 3)
        for dev in (light, sensor):
            await dev.close()
        return high, low, gain_in_range_1, back, gain_back

    high, low, gain1, back, gain_back = asyncio.run(run())
    assert bench.expected_counts(0.5, gain=2.0)[2] > FULL_SCALE  # gain 2 overflows blue
    assert high.saturated and high.range_index == 0 and high.range_scale == 1.0
    assert gain1 == pytest.approx(0.2)
    assert not low.saturated and low.range_index == 1 and low.range_scale == pytest.approx(0.1)
    np.testing.assert_allclose(low.values, bench.expected_counts(0.5, gain=0.2), atol=0.51)
    # Scaled back by the range, the reading is what gain 2 would read without clipping.
    np.testing.assert_allclose(np.asarray(low.values) / low.range_scale,
                               bench.expected_counts(0.5, gain=2.0), atol=0.51 / 0.1)
    assert gain_back == pytest.approx(2.0) and back.range_index == 0


def test_lamp_out_of_band_raises_on_switch_on(bench: Bench) -> None:
    async def run() -> None:
        light = ModbusLight(bench.light)
        await light.connect()
        bench.server.set_lamp_output("L1", 0.5)
        with pytest.raises(LampOutOfBand, match=r"outside 0\.800"):
            await light.set_on(True)
        status = await light.status()
        assert status.on and not status.in_band and status.faults == ("out_of_band",)
        bench.server.clear_faults()
        assert (await light.status()).in_band
        await light.close()

    asyncio.run(run())


def test_wrong_address_in_the_map_is_a_permanent_fault(bench: Bench) -> None:
    regs = SENSOR_REGS.model_copy(
        update={"sequence": Register(table="input", address=400, type="u16")}
    )
    cfg = bench.sensors[0].model_copy(update={"registers": regs})

    async def run() -> None:
        sensor = ModbusSensor(cfg)
        with pytest.raises(DeviceFault, match="check this address") as info:
            await sensor.connect()
        assert not info.value.recoverable
        assert "has no such register (Modbus exception 2" in str(info.value), info.value
        await sensor.close()

    asyncio.run(run())


def test_a_device_id_with_no_device_points_at_the_device_id_not_the_register_map(
    bench: Bench
) -> None:
    # `gonio rig apply-design` on a `gonio sim` rig adds lights with the next free device ids,
    # which the simulator does not have: the scan failed with "the device refused the request
    # (ExceptionResponse(dev_id=8, function_code=129, exception_code=4)); check this address
    # in the rig config's register map", whose register map was right. The simulator answers
    # as a Modbus TCP gateway does for a device that does not reply: 0x0B, gateway target
    # device failed to respond (it answered 4, device failure, pymodbus' simulator core's
    # KeyError).
    modbus = bench.light.modbus.model_copy(update={"device_id": 9})
    cfg = bench.light.model_copy(update={"modbus": modbus})

    async def run() -> None:
        light = ModbusLight(cfg)
        with pytest.raises(DeviceFault) as info:
            await light.connect()
        await light.close()
        text = str(info.value)
        assert f"device_id 9 at 127.0.0.1:{bench.server.port}" in text, text
        assert "modbus.device_id in the rig config" in text, text
        assert "(Modbus exception 11, gateway: no path or no response)" in text, text
        assert "register map" not in text and "ExceptionResponse" not in text, text
        assert not info.value.recoverable

    asyncio.run(run())


# --------------------------------------------------------------------------- round trips
def _sensor_requests(bench: Bench, name: str = "S1") -> int:
    return bench.server.request_counts()[name]


def test_steady_state_exposure_costs_two_round_trips(bench: Bench) -> None:
    """Trigger, then one poll that carries the values: no sequence read before the trigger."""

    async def run() -> tuple[int, Any]:
        pool = ModbusPool()
        light, sensor = ModbusLight(bench.light, pool), ModbusSensor(bench.sensors[0], pool)
        for dev in (light, sensor):
            await dev.connect()
        await light.set_on(True)
        await sensor.read(0.01)  # writes the exposure once
        n0 = _sensor_requests(bench)
        reading = await sensor.read(0.01, averages=3)
        used = _sensor_requests(bench) - n0
        for dev in (light, sensor):
            await dev.close()
        return used, reading

    used, reading = asyncio.run(run())
    assert used == 3 * 2
    np.testing.assert_allclose(reading.values, bench.expected_counts(0.01), atol=0.51)


class SlowBench:
    """A second server with one lamp and one sensor, for register maps or timing that differ
    from :class:`Bench`; ``time_scale < 1`` makes an exposure take longer than its nominal time
    (a sensor with conversion overhead)."""

    def __init__(self, bench: Bench, regs: SensorRegisters, time_scale: float = 1.0) -> None:
        spec = SimSensorSpec("S9", 9, regs, LabDirection(*SENSOR_DIRS[0]).vector(),
                             NoiseModel.noiseless(saturation=FULL_SCALE))
        lamp = SimLampSpec("L9", 8, LIGHT_REGS, LabDirection(*LIGHT_DIR).vector(), IRRADIANCE)
        self.server = ModbusRigServer(
            Specimen(Lambert(ALBEDO)), bench.motion, [lamp], [spec], time_scale=time_scale
        ).start()
        transport = bench.light.modbus.model_copy(update={"port": self.server.port})
        self.light = bench.light.model_copy(
            update={"modbus": transport.model_copy(update={"device_id": 8})})
        self.sensor = bench.sensors[0].model_copy(update={
            "name": "S9", "registers": regs,
            "modbus": transport.model_copy(update={"device_id": 9})})


def test_sequence_in_another_table_reads_values_after_the_poll(bench: Bench) -> None:
    regs = SENSOR_REGS.model_copy(
        update={"sequence": Register(table="holding", address=9, type="u16")}
    )
    other = SlowBench(bench, regs)

    async def run() -> tuple[int, Any]:
        pool = ModbusPool()
        light, sensor = ModbusLight(other.light, pool), ModbusSensor(other.sensor, pool)
        for dev in (light, sensor):
            await dev.connect()
        await light.set_on(True)
        await sensor.read(0.01)
        n0 = other.server.request_counts()["S9"]
        reading = await sensor.read(0.01)
        used = other.server.request_counts()["S9"] - n0
        for dev in (light, sensor):
            await dev.close()
        return used, reading

    try:
        used, reading = asyncio.run(run())
    finally:
        other.server.close()
    assert used == 3  # trigger, sequence poll, values
    np.testing.assert_allclose(reading.values, bench.expected_counts(0.01), atol=0.51)


def test_cancelled_exposure_is_never_taken_for_the_next_one(bench: Bench) -> None:
    """An exposure cancelled mid-way completes in the device later and steps the sequence; the
    next read must not take that step for its own (it would return a lit reading in the dark).
    The device here needs 10x the nominal exposure, so the first poll comes before its result."""
    other = SlowBench(bench, SENSOR_REGS, time_scale=0.1)
    trigger = ("S9", 6, SENSOR_REGS.trigger.address)

    async def run() -> Any:
        pool = ModbusPool()
        light, sensor = ModbusLight(other.light, pool), ModbusSensor(other.sensor, pool)
        for dev in (light, sensor):
            await dev.connect()
        await light.set_on(True)
        task = asyncio.create_task(sensor.read(0.05))  # 0.5 s in the device
        while trigger not in other.server.recent_requests():
            await asyncio.sleep(0.001)
        task.cancel()  # triggered, still exposing
        with pytest.raises(asyncio.CancelledError):
            await task
        await asyncio.sleep(0.55)  # the abandoned exposure is complete in the device now
        await light.set_on(False)
        dark = await sensor.read(0.01)
        for dev in (light, sensor):
            await dev.close()
        return dark

    try:
        dark = asyncio.run(asyncio.wait_for(run(), 10))
    finally:
        other.server.close()
    assert dark.values == (0.0, 0.0, 0.0)


def test_switching_a_monitored_light_on_costs_two_round_trips(bench: Bench) -> None:
    async def run() -> int:
        light = ModbusLight(bench.light)
        await light.connect()
        n0 = bench.server.request_counts()["L1"]
        await light.set_on(True)
        used = bench.server.request_counts()["L1"] - n0
        await light.set_on(False)
        await light.close()
        return used

    assert asyncio.run(run()) == 2  # coil write, monitor read


def test_switching_on_unchecked_costs_one_round_trip_and_the_check_one_more(
        bench: Bench) -> None:
    async def run() -> tuple[int, int]:
        light = ModbusLight(bench.light)
        await light.connect()
        n0 = bench.server.request_counts()["L1"]
        await light.switch_on(check=False)
        switched = bench.server.request_counts()["L1"] - n0
        await light.check_output()  # in band: nothing raised
        checked = bench.server.request_counts()["L1"] - n0 - switched
        assert (await light.status()).on
        await light.set_on(False)
        await light.close()
        return switched, checked

    assert asyncio.run(run()) == (1, 1)  # the coil write; then the monitor read


def test_the_deferred_check_of_a_lamp_out_of_band_keeps_the_switch_on_message(
        bench: Bench) -> None:
    async def run() -> None:
        light = ModbusLight(bench.light)
        await light.connect()
        bench.server.set_lamp_output("L1", 0.5)
        await light.switch_on(check=False)  # no monitor read, so nothing to raise yet
        assert (await light.status()).on
        # The monitor reads 0.5 x the 0.8 level (register scale 0.001: 400 -> 0.400).
        with pytest.raises(LampOutOfBand, match=r"L1: output 0\.400 is outside 0\.800 \+- 0\.050; "
                           r"check the lamp or lengthen warmup_s") as err:
            await light.check_output()
        assert err.value.code == "out_of_band"
        await light.set_on(False)
        await light.close()

    asyncio.run(run())


def test_poll_interval_follows_the_exposure(bench: Bench) -> None:
    sensor = ModbusSensor(bench.sensors[0])
    assert sensor.poll_interval(0.05) == pytest.approx(0.001)
    assert sensor.poll_interval(0.5) == pytest.approx(0.01)
    assert sensor.poll_interval(1e-4) == pytest.approx(0.001)  # floor
    assert sensor.poll_interval(5.0) == pytest.approx(0.02)  # cap
    assert ModbusSensor(bench.sensors[0], poll_s=0.004).poll_interval(1.0) == 0.004
    with pytest.raises(ValueError, match="poll_s must be > 0"):
        ModbusSensor(bench.sensors[0], poll_s=0.0)


def test_simulator_counts_each_request_once(bench: Bench) -> None:
    """Single writes are echoed through the action hook a second time: still one request."""

    async def run() -> int:
        n0 = bench.server.request_counts()["L1"]
        raw = AsyncModbusTcpClient("127.0.0.1", port=bench.server.port)
        await raw.connect()
        try:
            await raw.write_coil(5, True, device_id=1)  # fc 5, echoed
            await raw.read_coils(5, count=1, device_id=1)  # fc 1
            await raw.write_register(3, 500, device_id=1)  # fc 6, echoed
            await raw.write_registers(3, [600], device_id=1)  # fc 16
            await raw.read_input_registers(7, count=1, device_id=1)  # fc 4
        finally:
            raw.close()
        return bench.server.request_counts()["L1"] - n0

    assert asyncio.run(run()) == 5


def test_parallel_reads_trigger_every_sensor_before_polling_any(bench: Bench) -> None:
    """Sensors read together share one link: all triggers go out first, so the exposures
    overlap and the light period is one exposure plus a few round trips."""

    async def run() -> None:
        pool = ModbusPool()
        light = ModbusLight(bench.light, pool)
        sensors = [ModbusSensor(c, pool) for c in bench.sensors]
        for dev in (light, *sensors):
            await dev.connect()
        await light.set_on(True)
        await asyncio.gather(*(s.read(0.01) for s in sensors))  # writes the exposures
        n0 = len(bench.server.recent_requests())  # far below the log's 1000 entries
        await asyncio.gather(*(s.read(0.02) for s in sensors))
        log = [(name, fc, addr) for name, fc, addr in bench.server.recent_requests()[n0:]
               if name in ("S1", "S2") and (fc, addr) != (16, SENSOR_REGS.exposure.address)]
        for dev in (light, *sensors):
            await dev.close()
        trigger = (6, SENSOR_REGS.trigger.address)
        assert sorted((n, (fc, a)) for n, fc, a in log[:2]) == [("S1", trigger), ("S2", trigger)]
        assert [fc for _, fc, _ in log[2:]] == [4, 4]  # one combined poll each, no more

    asyncio.run(run())


def test_link_reconnected_during_an_exposure_discards_the_reading(bench: Bench) -> None:
    """Another device on the shared link times out mid-exposure, so the link is dropped and
    re-established: the device may have restarted, so the reading is refused, not trusted."""

    async def run() -> tuple[DeviceUnavailable, Any]:
        pool = ModbusPool()
        light, sensor = ModbusLight(bench.light, pool), ModbusSensor(bench.sensors[0], pool)
        for dev in (light, sensor):
            await dev.connect()
        await light.set_on(True)
        bench.server.silence("L1", 0.4)
        read = asyncio.create_task(sensor.read(0.5))
        await asyncio.sleep(0.05)  # triggered; the status request now hangs and times out
        with pytest.raises(DeviceUnavailable):
            await light.status()
        with pytest.raises(DeviceUnavailable) as info:
            await read
        again = await sensor.read(0.01)  # a fresh exposure on the new link is fine
        for dev in (light, sensor):
            await dev.close()
        return info.value, again

    err, again = asyncio.run(asyncio.wait_for(run(), 10))
    assert err.code == "reconnected" and err.recoverable and err.device == "S1"
    np.testing.assert_allclose(again.values, bench.expected_counts(0.01), atol=0.51)


def test_a_lamp_in_use_is_not_fed_and_an_idle_one_is() -> None:
    """Any request restarts a controller's watchdog: a lamp that hears from the driver anyway
    (here its output check, every 50 ms for longer than a feeding period) gets no feed to
    queue on the shared link, and a lamp left on alone is still fed before it would trip."""
    watchdog_s = 3.0  # a feed is due after 1 s without a request
    with start_sim_rig(SimRigOptions(time_scale=1.0, lamp_watchdog_s=watchdog_s)) as sim:
        assert sim.modbus is not None
        modbus = sim.modbus
        cfg = sim.config.lights[0]
        coil = cfg.registers.on_coil

        def coil_reads() -> int:  # function code 1 at the lamp's coil: a feed
            return sum(1 for name, fc, addr in modbus.recent_requests()
                       if name == cfg.name and fc == 1 and addr == coil)

        async def run() -> tuple[int, int]:
            light = ModbusLight(cfg)
            await light.connect()
            try:
                await light.switch_on(check=False)
                before = coil_reads()
                t_end = time.monotonic() + 1.5 * watchdog_s / 3.0
                while time.monotonic() < t_end:
                    await light.check_output()
                    await asyncio.sleep(0.05)
                in_use = coil_reads() - before
                deadline = time.monotonic() + 60.0
                while coil_reads() - before == in_use and time.monotonic() < deadline:
                    await asyncio.sleep(0.02)  # left alone: wait for the feed
                return in_use, coil_reads() - before - in_use
            finally:
                await light.set_on(False)
                await light.close()

        in_use, idle = asyncio.run(run())
        assert in_use == 0
        assert idle >= 1
        trips = sum(t for _, t in modbus.snapshot()["watchdogs"].values())
        assert trips == 0


def test_a_trigger_is_acknowledged_before_its_reading_is_drawn(
        bench: Bench, monkeypatch: pytest.MonkeyPatch) -> None:
    """A real sensor acknowledges its trigger at once: the simulator draws the reading after
    the reply (during the exposure), from what the sensor saw at the trigger."""
    acked = threading.Event()
    drawn_after_ack: list[bool] = []
    draw = modbus_server.expected_counts

    def drawing(*args: Any, **kwargs: Any) -> Any:
        # Holds the simulator until the client has the trigger's reply: one that drew the
        # reading before replying waits here in vain, and the trigger times out.
        drawn_after_ack.append(acked.wait(timeout=10.0))
        return draw(*args, **kwargs)

    monkeypatch.setattr(modbus_server, "expected_counts", drawing)
    regs = SENSOR_REGS

    async def run() -> list[float]:
        light = ModbusLight(bench.light)
        await light.connect()
        await light.set_on(True)
        raw = AsyncModbusTcpClient("127.0.0.1", port=bench.server.port, timeout=30.0)
        await raw.connect()
        try:
            seq = (await raw.read_input_registers(regs.sequence.address, count=1,
                                                  device_id=2)).registers[0]
            await raw.write_registers(regs.exposure.address, encode(regs.exposure, 0.02, "e"),
                                      device_id=2)
            await raw.write_register(regs.trigger.address, 1, device_id=2)
            acked.set()
            await light.set_on(False)  # after the trigger: the reading stays lit
            deadline = time.monotonic() + 30.0
            while (await raw.read_input_registers(regs.sequence.address, count=1,
                                                  device_id=2)).registers[0] == seq:
                assert time.monotonic() < deadline, "the exposure never completed"
                await asyncio.sleep(0.01)
            words = (await raw.read_input_registers(0, count=8, device_id=2)).registers
        finally:
            raw.close()
            await light.close()
        return [decode(r, words[r.address:r.address + r.width]) * r.scale for r in regs.values]

    values = asyncio.run(run())
    assert drawn_after_ack == [True]
    # Noiseless counts of the lit specimen at the sensor's own gain (1: no driver set it).
    np.testing.assert_allclose(values, bench.expected_counts(0.02, gain=1.0), atol=0.51)
