"""Device interfaces the engine sees: Stage, Light, Sensor and the Rig that holds them.

Everything here is async. Drivers (``gonio.drivers``) implement these interfaces; blocking SDK
calls run in a worker thread, never on the event loop. Angles at this boundary are degrees
(they come straight from config files and API payloads); the numerical core converts.

Errors a device can raise are :class:`DeviceFault` subclasses, so the engine can decide between
suspending (a recoverable fault) and failing the job, without knowing which driver it runs.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from pydantic import BaseModel, ConfigDict

from gonio.fields import Text


# --------------------------------------------------------------------------- errors
class DeviceFault(Exception):
    """A device reported a fault or stopped answering.

    Parameters
    ----------
    device : str
        Name of the device in the rig config.
    message : str
        What happened and, where known, what to do.
    code : str
        Short machine-readable code (``"overload"``, ``"FS"``, ``"timeout"`` (no reply),
        ``"corrupt_reply"`` (replies, all broken: check the cable), ...).
    recoverable : bool
        True when the condition may clear by itself or by a driver recovery (reboot, reconnect,
        ``warnings clear``): the engine suspends the job and retries. False fails the job.
    secondary : bool
        True when this fault is only a consequence of another device's fault (e.g. a reading
        discarded because a shared link was re-established after another device on it went
        silent). When several devices fail at once, the engine reports a primary fault.
    """

    def __init__(self, device: str, message: str, code: str = "fault", recoverable: bool = True,
                 secondary: bool = False):
        super().__init__(f"{device}: {message}")
        self.device = device
        self.code = code
        self.recoverable = recoverable
        self.secondary = secondary


class StageFault(DeviceFault):
    """The stage reported a hardware fault (overload, stall, encoder, driver disabled, ...)."""


class DeviceUnavailable(DeviceFault):
    """The device did not answer (timeout, lost connection, unparseable replies)."""


class DeviceInUse(DeviceUnavailable):
    """Another program owns the device's port or endpoint (:mod:`gonio.locks`); not recoverable
    by retrying: that program must stop, or be asked through its API."""

    def __init__(self, device: str, message: str) -> None:
        super().__init__(device, message, code="in_use", recoverable=False)


class LampOutOfBand(DeviceFault):
    """A light's monitored output is outside its allowed band."""


# --------------------------------------------------------------------------- values
@dataclass(frozen=True)
class LabDirection:
    """A fixed direction in the lab frame, degrees (theta from the stage normal, phi azimuth)."""

    theta_deg: float
    phi_deg: float

    def vector(self) -> tuple[float, float, float]:
        """Unit vector (x, y, z) in the lab frame."""
        t, p = math.radians(self.theta_deg), math.radians(self.phi_deg)
        return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


@dataclass(frozen=True)
class TravelLimits:
    """Allowed stage angles, degrees, inclusive."""

    min_deg: float
    max_deg: float

    def contains(self, angle_deg: float) -> bool:
        return self.min_deg - 1e-9 <= angle_deg <= self.max_deg + 1e-9


@dataclass(frozen=True)
class StageStatus:
    """What a stage says of itself.

    ``homed``: a zero was set since the stage last powered up. ``zero_lost_at_power_up``:
    a power cycle can move the zero itself, so a stage that was homed and reads not homed
    again may now stand at other angles than its positions say (a geared servo's absolute
    encoder keeps only the angle within one motor turn: whole turns of ``360 / gear`` stage
    degrees are lost). False for a direct-drive servo, whose zero (kept in its EEPROM) and
    one-turn encoder survive a power cycle, and for a stage homed on a sensor (a Zaber: homing
    again finds the same zero).
    """

    position_deg: float
    moving: bool
    homed: bool
    faults: tuple[str, ...] = ()
    detail: Mapping[str, object] = field(default_factory=dict)
    zero_lost_at_power_up: bool = False


@dataclass(frozen=True)
class LightStatus:
    on: bool
    level: float
    in_band: bool = True
    faults: tuple[str, ...] = ()


@dataclass(frozen=True)
class SensorReading:
    """One sensor reading: per-channel values in the sensor's physical units (after scale).

    ``saturated`` is True when any channel reached the configured saturation level in any of
    the averaged exposures. ``range_index`` is the sensor range it was taken in (0: the
    nominal one; :attr:`Sensor.ranges`) and ``range_scale`` that range's sensitivity relative
    to range 0: ``values`` (less the dark signal read in the same range) divided by
    ``range_scale`` are in range-0 units.
    """

    values: tuple[float, ...]
    saturated: bool
    exposure_s: float
    averages: int
    timestamp: float = field(default_factory=time.time)
    range_index: int = 0
    range_scale: float = 1.0


@dataclass(frozen=True)
class SensorStatus:
    ok: bool
    faults: tuple[str, ...] = ()


# --------------------------------------------------------------------------- devices
class Device(abc.ABC):
    """Anything with a name that can be connected and closed."""

    name: str

    @abc.abstractmethod
    async def connect(self) -> None:
        """Open the transport and check that the device answers."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Release the transport; safe to call twice."""


class Stage(Device):
    """A rotation stage under the specimen."""

    limits: TravelLimits
    speed_dps: float
    """Configured travel speed, degrees per second (for duration estimates)."""
    accel_dps2: float
    """Configured acceleration, degrees per second squared (for duration estimates)."""
    settle_s: float = 0.0
    """Time to wait after a move before reading, seconds."""
    resolution_deg: float = 0.01
    """Smallest meaningful angular step of the stage, degrees."""

    @property
    def profile_dps(self) -> tuple[float, float]:
        """(speed deg/s, acceleration deg/s^2) the device really moves with.

        Devices take their motion profile in units of their own, so the configured
        :attr:`speed_dps` and :attr:`accel_dps2` are rounded to the nearest unit; drivers
        that know those units override this with the rounded values (the true physical move
        time, :func:`gonio.motion.move_time`). The base class: the configured values.
        """
        return self.speed_dps, self.accel_dps2

    @abc.abstractmethod
    async def home(self) -> None:
        """Establish the reference position (0 degrees)."""

    @abc.abstractmethod
    async def move_to(self, angle_deg: float, timeout_s: float | None = None) -> float:
        """Move to ``angle_deg`` and wait until the move has finished and settled.

        Returns the actual position, degrees. Raises :class:`StageFault` on a device fault,
        :class:`DeviceUnavailable` when it stops answering or the move times out, and
        ``ValueError`` for an angle outside the travel limits.
        """

    @abc.abstractmethod
    async def position(self) -> float:
        """Present position, degrees."""

    @abc.abstractmethod
    async def stop(self) -> None:
        """Stop any motion now (decelerate)."""

    @abc.abstractmethod
    async def status(self) -> StageStatus:
        """Position, motion, homing and active faults."""

    @abc.abstractmethod
    async def clear_faults(self) -> None:
        """Try to clear latched faults (reboot, ``warnings clear``); raise if they persist."""


async def status_at_rest(stage: Stage, timeout_s: float = 10.0, poll_s: float = 0.02
                         ) -> StageStatus:
    """The stage's status once it has come to rest, for reporting after a manual command.

    A stop decelerates, and even a zero-length move (stop or home at rest, torque back on after
    a reboot) rings for a moment, during which a stage truthfully reports "moving"; what the
    operator asked is where the stage ends up. Returns the last status read if it still moves
    after ``timeout_s`` seconds (then it *is* moving, and says so).
    """
    deadline = time.monotonic() + timeout_s
    while True:
        st = await stage.status()
        if not st.moving or time.monotonic() >= deadline:
            return st
        await asyncio.sleep(poll_s)


class Light(Device):
    """A fixed light source."""

    direction: LabDirection

    @abc.abstractmethod
    async def set_on(self, on: bool) -> None: ...

    @abc.abstractmethod
    async def set_level(self, level: float) -> None:
        """Drive level as a fraction in [0, 1]."""

    @abc.abstractmethod
    async def status(self) -> LightStatus: ...

    async def switch_on(self, *, check: bool = True) -> None:
        """Switch on; with ``check=False`` the output is not checked here: the caller calls
        :meth:`check_output` itself while the light is in use (the engine does so during the
        exposure, when the link is idle, which saves a round trip before the exposure).

        The base class always checks (it calls ``set_on(True)``); drivers whose switch-on
        check costs a request override this.
        """
        await self.set_on(True)

    async def check_output(self) -> None:
        """Raise :class:`LampOutOfBand` when the lit light's output is outside its band.

        The base class asks :meth:`status`; drivers that can read the output alone override
        this with the switch-on check's own request and message.
        """
        st = await self.status()
        if not st.in_band:
            raise LampOutOfBand(self.name,
                                f"output level {st.level:.3g} is outside its allowed band",
                                code="out_of_band")


class Sensor(Device):
    """A fixed photodiode or multi-channel sensor.

    ``ranges`` are the sensitivities of the sensor's ranges (gain stages) relative to the
    nominal one, range 0 first (1.0), each lower than the one before: a reading that saturates
    in range ``k`` may be taken again in range ``k + 1`` (auto-ranging, docs/engine.md). A
    sensor with one range cannot do that.
    """

    direction: LabDirection
    channels: tuple[str, ...]
    min_exposure_s: float = 1e-4
    max_exposure_s: float = 10.0
    ranges: tuple[float, ...] = (1.0,)

    @abc.abstractmethod
    async def read(self, exposure_s: float, averages: int = 1) -> SensorReading:
        """Integrate for ``exposure_s`` seconds ``averages`` times and return the mean."""

    async def read_in_range(self, exposure_s: float, averages: int,
                            range_index: int) -> SensorReading:
        """:meth:`read` in range ``range_index`` of :attr:`ranges` (0: the nominal range).

        Sensors with several ranges override this; the base class has range 0 only.

        Raises
        ------
        ValueError
            ``range_index`` is not one of the sensor's ranges.
        """
        if range_index != 0:
            raise ValueError(f"{self.name}: no range {range_index}; this sensor has one range")
        return await self.read(exposure_s, averages)

    @abc.abstractmethod
    async def status(self) -> SensorStatus: ...


# The one pair type: a rig's pairs, a plan's pairs, calibration factors and result files all
# name pairs with it. Its geometry is not here but in the light's and sensor's directions.
class PairSpec(BaseModel):
    """A light/sensor pair by device name."""

    model_config = ConfigDict(frozen=True)

    light: Text
    sensor: Text

    def label(self) -> str:
        return f"{self.light}/{self.sensor}"


@dataclass
class Rig:
    """One measurement rig: a stage, fixed lights and sensors, and the pairs that are measured."""

    stage: Stage
    lights: dict[str, Light]
    sensors: dict[str, Sensor]
    pairs: list[PairSpec]

    def __post_init__(self) -> None:
        for p in self.pairs:
            if p.light not in self.lights:
                raise ValueError(f"pair {p.label()}: no light named {p.light!r} in the rig")
            if p.sensor not in self.sensors:
                raise ValueError(f"pair {p.label()}: no sensor named {p.sensor!r} in the rig")

    def devices(self) -> Sequence[Device]:
        return [self.stage, *self.lights.values(), *self.sensors.values()]

    async def connect(self) -> None:
        """Connect every device; on failure, close the ones already connected and re-raise."""
        done: list[Device] = []
        try:
            for d in self.devices():
                await d.connect()
                done.append(d)
        except BaseException:
            for d in reversed(done):
                # Closing is best effort here: the original error is the one to report.
                with contextlib.suppress(Exception):
                    await d.close()
            raise

    async def close(self) -> None:
        for d in reversed(self.devices()):
            with contextlib.suppress(Exception):  # one failing device must not keep others open
                await d.close()

    async def __aenter__(self) -> Rig:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
