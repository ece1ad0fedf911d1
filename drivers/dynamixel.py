"""Rotation stage on a Dynamixel X-series servo (Protocol 2.0) through ``dynamixel-sdk``.

The servo runs in extended position mode (multi-turn) so the stage can pass 360 degrees, with
Profile Velocity and Profile Acceleration derived from the configured stage speed and the gear
ratio. The 0-degree reference lives in the servo's Homing Offset (EEPROM): :meth:`home` makes
the present position 0 degrees.

Every SDK call is blocking; it runs in a worker thread (``asyncio.to_thread``) while holding a
lock per serial port, so two devices on one bus never interleave packets. A call that gets no
reply or a corrupted one is retried; an exception from the port (unplugged adapter) triggers a
reopen before the retry. A status packet with the alert bit set means Hardware Error Status is
non-zero: the driver reads it and raises a typed :class:`~gonio.hal.StageFault`. Such faults
latch until a REBOOT, which :meth:`clear_faults` sends.

X-series units (ROBOTIS e-manual): 4096 counts per motor turn, Profile Velocity 0.229 rpm per
unit, Profile Acceleration 214.577 rev/min^2 per unit.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import select
import time
from collections.abc import Callable
from typing import Any

import dynamixel_sdk as sdk
import serial

from gonio.drivers._arrival import poll_delay
from gonio.drivers._ownership import bus_lock, claim
from gonio.drivers._rest import RestPosition
from gonio.drivers._serialport import lock_refused, open_failure
from gonio.drivers._stage_settings import check_motion_settings, check_target
from gonio.hal import DeviceInUse, DeviceUnavailable, StageFault, StageStatus, TravelLimits
from gonio.hal import Stage as _Stage
from gonio.motion import approach_waypoints, move_time

COUNTS_PER_TURN = 4096
DPS_PER_VELOCITY_UNIT = 0.229 * 360.0 / 60.0  # motor degrees/s per Profile Velocity unit
DPS2_PER_ACCEL_UNIT = 214.577 * 360.0 / 3600.0  # motor degrees/s^2 per Profile Acceleration unit
PROFILE_MAX = 32767
HOMING_OFFSET_LIMIT = 1_044_479

ADDR_MODEL_NUMBER = 0
ADDR_OPERATING_MODE = 11
ADDR_HOMING_OFFSET = 20
ADDR_TORQUE_ENABLE = 64
ADDR_LED = 65
ADDR_HARDWARE_ERROR = 70
ADDR_PROFILE_ACCELERATION = 108
ADDR_PROFILE_VELOCITY = 112
ADDR_GOAL_POSITION = 116
ADDR_MOVING = 122
ADDR_PRESENT_POSITION = 132
ADDR_PRESENT_TEMPERATURE = 146
# Moving (122) through Present Position (132..135) in one READ: one transaction per poll.
ARRIVAL_BLOCK = (ADDR_MOVING, ADDR_PRESENT_POSITION + 4 - ADDR_MOVING)
EXTENDED_POSITION_MODE = 4

ALERT_BIT = 0x80
# Hardware Error Status bits: (code, what it means, recoverable by a reboot)
HARDWARE_ERRORS: dict[int, tuple[str, str, bool]] = {
    0x01: ("input_voltage", "input voltage out of range; check the power supply", True),
    0x04: ("overheating", "servo overheated; let it cool and reduce the load", True),
    0x08: ("encoder", "motor encoder malfunction; the servo may need service", False),
    0x10: ("electrical_shock", "electrical shock or damaged motor circuit", False),
    0x20: ("overload", "persistent overload; check for a blocked or overloaded stage", True),
}
PROTOCOL_ERRORS = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}

class _ExclusivePortHandler(sdk.PortHandler):
    """The SDK's port handler, opening the port with ``exclusive=True`` (a ``flock`` on the
    device): another program that asks for the port exclusively is refused while we hold it."""

    def setupPort(self, cflag_baud: int) -> bool:
        if bool(getattr(self, "is_open", False)):
            self.closePort()
        self.ser = serial.Serial(port=self.port_name, baudrate=self.baudrate,
                                 bytesize=serial.EIGHTBITS, timeout=0, exclusive=True)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0  # ms per byte, as the SDK
        return True


def _signed32(value: int) -> int:
    return value - (1 << 32) if value & 0x80000000 else value


class _PortHandler(_ExclusivePortHandler):
    """The exclusive port with a floor under the SDK's reply timeout.

    The SDK waits (bytes on the wire) + 2 x 16 ms latency timer + 2 ms for a status packet,
    about 35 ms: right for a USB adapter on an idle PC. A simulator on a pseudo-terminal (or a
    PC whose cores are saturated) may answer later, and the wire protocol allows waiting
    longer (a status packet is only ever sent in reply to one instruction); the cost is paid
    only when a reply really is missing.
    """

    min_timeout_ms = 0.0

    def setPacketTimeout(self, packet_length: int) -> None:
        super().setPacketTimeout(packet_length)
        base = float(getattr(self, "packet_timeout", 0.0))
        self.packet_timeout: float = max(base, self.min_timeout_ms)

    def readPort(self, length: int) -> bytes:
        """The bytes waiting on the port (at most ``length``), after waiting for the first
        of them until the packet's timeout.

        The SDK calls this in a loop until a whole status packet or its timeout has come, and
        the port is non-blocking (``timeout=0``), so the SDK's own read spins on a core for the
        whole of every reply's latency: CPU taken from the device, the event loop and, on a
        busy PC, everything else. Waiting in ``select`` for the port to become readable costs
        nothing meanwhile and returns as soon as a byte arrives; the SDK's loop, its timeout
        (:meth:`isPacketTimeout`) and what it reads are unchanged.
        """
        ser = self.ser
        if not ser.in_waiting:
            left_ms = float(self.packet_timeout) - self.getTimeSinceStart()
            if left_ms > 0:
                select.select([ser.fileno()], [], [], left_ms / 1000.0)
        data: bytes = ser.read(length)
        return data


class DynamixelStage(_Stage):
    """A rotation stage driven by one Dynamixel X-series servo.

    Parameters
    ----------
    name : str
        Device name in the rig config (used in every error message).
    port : str
        Serial port of the USB adapter (U2D2), e.g. ``/dev/ttyUSB0``.
    baudrate : int
        Bus baud rate, must match the servo's Baud Rate item.
    dxl_id : int
        Servo ID, 0-252.
    counts_per_degree : float
        Encoder counts per degree of stage rotation: 4096/360 times the gear ratio.
    limits : TravelLimits
        Allowed stage angles, degrees.
    speed_dps : float
        Stage travel speed, degrees per second.
    accel_dps2 : float
        Stage acceleration, degrees per second squared.
    settle_s : float
        Wait after each move before returning, seconds.
    approach : {"positive", "negative", "none"}
        Side from which every target is approached (backlash compensation).
    backlash_deg : float
        Overshoot used to approach from the configured side, degrees.
    move_timeout_s : float
        Default limit for one move, seconds.
    retries : int
        Attempts per transaction on timeouts, corrupted replies and port errors.
    position_tolerance_counts : int
        A move has arrived when the servo stopped within this many counts of the goal.
    poll_interval_s : float
        Interval between Moving / Present Position polls while a move is predicted to be
        under way, seconds; from the predicted end (trapezoidal profile at ``speed_dps`` and
        ``accel_dps2``) on, the driver polls every 2 ms (:mod:`gonio.drivers._arrival`).
    """

    def __init__(
        self,
        name: str,
        port: str,
        *,
        baudrate: int = 57600,
        dxl_id: int = 1,
        counts_per_degree: float,
        limits: TravelLimits,
        speed_dps: float,
        accel_dps2: float,
        settle_s: float = 0.0,
        approach: str = "positive",
        backlash_deg: float = 0.0,
        move_timeout_s: float = 60.0,
        retries: int = 3,
        position_tolerance_counts: int = 3,
        poll_interval_s: float = 0.02,
        reply_timeout_s: float | None = None,
    ) -> None:
        self.name = name
        if reply_timeout_s is not None and not (
                math.isfinite(reply_timeout_s) and 0 < reply_timeout_s <= 10):
            raise ValueError(f"{name}: reply_timeout_s must be in (0, 10] seconds, got "
                             f"{reply_timeout_s}")
        self.reply_timeout_s = reply_timeout_s
        self.port = port
        self.baudrate = int(baudrate)
        self.dxl_id = int(dxl_id)
        if not 0 <= self.dxl_id <= 252:
            raise ValueError(f"{name}: dxl_id must be 0-252, got {dxl_id}")
        if not math.isfinite(counts_per_degree) or counts_per_degree <= 0:
            raise ValueError(f"{name}: counts_per_degree must be > 0, got {counts_per_degree}")
        check_motion_settings(
            name, limits=limits, speed_dps=speed_dps, accel_dps2=accel_dps2, approach=approach,
            backlash_deg=backlash_deg, move_timeout_s=move_timeout_s, retries=retries,
            poll_interval_s=poll_interval_s,
        )
        self.cpd = float(counts_per_degree)
        self.limits = limits
        self.speed_dps = float(speed_dps)
        self.accel_dps2 = float(accel_dps2)
        self.settle_s = float(settle_s)
        self.approach = approach
        self.backlash_deg = float(backlash_deg)
        self.move_timeout_s = float(move_timeout_s)
        self.retries = int(retries)
        self.tolerance_counts = int(position_tolerance_counts)
        self.poll_interval_s = float(poll_interval_s)
        self.resolution_deg = 1.0 / self.cpd
        gear = self.cpd * 360.0 / COUNTS_PER_TURN
        self.profile_velocity = self._profile_units(
            "speed_dps", speed_dps, gear / DPS_PER_VELOCITY_UNIT
        )
        self.profile_acceleration = self._profile_units(
            "accel_dps2", accel_dps2, gear / DPS2_PER_ACCEL_UNIT
        )
        # What the servo really runs: the profile units above, back in stage units.
        self._profile_dps = (self.profile_velocity * DPS_PER_VELOCITY_UNIT / gear,
                             self.profile_acceleration * DPS2_PER_ACCEL_UNIT / gear)
        self._ph: Any = None
        self._claim: Any = None  # this process's lock on the port (gonio.locks)
        self._pk: Any = sdk.PacketHandler(2.0)
        # SDK result of the last failed attempt: tells "no answer" from "corrupted answers".
        self.last_comm_result: int = sdk.COMM_RX_TIMEOUT
        self._lock = bus_lock(port)
        self._op_lock = asyncio.Lock()
        self._homed = False
        # Where the last move came to rest (gonio.drivers._rest).
        self._rest = RestPosition(self.approach, self.backlash_deg)
        self.model_number: int | None = None

    def _profile_units(self, what: str, value: float, units_per_stage_unit: float) -> int:
        if not math.isfinite(value) or value <= 0:
            raise ValueError(f"{self.name}: {what} must be > 0, got {value}")
        units = max(1, round(value * units_per_stage_unit))
        if units > PROFILE_MAX:
            raise ValueError(
                f"{self.name}: {what}={value:g} needs profile value {units} at this gear "
                f"ratio, above the servo maximum {PROFILE_MAX}; lower {what}"
            )
        return units

    @property
    def profile_dps(self) -> tuple[float, float]:
        """(speed deg/s, acceleration deg/s^2) of Profile Velocity and Profile Acceleration
        as written: the configured values rounded to the servo's units (e.g. 60 deg/s and
        240 deg/s^2 at gear 1 run as 60.46 deg/s and 236.0 deg/s^2)."""
        return self._profile_dps

    # ------------------------------------------------------------------ transport
    def _open(self) -> None:
        ph = _PortHandler(self.port)
        if self.reply_timeout_s is not None:
            ph.min_timeout_ms = 1000.0 * self.reply_timeout_s
        try:
            ok = ph.setBaudRate(self.baudrate)
        except Exception as exc:  # pyserial raises SerialException/OSError on a missing port
            if "exclusively lock" in str(exc):
                raise DeviceInUse(self.name, lock_refused(self.port)) from exc
            raise DeviceUnavailable(
                self.name,
                f"{open_failure(self.port, exc)}; check the USB adapter and the port name in "
                "the rig config",
                code="port",
            ) from exc
        if not ok:
            raise ValueError(f"{self.name}: baud rate {self.baudrate} is not supported by the SDK")
        self._ph = ph

    def _reopen(self) -> None:
        if self._ph is not None:
            with contextlib.suppress(Exception):
                self._ph.closePort()
        self._ph = None
        self._open()

    def _transact(self, what: str, fn: Callable[..., Any], *args: Any) -> tuple[Any, int]:
        """Run one SDK transaction with retries; returns (value, status error byte).

        Runs in a worker thread. Raises DeviceUnavailable when every attempt failed.
        """
        last = ""
        corrupt = 0  # attempts answered with a broken packet (bad CRC, malformed)
        # The port could not be opened at the last attempt (an adapter unplugged mid-scan):
        # that is the fault, said as the driver says it, not inside "no valid reply (...)".
        lost: DeviceUnavailable | None = None
        self.last_comm_result = sdk.COMM_RX_TIMEOUT
        with self._lock:
            for attempt in range(self.retries):
                lost = None
                try:
                    if self._ph is None:
                        self._open()
                    self._ph.is_using = False  # a failed call may leave the SDK's flag set
                    out = fn(self._ph, self.dxl_id, *args)
                except DeviceInUse:
                    raise  # retrying cannot take the port from its owner
                except DeviceUnavailable as exc:
                    last = str(exc)
                    lost = exc if exc.code == "port" else None
                    time.sleep(0.05 * (attempt + 1))
                    continue
                except Exception as exc:  # lost port: pyserial raises from read/write
                    last = f"port error: {exc}"
                    with contextlib.suppress(DeviceUnavailable):
                        self._reopen()
                    continue
                value, result, error = out if len(out) == 3 else (None, *out)
                if result == sdk.COMM_SUCCESS:
                    return value, int(error)
                last = self._pk.getTxRxResult(result)
                self.last_comm_result = result
                corrupt += result == sdk.COMM_RX_CORRUPT
                self._ph.clearPort()
        if lost is not None:
            raise lost
        if corrupt:
            # The servo answers, but what arrives is broken: noise or a loose contact on the
            # cable, not a missing servo (a timeout), so the lab looks at the wiring first.
            raise DeviceUnavailable(
                self.name,
                f"{what}: corrupted status packets from Dynamixel ID {self.dxl_id} on "
                f"{self.port} ({corrupt} of {self.retries} attempts; last: {last}); check the "
                "cable and connectors for noise or a loose contact, and the baud rate "
                f"({self.baudrate})",
                code="corrupt_reply",
            )
        raise DeviceUnavailable(
            self.name,
            f"{what}: no valid reply from Dynamixel ID {self.dxl_id} on {self.port} after "
            f"{self.retries} attempts ({last}); check power, cable, ID and baud rate "
            f"({self.baudrate})",
            code="timeout",
        )

    async def _call(self, what: str, fn: Callable[..., Any], *args: Any) -> tuple[Any, int]:
        return await asyncio.to_thread(self._transact, what, fn, *args)

    async def _read(self, what: str, address: int, size: int, *, check: bool = True) -> int:
        fn = {1: self._pk.read1ByteTxRx, 4: self._pk.read4ByteTxRx}[size]
        value, error = await self._call(what, fn, address)
        if check:
            await self._check(what, error)
        return _signed32(int(value)) if size == 4 else int(value)

    async def _read_block(self, what: str, address: int, length: int) -> bytes:
        """``length`` bytes of the control table from ``address`` in one transaction."""
        data, error = await self._call(what, self._pk.readTxRx, address, length)
        await self._check(what, error)
        block = bytes(data)
        if len(block) != length:
            raise DeviceUnavailable(self.name, f"{what}: short reply {block!r}", code="short")
        return block

    async def _write(self, what: str, address: int, size: int, value: int) -> None:
        fn = {1: self._pk.write1ByteTxRx, 4: self._pk.write4ByteTxRx}[size]
        _, error = await self._call(what, fn, address, value & 0xFFFFFFFF)
        await self._check(what, error)

    async def _check(self, what: str, error: int) -> None:
        if error & ALERT_BIT:
            await self._raise_hardware_error()
        number = error & 0x7F
        if number:
            raise StageFault(
                self.name,
                f"{what}: servo refused the request ({PROTOCOL_ERRORS.get(number, number)}); "
                "check the servo model and the rig config",
                code="protocol",
                recoverable=False,
            )

    async def _hardware_error(self) -> int:
        return await self._read("read Hardware Error Status", ADDR_HARDWARE_ERROR, 1, check=False)

    async def _raise_hardware_error(self) -> None:
        bits = await self._hardware_error()
        known = [v for b, v in HARDWARE_ERRORS.items() if bits & b]
        if not known:
            known = [(f"hardware_error_0x{bits:02x}", "unknown hardware error", True)]
        codes = "+".join(k[0] for k in known)
        reasons = "; ".join(k[1] for k in known)
        raise StageFault(
            self.name,
            f"hardware error ({reasons}); torque is off until clear_faults() reboots the servo",
            code=codes,
            recoverable=all(k[2] for k in known),
        )

    # ------------------------------------------------------------------ Device
    async def connect(self) -> None:
        self._rest.forget()
        if self._claim is None:
            self._claim = claim(self.name, self.port)
        try:
            await self._connect()
        except BaseException:
            await self.close()
            raise

    async def _connect(self) -> None:
        async with self._op_lock:
            await asyncio.to_thread(self._open_locked)
            try:
                model, _ = await self._call("ping", self._pk.ping)
            except DeviceUnavailable as exc:
                if self.last_comm_result == sdk.COMM_RX_CORRUPT:
                    # It answers, but with broken packets: say that, not "no answer", so the
                    # lab looks at the cable's noise and connectors rather than the power.
                    raise DeviceUnavailable(
                        self.name,
                        f"Dynamixel ID {self.dxl_id} on {self.port} answers with corrupted "
                        f"status packets ({self._pk.getTxRxResult(sdk.COMM_RX_CORRUPT)}); "
                        "check the cable and connectors for noise or a loose contact, and the "
                        f"baud rate ({self.baudrate})",
                        code="corrupt_reply",
                    ) from exc
                raise DeviceUnavailable(
                    self.name,
                    f"Dynamixel ID {self.dxl_id} does not answer on {self.port} at "
                    f"{self.baudrate} baud; check power, cable, ID and baud rate",
                    code="no_answer",
                ) from exc
            self.model_number = int(model)
            if await self._hardware_error() == 0:
                await self._configure()

    def _open_locked(self) -> None:
        with self._lock:
            self._open()

    async def _configure(self) -> None:
        """Extended position mode and motion profile; leaves torque on."""
        mode = await self._read("read Operating Mode", ADDR_OPERATING_MODE, 1)
        if mode != EXTENDED_POSITION_MODE:
            # Operating Mode is in EEPROM: writable only with torque off.
            await self._write("torque off", ADDR_TORQUE_ENABLE, 1, 0)
            await self._write("set extended position mode", ADDR_OPERATING_MODE, 1,
                              EXTENDED_POSITION_MODE)
        await self._write("set Profile Acceleration", ADDR_PROFILE_ACCELERATION, 4,
                          self.profile_acceleration)
        await self._write("set Profile Velocity", ADDR_PROFILE_VELOCITY, 4, self.profile_velocity)
        await self._write("torque on", ADDR_TORQUE_ENABLE, 1, 1)

    async def close(self) -> None:
        self._rest.forget()
        ph, self._ph = self._ph, None
        if ph is not None:
            def _close() -> None:
                with self._lock, contextlib.suppress(Exception):
                    ph.closePort()
            await asyncio.to_thread(_close)
        owned, self._claim = self._claim, None
        if owned is not None:
            owned.release()

    # ------------------------------------------------------------------ Stage
    async def position(self) -> float:
        # Reading works with a latched hardware error; moves and status() report the fault.
        return await self._counts(check=False) / self.cpd

    async def _counts(self, *, check: bool = True) -> int:
        return await self._read("read Present Position", ADDR_PRESENT_POSITION, 4, check=check)

    async def home(self) -> None:
        """Make the present position the 0-degree reference (stored in Homing Offset)."""
        self._rest.forget()
        async with self._op_lock:
            await self._write("torque off", ADDR_TORQUE_ENABLE, 1, 0)
            present = await self._counts()
            offset = await self._read("read Homing Offset", ADDR_HOMING_OFFSET, 4)
            new_offset = offset - present
            if abs(new_offset) > HOMING_OFFSET_LIMIT:
                raise StageFault(
                    self.name,
                    f"cannot zero here: the servo is {present - offset} counts from its power-up "
                    f"turn, beyond the Homing Offset range +-{HOMING_OFFSET_LIMIT}; move the "
                    "stage back towards 0 and home again",
                    code="homing_range",
                    recoverable=False,
                )
            await self._write("write Homing Offset", ADDR_HOMING_OFFSET, 4, new_offset)
            await self._write("torque on", ADDR_TORQUE_ENABLE, 1, 1)
            await self._write("LED on: zero set", ADDR_LED, 1, 1)
            self._homed = True

    async def move_to(self, angle_deg: float, timeout_s: float | None = None) -> float:
        return await self._rest.track(self._move(angle_deg, timeout_s))

    async def _move(self, angle_deg: float, timeout_s: float | None) -> float:
        # The last rest position may save a transaction (the arrival compares Present
        # Position with the goal, so a wrong guess never makes a wrong arrival).
        current = await self._rest.start(self.position)
        waypoints = approach_waypoints(current, angle_deg, self.approach, self.backlash_deg)
        check_target(self.name, self.limits, angle_deg, waypoints)
        limit = self.move_timeout_s if timeout_s is None else float(timeout_s)
        deadline = time.monotonic() + limit
        here = current
        present = round(current * self.cpd)
        for wp in waypoints:
            goal = round(wp * self.cpd)
            await self._write("write Goal Position", ADDR_GOAL_POSITION, 4, goal)
            expected_end = time.monotonic() + move_time(wp - here, *self._profile_dps)
            present = await self._wait_arrival(goal, deadline, limit, expected_end)
            here = wp
        if self.settle_s > 0:
            await asyncio.sleep(self.settle_s)
            return await self.position()
        return present / self.cpd  # read at rest by the poll that saw the arrival

    async def _wait_arrival(
        self, goal: int, deadline: float, limit: float, expected_end: float | None = None
    ) -> int:
        """Poll until the servo rests within tolerance of ``goal``; returns Present Position."""
        stopped_short = 0
        short_since = 0.0
        while True:
            block = await self._read_block("read Moving and Present Position", *ARRIVAL_BLOCK)
            moving = block[0]
            at = ADDR_PRESENT_POSITION - ADDR_MOVING
            present = _signed32(int.from_bytes(block[at : at + 4], "little"))
            now = time.monotonic()
            if not moving:
                if abs(present - goal) <= self.tolerance_counts:
                    return present
                # Moving can lag a fresh goal by a control cycle: insist (three polls spanning
                # two coarse intervals, however fast the polls come) before calling it a stall.
                stopped_short += 1
                if stopped_short == 1:
                    short_since = now
                if stopped_short >= 3 and now - short_since >= 2 * self.poll_interval_s:
                    raise StageFault(
                        self.name,
                        f"stage stopped at {present / self.cpd:.3f} deg, short of the target "
                        f"{goal / self.cpd:.3f} deg; check for a mechanical obstruction",
                        code="stall",
                    )
            else:
                stopped_short = 0
            if now > deadline:
                with contextlib.suppress(Exception):
                    await self.stop()
                raise DeviceUnavailable(
                    self.name,
                    f"move to {goal / self.cpd:.3f} deg did not finish within {limit:g} s "
                    f"(now at {present / self.cpd:.3f} deg); check speed settings and load",
                    code="timeout",
                )
            await asyncio.sleep(poll_delay(now, expected_end, self.poll_interval_s))

    async def stop(self) -> None:
        """Hold the present position: the servo's profile decelerates to it."""
        self._rest.forget()
        await self._write("stop (goal = present)", ADDR_GOAL_POSITION, 4, await self._counts())

    async def status(self) -> StageStatus:
        bits = await self._hardware_error()
        position = await self._read("read Present Position", ADDR_PRESENT_POSITION, 4, check=False)
        moving = await self._read("read Moving", ADDR_MOVING, 1, check=False)
        temperature = await self._read("read temperature", ADDR_PRESENT_TEMPERATURE, 1, check=False)
        led = await self._read("read LED", ADDR_LED, 1, check=False)
        faults = tuple(v[0] for b, v in HARDWARE_ERRORS.items() if bits & b)
        return StageStatus(
            position_deg=position / self.cpd,
            moving=bool(moving),
            # home() lights the LED (RAM: out after a power-up or reboot, when whole motor turns
            # of the zero may be lost), so any program connecting later sees that the zero was
            # set since the servo powered up. The Homing Offset alone cannot tell: 0 is both the
            # factory value and a zero set at the power-up position.
            homed=bool(led),
            faults=faults,
            detail={
                "hardware_error_status": bits,
                "model_number": self.model_number,
                "temperature_c": temperature,
            },
            # After a power-up the encoder knows the angle within one motor turn: at gear 1
            # that is the stage's angle, and the zero in EEPROM still holds; geared, whole
            # motor turns (360 / gear stage degrees) are lost.
            zero_lost_at_power_up=abs(self.cpd * 360.0 - COUNTS_PER_TURN) > 1e-6,
        )

    async def clear_faults(self) -> None:
        """Reboot the servo, keep its multi-turn reference, restore mode and profile."""
        self._rest.forget()
        async with self._op_lock:
            before: int | None
            try:
                before = await self._read("read Present Position", ADDR_PRESENT_POSITION, 4,
                                          check=False)
                led_before = await self._read("read LED", ADDR_LED, 1, check=False)
            except DeviceUnavailable:
                before, led_before = None, 0
            await self._call("reboot", self._pk.reboot)
            await self._wait_for_boot()
            bits = await self._hardware_error()
            if bits:
                await self._raise_hardware_error_persisting(bits)
            kept = before is not None and await self._restore_turns(before)
            await self._configure()
            if kept and led_before:
                # The reboot put the LED out; the zero survived it, so say so again.
                await self._write("LED on: zero set", ADDR_LED, 1, 1)

    async def _wait_for_boot(self, limit_s: float = 3.0) -> None:
        deadline = time.monotonic() + limit_s
        while True:
            try:
                await self._call("ping after reboot", self._pk.ping)
                return
            except DeviceUnavailable:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.05)

    async def _raise_hardware_error_persisting(self, bits: int) -> None:
        names = [v[0] for b, v in HARDWARE_ERRORS.items() if bits & b] or [f"0x{bits:02x}"]
        raise StageFault(
            self.name,
            f"hardware error {'+'.join(names)} persists after a reboot; the servo needs "
            "inspection",
            code="+".join(names),
            recoverable=False,
        )

    async def _restore_turns(self, before: int) -> bool:
        """A reboot forgets whole motor turns; put them back into the Homing Offset.

        Returns False when the reference could not be kept (the stage must be homed again).
        """
        after = await self._read("read Present Position", ADDR_PRESENT_POSITION, 4)
        turns = round((before - after) / COUNTS_PER_TURN)
        if turns == 0:
            return True
        offset = await self._read("read Homing Offset", ADDR_HOMING_OFFSET, 4)
        new_offset = offset + turns * COUNTS_PER_TURN
        if abs(new_offset) > HOMING_OFFSET_LIMIT:
            self._homed = False  # the reference cannot be kept: the engine must home again
            return False
        # Torque is off after a reboot, so the EEPROM item is writable.
        await self._write("restore Homing Offset", ADDR_HOMING_OFFSET, 4, new_offset)
        return True
