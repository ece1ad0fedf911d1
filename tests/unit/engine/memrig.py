"""An in-memory rig implementing the :mod:`gonio.hal` interfaces, for engine unit tests.

This is a simulated backend *below* the hal boundary (the engine cannot tell it from a driver):
a stage that takes time to move, lights that switch, and sensors whose reading depends on the
stage angle and which light is on, so tests can check what was measured where. Faults are armed
per device with plain attributes.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field

from gonio import hal


@dataclass
class Log:
    """Every device call in order, for assertions on sequencing."""

    calls: list[tuple[str, str, object]] = field(default_factory=list)

    def add(self, device: str, what: str, arg: object = None) -> None:
        self.calls.append((device, what, arg))


class MemStage(hal.Stage):
    def __init__(self, log: Log, *, speed_dps: float = 3600.0, limits: tuple[float, float] = (
            -720.0, 720.0)):
        self.name = "stage"
        self.log = log
        self.limits = hal.TravelLimits(*limits)
        self.speed_dps = speed_dps
        self.accel_dps2 = speed_dps * 10
        self.settle_s = 0.0
        self.resolution_deg = 0.01
        self.pos = 0.0
        self.faults: list[str] = []
        self.fault_next_moves: list[hal.DeviceFault] = []
        self.sticky_fault = False  # clear_faults does not help
        self.moves: list[float] = []
        self.stopped = 0

    async def connect(self) -> None:
        self.log.add(self.name, "connect")

    async def close(self) -> None:
        self.log.add(self.name, "close")

    async def home(self) -> None:
        self.pos = 0.0

    async def move_to(self, angle_deg: float, timeout_s: float | None = None) -> float:
        if not self.limits.contains(angle_deg):
            raise ValueError(f"{angle_deg} outside limits")
        if self.faults:
            raise hal.StageFault(self.name, f"latched {self.faults}", code=self.faults[0])
        if self.fault_next_moves:
            f = self.fault_next_moves.pop(0)
            if isinstance(f, hal.StageFault):
                self.faults.append(f.code)
            raise f
        self.log.add(self.name, "move", angle_deg)
        await asyncio.sleep(abs(angle_deg - self.pos) / self.speed_dps)
        self.pos = angle_deg
        self.moves.append(angle_deg)
        return self.pos

    async def position(self) -> float:
        return self.pos

    async def stop(self) -> None:
        self.stopped += 1
        self.log.add(self.name, "stop")

    async def status(self) -> hal.StageStatus:
        return hal.StageStatus(self.pos, False, True, tuple(self.faults))

    async def clear_faults(self) -> None:
        self.log.add(self.name, "clear_faults")
        if self.sticky_fault:
            raise hal.StageFault(self.name, "fault does not clear", code="overload")
        self.faults.clear()


class MemLight(hal.Light):
    def __init__(self, name: str, log: Log, theta: float, phi: float):
        self.name = name
        self.log = log
        self.direction = hal.LabDirection(theta, phi)
        self.on = False
        self.in_band = True
        self.unavailable = 0  # next n set_on calls fail with DeviceUnavailable

    async def connect(self) -> None:
        self.log.add(self.name, "connect")

    async def close(self) -> None:
        self.log.add(self.name, "close")

    async def set_on(self, on: bool) -> None:
        if self.unavailable > 0:
            self.unavailable -= 1
            raise hal.DeviceUnavailable(self.name, "no reply", code="timeout")
        self.on = on
        self.log.add(self.name, "on" if on else "off")

    async def set_level(self, level: float) -> None:
        pass

    async def status(self) -> hal.LightStatus:
        return hal.LightStatus(self.on, 1.0, self.in_band)


class MemSensor(hal.Sensor):
    """Reads ``base * (1 + 0.5 cos(2 (stage angle - light phi)))`` per channel, per light on."""

    def __init__(self, name: str, log: Log, rig: MemRig, theta: float, phi: float):
        self.name = name
        self.log = log
        self.rig = rig
        self.direction = hal.LabDirection(theta, phi)
        self.channels = ("R", "G", "B")
        self.saturate_next = 0
        self.dark_level = 0.01
        self.reads = 0

    async def connect(self) -> None:
        self.log.add(self.name, "connect")

    async def close(self) -> None:
        self.log.add(self.name, "close")

    async def read(self, exposure_s: float, averages: int = 1) -> hal.SensorReading:
        self.reads += 1
        self.log.add(self.name, "read", self.rig.mstage.pos)
        await asyncio.sleep(exposure_s * averages)
        lit = [lt for lt in self.rig.lights.values() if self.rig.light(lt.name).on]
        angle = math.radians(self.rig.mstage.pos)
        sig = sum(
            1.0 + 0.5 * math.cos(2 * (angle - math.radians(lt.direction.phi_deg))) for lt in lit
        )
        vals = tuple(self.dark_level + sig * k for k in (1.0, 0.8, 0.6))
        sat = False
        if self.saturate_next > 0 and lit:
            self.saturate_next -= 1
            sat = True
        return hal.SensorReading(vals, sat, exposure_s, averages)

    async def status(self) -> hal.SensorStatus:
        return hal.SensorStatus(True)


class MemRig(hal.Rig):
    """Two lights, two sensors, three pairs."""

    def __init__(self, speed_dps: float = 3600.0) -> None:
        self.log = Log()
        stage = MemStage(self.log, speed_dps=speed_dps)
        lights: dict[str, hal.Light] = {
            "L1": MemLight("L1", self.log, 45.0, 0.0),
            "L2": MemLight("L2", self.log, 30.0, 90.0),
        }
        sensors: dict[str, hal.Sensor] = {
            "S1": MemSensor("S1", self.log, self, 45.0, 180.0),
            "S2": MemSensor("S2", self.log, self, 60.0, 200.0),
        }
        pairs = [hal.PairSpec(light="L1", sensor="S1"), hal.PairSpec(light="L1", sensor="S2"),
                 hal.PairSpec(light="L2", sensor="S1")]
        super().__init__(stage=stage, lights=lights, sensors=sensors, pairs=pairs)

    @property
    def mstage(self) -> MemStage:
        assert isinstance(self.stage, MemStage)
        return self.stage

    def light(self, name: str) -> MemLight:
        lt = self.lights[name]
        assert isinstance(lt, MemLight)
        return lt

    def any_light_on(self) -> bool:
        return any(self.light(n).on for n in self.lights)

    def sensor(self, name: str) -> MemSensor:
        s = self.sensors[name]
        assert isinstance(s, MemSensor)
        return s
