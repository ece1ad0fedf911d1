"""An in-memory rig implementing the :mod:`gonio.hal` interfaces, with no wire protocol.

Use it where a whole rig is wanted fast and without ports, sockets or simulator processes: unit
tests of the engine, worker and service, notebooks, and dry experiments with a plan. It sits
*below* the hal boundary, so the engine cannot tell it from a driver: a stage that takes time to
move, lights that switch, and sensors whose reading depends on the stage angle and on which
lights are on, so a test can check what was measured where. Every device call is recorded in
order in a :class:`Log`, and faults are armed per device with plain attributes.

For the real wire protocols (Dynamixel, Zaber ASCII, Modbus) use :mod:`gonio.sim.rig` instead;
the drivers talk to those simulators exactly as to the hardware.

Examples
--------
>>> import asyncio
>>> rig = MemRig()
>>> asyncio.run(rig.stage.move_to(90.0))
90.0
>>> sorted(rig.lights), sorted(rig.sensors)
(['L1', 'L2'], ['S1', 'S2'])
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field

from gonio import hal

__all__ = ["Log", "MemLight", "MemRig", "MemSensor", "MemStage"]


@dataclass
class Log:
    """Every device call in order, for assertions on sequencing.

    Attributes
    ----------
    calls : list of (str, str, object)
        ``(device name, what, argument)`` per call, oldest first; e.g. ``("stage", "move",
        90.0)``, ``("L1", "on", None)``, ``("S1", "read", <stage angle, degrees>)``.
    """

    calls: list[tuple[str, str, object]] = field(default_factory=list)

    def add(self, device: str, what: str, arg: object = None) -> None:
        """Record one call."""
        self.calls.append((device, what, arg))


class MemStage(hal.Stage):
    """A rotation stage that moves at constant speed, in memory.

    A move sleeps ``|distance| / speed_dps`` seconds (no ramps). Faults are armed with
    attributes: ``faults`` (codes latched now: every move raises :class:`gonio.hal.StageFault`
    until :meth:`clear_faults`), ``fault_next_moves`` (faults the next moves raise, in order; a
    ``StageFault`` latches its code) and ``sticky_fault`` (:meth:`clear_faults` fails).

    Parameters
    ----------
    log : Log
        Where calls are recorded.
    speed_dps : float
        Travel speed, degrees per second (acceleration is taken as ten times that, per second).
    limits : tuple of float
        Travel limits ``(low, high)``, degrees.
    """

    def __init__(self, log: Log, *, speed_dps: float = 3600.0, limits: tuple[float, float] = (
            -720.0, 720.0)) -> None:
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
        # What status() says of the zero (hal.StageStatus): set by a test to play a stage
        # powered off and on (homed False; a geared or stepper stage loses its zero).
        self.homed = True
        self.zero_lost_at_power_up = False

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
        return hal.StageStatus(self.pos, False, self.homed, tuple(self.faults),
                               zero_lost_at_power_up=self.zero_lost_at_power_up)

    async def clear_faults(self) -> None:
        self.log.add(self.name, "clear_faults")
        if self.sticky_fault:
            raise hal.StageFault(self.name, "fault does not clear", code="overload")
        self.faults.clear()


class MemLight(hal.Light):
    """A light that switches on and off, in memory.

    Set ``in_band = False`` to report its output out of band, and ``unavailable = n`` to make
    the next ``n`` :meth:`set_on` calls raise :class:`gonio.hal.DeviceUnavailable`.

    Parameters
    ----------
    name : str
        Device name.
    log : Log
        Where calls are recorded.
    theta, phi : float
        Lab direction, degrees.
    """

    def __init__(self, name: str, log: Log, theta: float, phi: float) -> None:
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
    """An RGB sensor whose reading follows the stage angle and the lights that are on.

    Channel ``c`` reads ``dark_level + k_c * sum over lit lights of (1 + 0.5 cos(2 (alpha -
    phi_l)))`` with ``k = (1.0, 0.8, 0.6)``, ``alpha`` the stage angle and ``phi_l`` the
    light's azimuth: a known anisotropic signal, period 180 degrees, times
    ``1 + lean cos(alpha)`` with the rig's :attr:`MemRig.lean` (0 by default: a specimen
    without twofold symmetry when it is not). A read sleeps
    ``exposure_s * averages`` seconds. Set ``saturate_next = n`` to flag the next ``n`` lit
    readings saturated.

    Parameters
    ----------
    name : str
        Device name.
    log : Log
        Where calls are recorded.
    rig : MemRig
        The rig whose stage angle and lights the reading follows.
    theta, phi : float
        Lab direction, degrees.
    """

    def __init__(self, name: str, log: Log, rig: MemRig, theta: float, phi: float) -> None:
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
        ) * (1.0 + self.rig.lean * math.cos(angle))
        vals = tuple(self.dark_level + sig * k for k in (1.0, 0.8, 0.6))
        sat = False
        if self.saturate_next > 0 and lit:
            self.saturate_next -= 1
            sat = True
        return hal.SensorReading(vals, sat, exposure_s, averages)

    async def status(self) -> hal.SensorStatus:
        return hal.SensorStatus(True)


class MemRig(hal.Rig):
    """Two lights, two sensors, three pairs, all in memory.

    Lights ``L1`` (theta 45, phi 0 degrees) and ``L2`` (30, 90); sensors ``S1`` (45, 180) and
    ``S2`` (60, 200); pairs ``L1/S1``, ``L1/S2``, ``L2/S1``.

    Parameters
    ----------
    speed_dps : float
        Stage speed, degrees per second; the default makes a full turn take 0.1 s.
    lean : float
        The specimen's once-per-turn lean: every reading times ``1 + lean cos(alpha)``
        (alpha the stage angle), so that a specimen turned by half a turn no longer reads the
        same (|lean| < 1; 0, the default: twofold symmetric).
    """

    def __init__(self, speed_dps: float = 3600.0, lean: float = 0.0) -> None:
        self.log = Log()
        self.lean = float(lean)
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
        """The stage, typed as :class:`MemStage` (to arm faults, read ``moves``)."""
        assert isinstance(self.stage, MemStage)
        return self.stage

    def light(self, name: str) -> MemLight:
        """Light ``name``, typed as :class:`MemLight`."""
        lt = self.lights[name]
        assert isinstance(lt, MemLight)
        return lt

    def any_light_on(self) -> bool:
        """True while any light is on."""
        return any(self.light(n).on for n in self.lights)

    def sensor(self, name: str) -> MemSensor:
        """Sensor ``name``, typed as :class:`MemSensor`."""
        s = self.sensors[name]
        assert isinstance(s, MemSensor)
        return s
