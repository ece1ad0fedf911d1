"""Simulated Dynamixel X-series servo (XM430-W350 control table) on a pseudo-terminal.

Three layers, in the style of tickit: :class:`XSeriesServo` is the device (control table,
access rules, hardware errors, motion through :class:`~gonio.sim.motion.StageMotion`);
:class:`DynamixelAdapter` speaks Protocol 2.0 to it (framing, instruction dispatch, broadcast
rules, injected wire faults); :class:`~gonio.sim.pty.PtyTransport` moves the bytes.
:func:`start_dynamixel_sim` wires the three together.

Modelled behaviour (from the ROBOTIS e-manual for the X series):

- EEPROM items (addresses below 64) are writable only with torque off, else Access Error.
- Values outside an item's range give Data Range Error, partial writes of a multi-byte item
  Data Length Error, read-only or unknown addresses Access Error; a rejected write changes
  nothing.
- Goal Position is limited to the Min/Max Position Limits in position mode (3) and to
  +-1,048,575 in extended position mode (4). It moves the motor only with torque on.
- Present Position = encoder position + Homing Offset. The encoder keeps multi-turn counts
  while powered; after a REBOOT only the position within one motor turn survives.
- Profile Velocity (0.229 rpm per unit, 0 = unlimited) and Profile Acceleration
  (214.577 rev/min^2 per unit, 0 = unlimited) shape the next move.
- An overload sets bit 5 of Hardware Error Status, drops torque, and sets the alert bit (0x80)
  in every status packet until a REBOOT.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path

from gonio.sim import dynamixel_protocol as dxl
from gonio.sim.faults import FaultPlan
from gonio.sim.motion import StageMotion
from gonio.sim.pty import PtyTransport

COUNTS_PER_TURN = 4096
RPM_PER_VELOCITY_UNIT = 0.229
REV_PER_MIN2_PER_ACCEL_UNIT = 214.577
# With a profile value of 0 ("unlimited") the motor runs as fast as it can: XM430-W350 no-load
# speed (46 rpm at 12 V) and an acceleration high enough to look like a step.
MAX_MOTOR_DPS = 46.0 * 6.0
MAX_MOTOR_DPS2 = 50_000.0
EXTENDED_GOAL_LIMIT = 1_048_575
HOMING_OFFSET_LIMIT = 1_044_479

# Hardware Error Status bits
HW_INPUT_VOLTAGE = 0x01
HW_OVERHEATING = 0x04
HW_ENCODER = 0x08
HW_ELECTRICAL_SHOCK = 0x10
HW_OVERLOAD = 0x20

MODE_POSITION = 3
MODE_EXTENDED_POSITION = 4


@dataclass(frozen=True)
class Item:
    """One control-table entry."""

    name: str
    address: int
    size: int
    writable: bool
    eeprom: bool
    signed: bool = False
    lo: int = 0
    hi: int = 0
    default: int = 0
    allowed: tuple[int, ...] = ()


ITEMS: tuple[Item, ...] = (
    Item("Model Number", 0, 2, False, True),
    Item("Firmware Version", 6, 1, False, True, default=48),
    Item("ID", 7, 1, True, True, lo=0, hi=252, default=1),
    Item("Baud Rate", 8, 1, True, True, lo=0, hi=7, default=1),
    Item("Return Delay Time", 9, 1, True, True, lo=0, hi=254, default=250),
    Item("Drive Mode", 10, 1, True, True, lo=0, hi=13),
    Item("Operating Mode", 11, 1, True, True, default=3, allowed=(0, 1, 3, 4, 5, 16)),
    Item("Homing Offset", 20, 4, True, True, True, -HOMING_OFFSET_LIMIT, HOMING_OFFSET_LIMIT),
    Item("Max Position Limit", 48, 4, True, True, lo=0, hi=4095, default=4095),
    Item("Min Position Limit", 52, 4, True, True, lo=0, hi=4095, default=0),
    Item("Torque Enable", 64, 1, True, False, lo=0, hi=1),
    Item("LED", 65, 1, True, False, lo=0, hi=1),
    Item("Status Return Level", 68, 1, True, False, lo=0, hi=2, default=2),
    Item("Hardware Error Status", 70, 1, False, False),
    Item("Profile Acceleration", 108, 4, True, False, lo=0, hi=32767),
    Item("Profile Velocity", 112, 4, True, False, lo=0, hi=32767),
    Item("Goal Position", 116, 4, True, False, True, -EXTENDED_GOAL_LIMIT, EXTENDED_GOAL_LIMIT),
    Item("Moving", 122, 1, False, False),
    Item("Present Position", 132, 4, False, False, True),
    Item("Present Temperature", 146, 1, False, False, default=36),
)
BY_ADDRESS = {it.address: it for it in ITEMS}
BY_NAME = {it.name: it for it in ITEMS}
TABLE_END = max(it.address + it.size for it in ITEMS)


class DeviceError(Exception):
    """A request the servo refuses; ``number`` is the Protocol 2.0 error number."""

    def __init__(self, number: int, why: str) -> None:
        super().__init__(why)
        self.number = number


KEPT_EEPROM = ("Operating Mode", "Homing Offset", "Max Position Limit", "Min Position Limit",
               "Drive Mode")
"""The EEPROM items a simulated servo keeps across restarts (``eeprom_file``): what the driver
writes (the mode, the zero) and what a lab may set (limits, direction)."""


class XSeriesServo:
    """Control table and behaviour of one X-series servo driving a rotation stage.

    Parameters
    ----------
    motion : StageMotion
        Physics of the stage (degrees of the stage, not of the motor).
    dxl_id : int
        Bus ID, 0-252.
    counts_per_degree : float
        Encoder counts per degree of stage rotation (4096/360 times the gear ratio).
    model_number : int
        Reported by PING and at address 0 (1020 = XM430-W350).
    faults : FaultPlan or None
        Mechanical faults (stall, overload) consumed when a move starts.
    eeprom_file : path or None
        Where the writable EEPROM items (Homing Offset, Operating Mode, limits...) are kept
        across simulator restarts, as a real servo keeps them across power cycles (JSON, by
        item name; written at every EEPROM write, read at construction). None: factory values
        at each start. A restarted ``gonio serve --sim`` that forgot the Homing Offset read the
        stage turned by the old zero, so a resumed scan mixed two zeros.
    """

    def __init__(
        self,
        motion: StageMotion,
        *,
        dxl_id: int = 1,
        counts_per_degree: float = COUNTS_PER_TURN / 360.0,
        model_number: int = 1020,
        faults: FaultPlan | None = None,
        eeprom_file: str | os.PathLike[str] | None = None,
    ) -> None:
        if counts_per_degree <= 0:
            raise ValueError(f"counts_per_degree must be > 0, got {counts_per_degree}")
        self.motion = motion
        self.faults = faults if faults is not None else FaultPlan()
        self.cpd = float(counts_per_degree)
        self._lock = threading.RLock()
        self._values = {it.address: it.default for it in ITEMS}
        self._values[BY_NAME["Model Number"].address] = model_number
        self._values[BY_NAME["ID"].address] = dxl_id
        self._eeprom_file = Path(eeprom_file) if eeprom_file is not None else None
        self._load_eeprom()
        self._turn_offset = 0
        self._power_up()

    # ------------------------------------------------------------------ helpers
    def _get(self, name: str) -> int:
        return self._values[BY_NAME[name].address]

    def _set(self, name: str, value: int) -> None:
        self._values[BY_NAME[name].address] = value

    @property
    def dxl_id(self) -> int:
        return self._get("ID")

    @property
    def gear(self) -> float:
        """Motor turns per stage turn."""
        return self.cpd * 360.0 / COUNTS_PER_TURN

    def _raw_counts(self) -> int:
        return round(self.motion.position_deg() * self.cpd)

    def _encoder(self) -> int:
        return self._raw_counts() - self._turn_offset

    def _identity(self) -> dict[str, float]:
        """What the kept EEPROM belongs to: this model, geared as it is (a file of another
        servo or gear ratio would move the zero by a wrong number of counts)."""
        return {"model": self._get("Model Number"), "counts_per_degree": self.cpd}

    def _load_eeprom(self) -> None:
        """The kept EEPROM items, when a file holds them for this servo (:meth:`_identity`);
        an unreadable file, one of another servo or gear, or an item out of its range leaves
        the factory values (a servo that lost its EEPROM). Only :data:`KEPT_EEPROM` is read:
        the bus ID and baud rate stay the constructor's, which the rig config names."""
        if self._eeprom_file is None or not self._eeprom_file.exists():
            return
        try:
            kept = json.loads(self._eeprom_file.read_text())
            if kept.get("servo") != self._identity():
                return
            values = {BY_NAME[name]: int(v) for name, v in kept["items"].items()
                      if name in KEPT_EEPROM}
        except (OSError, ValueError, TypeError, AttributeError, KeyError):
            return
        for it, value in values.items():
            if (value in it.allowed) if it.allowed else it.lo <= value <= it.hi:
                self._values[it.address] = value

    def _save_eeprom(self) -> None:
        """Keep :data:`KEPT_EEPROM` in the file. A write that fails (a full disk, a removed
        folder) keeps the value in the servo's memory and the servo answering, as a flash
        write that failed would: the next restart then starts from the last file kept."""
        if self._eeprom_file is None:
            return
        kept = {"servo": self._identity(),
                "items": {name: self._get(name) for name in KEPT_EEPROM}}
        tmp = self._eeprom_file.with_name(self._eeprom_file.name + ".tmp")
        try:
            tmp.write_text(json.dumps(kept, indent=1))
            os.replace(tmp, self._eeprom_file)  # whole or not at all
        except OSError:
            with contextlib.suppress(OSError):
                tmp.unlink()

    def _power_up(self) -> None:
        # The absolute encoder knows only the angle within one motor turn after power-up.
        raw = self._raw_counts()
        self._turn_offset = raw - (raw % COUNTS_PER_TURN)
        self._set("Goal Position", self._encoder() + self._get("Homing Offset"))

    def _check_trips(self) -> None:
        if self.motion.overloaded() and not self._get("Hardware Error Status") & HW_OVERLOAD:
            self._set("Hardware Error Status", self._get("Hardware Error Status") | HW_OVERLOAD)
            self._set("Torque Enable", 0)

    @property
    def alert(self) -> bool:
        """True while Hardware Error Status is non-zero (sets bit 7 of every status ERR byte)."""
        with self._lock:
            self._check_trips()
            return self._get("Hardware Error Status") != 0

    # ------------------------------------------------------------------ instructions
    def read(self, address: int, length: int) -> bytes:
        """Bytes ``address`` .. ``address + length - 1`` of the control table."""
        if length < 1 or address + length > TABLE_END:
            raise DeviceError(dxl.ERR_ACCESS, f"read {address}+{length} outside the table")
        with self._lock:
            self._check_trips()
            live = dict(self._values)
            live[BY_NAME["Present Position"].address] = self._encoder() + self._get("Homing Offset")
            moving = self._get("Torque Enable") == 1 and self.motion.is_moving()
            live[BY_NAME["Moving"].address] = int(moving)
            image = bytearray(TABLE_END)
            for it in ITEMS:
                raw = live[it.address] & ((1 << (8 * it.size)) - 1)
                image[it.address : it.address + it.size] = raw.to_bytes(it.size, "little")
            return bytes(image[address : address + length])

    def write(self, address: int, data: bytes) -> None:
        """Write ``data`` at ``address``: all items or none (raises :class:`DeviceError`)."""
        with self._lock:
            self._check_trips()
            updates = self._validate(address, data)
            for it, value in updates:
                self._apply(it, value)
            if any(it.eeprom for it, _ in updates):
                self._save_eeprom()

    def _validate(self, address: int, data: bytes) -> list[tuple[Item, int]]:
        if not data:
            raise DeviceError(dxl.ERR_DATA_LENGTH, "write without data")
        updates: list[tuple[Item, int]] = []
        pos, end = address, address + len(data)
        while pos < end:
            it = BY_ADDRESS.get(pos)
            if it is None:
                raise DeviceError(dxl.ERR_ACCESS, f"no writable item at address {pos}")
            if pos + it.size > end:
                raise DeviceError(dxl.ERR_DATA_LENGTH, f"{it.name} needs {it.size} bytes")
            if not it.writable:
                raise DeviceError(dxl.ERR_ACCESS, f"{it.name} is read-only")
            if it.eeprom and self._get("Torque Enable"):
                raise DeviceError(dxl.ERR_ACCESS, f"{it.name} is EEPROM: turn torque off first")
            raw = data[pos - address : pos - address + it.size]
            value = int.from_bytes(raw, "little", signed=it.signed)
            self._check_range(it, value)
            updates.append((it, value))
            pos += it.size
        return updates

    def _check_range(self, it: Item, value: int) -> None:
        if it.allowed:
            ok = value in it.allowed
        elif it.name == "Goal Position" and self._get("Operating Mode") == MODE_POSITION:
            ok = self._get("Min Position Limit") <= value <= self._get("Max Position Limit")
        else:
            ok = it.lo <= value <= it.hi
        if not ok:
            raise DeviceError(dxl.ERR_DATA_RANGE, f"{value} out of range for {it.name}")
        if it.name == "Torque Enable" and value == 1 and self._get("Hardware Error Status"):
            raise DeviceError(dxl.ERR_RESULT_FAIL, "hardware error latched: reboot first")

    def _apply(self, it: Item, value: int) -> None:
        self._values[it.address] = value
        if it.name == "Torque Enable":
            if value:
                # Enabling torque holds the present position instead of jumping to an old goal.
                self._set("Goal Position", self._encoder() + self._get("Homing Offset"))
            else:
                self.motion.halt()
        elif it.name == "Goal Position" and self._get("Torque Enable"):
            self._start_move(value)

    def _start_move(self, goal: int) -> None:
        motor_dps = self._get("Profile Velocity") * RPM_PER_VELOCITY_UNIT * 6.0 or MAX_MOTOR_DPS
        motor_dps2 = (
            self._get("Profile Acceleration") * REV_PER_MIN2_PER_ACCEL_UNIT * 0.1 or MAX_MOTOR_DPS2
        )
        self.motion.set_speed(min(motor_dps, MAX_MOTOR_DPS) / self.gear)
        self.motion.set_accel(motor_dps2 / self.gear)
        target_deg = (goal - self._get("Homing Offset") + self._turn_offset) / self.cpd
        fraction = self.faults.take_stall()
        if fraction is not None:
            self.motion.arm_stall(fraction)
        if self.faults.take_overload():
            self.motion.arm_overload(0.5)
        self.motion.move_to(target_deg)

    def reboot(self) -> None:
        """Restart: RAM items to defaults, hardware errors cleared, multi-turn count lost."""
        with self._lock:
            self.motion.halt()
            self.motion.reset_overload()
            for it in ITEMS:
                if not it.eeprom and it.writable:
                    self._values[it.address] = it.default
            self._set("Hardware Error Status", 0)
            self._power_up()

    def position_deg(self) -> float:
        """Stage angle as this servo reports it (Present Position / counts per degree)."""
        raw = self.read(BY_NAME["Present Position"].address, 4)
        pos = int.from_bytes(raw, "little", signed=True)
        return pos / self.cpd


class DynamixelAdapter:
    """Protocol 2.0 front end of an :class:`XSeriesServo`: bytes in, status packets out."""

    def __init__(self, servo: XSeriesServo, faults: FaultPlan) -> None:
        self.servo = servo
        self.faults = faults
        self._parser = dxl.PacketParser()

    def handle(self, data: bytes) -> bytes:
        out = bytearray()
        for packet in self._parser.feed(data):
            if self.faults.is_silent():
                continue
            reply = self._execute(packet)
            if reply is None or self.faults.take_drop():
                continue
            if self.faults.take_corrupt():
                reply = reply[:-1] + bytes([reply[-1] ^ 0x5A])
            out += reply
        return bytes(out)

    def _status(self, error: int = 0, params: bytes = b"") -> bytes:
        alert = dxl.ALERT_BIT if self.servo.alert else 0
        return dxl.encode_status(self.servo.dxl_id, error | alert, params)

    def _execute(self, p: dxl.Packet) -> bytes | None:
        my_id = self.servo.dxl_id
        broadcast = p.dxl_id == dxl.BROADCAST_ID
        if p.dxl_id != my_id and not broadcast:
            return None
        if not p.crc_ok:
            return None if broadcast else self._status(dxl.ERR_CRC)
        inst = p.instruction
        try:
            if inst == dxl.PING:
                info = self.servo.read(0, 2) + self.servo.read(6, 1)
                return self._status(0, info)
            if inst == dxl.SYNC_READ:
                return self._sync_read(p.params)
            if inst == dxl.SYNC_WRITE:
                self._sync_write(p.params)
                return None
            reply = self._unicast(inst, p.params)
        except DeviceError as exc:
            reply = self._status(exc.number)
        return None if broadcast else reply

    def _unicast(self, inst: int, params: bytes) -> bytes:
        if inst == dxl.READ:
            if len(params) != 4:
                raise DeviceError(dxl.ERR_DATA_LENGTH, "READ takes address and length")
            addr = int.from_bytes(params[:2], "little")
            length = int.from_bytes(params[2:], "little")
            return self._status(0, self.servo.read(addr, length))
        if inst == dxl.WRITE:
            if len(params) < 3:
                raise DeviceError(dxl.ERR_DATA_LENGTH, "WRITE takes address and data")
            self.servo.write(int.from_bytes(params[:2], "little"), params[2:])
            return self._status()
        if inst == dxl.REBOOT:
            reply = self._status()  # the servo answers, then restarts
            self.servo.reboot()
            return reply
        raise DeviceError(dxl.ERR_INSTRUCTION, f"instruction 0x{inst:02X} not supported")

    def _sync_read(self, params: bytes) -> bytes | None:
        if len(params) < 5:
            return None
        addr, length = int.from_bytes(params[:2], "little"), int.from_bytes(params[2:4], "little")
        if self.servo.dxl_id not in params[4:]:
            return None
        try:
            return self._status(0, self.servo.read(addr, length))
        except DeviceError as exc:
            return self._status(exc.number)

    def _sync_write(self, params: bytes) -> None:
        if len(params) < 4:
            return
        addr, length = int.from_bytes(params[:2], "little"), int.from_bytes(params[2:4], "little")
        block = params[4:]
        for i in range(0, len(block) - length, length + 1):
            if block[i] == self.servo.dxl_id:
                # SYNC_WRITE has no status packet to carry an error: a refused write is lost.
                with contextlib.suppress(DeviceError):
                    self.servo.write(addr, block[i + 1 : i + 1 + length])
                return


class DynamixelSimHandle:
    """A running simulated servo: ``port`` is the path to open, ``close()`` stops it."""

    def __init__(self, servo: XSeriesServo, faults: FaultPlan) -> None:
        self.servo = servo
        self.faults = faults
        self.motion = servo.motion
        self.adapter = DynamixelAdapter(servo, faults)
        self._transport = PtyTransport(self.adapter.handle, name=f"dxl-sim-{servo.dxl_id}")
        self.port = self._transport.port

    def close(self) -> None:
        self._transport.close()

    def __enter__(self) -> DynamixelSimHandle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_dynamixel_sim(
    motion: StageMotion,
    *,
    dxl_id: int = 1,
    counts_per_degree: float = COUNTS_PER_TURN / 360.0,
    model_number: int = 1020,
    faults: FaultPlan | None = None,
    eeprom_file: str | os.PathLike[str] | None = None,
) -> DynamixelSimHandle:
    """Start a simulated X-series servo on a new pseudo-terminal (``eeprom_file``: as
    :class:`XSeriesServo`'s, where its EEPROM is kept across restarts).

    Returns
    -------
    DynamixelSimHandle
        ``.port`` is the pty path for ``dynamixel_sdk.PortHandler``; ``.faults`` arms faults.
    """
    if not 0 <= dxl_id <= dxl.MAX_ID:
        raise ValueError(f"dxl_id must be 0-252, got {dxl_id}")
    if not math.isfinite(counts_per_degree) or counts_per_degree <= 0:
        raise ValueError(f"counts_per_degree must be a positive number, got {counts_per_degree}")
    plan = faults if faults is not None else FaultPlan()
    servo = XSeriesServo(
        motion, dxl_id=dxl_id, counts_per_degree=counts_per_degree,
        model_number=model_number, faults=plan, eeprom_file=eeprom_file,
    )
    return DynamixelSimHandle(servo, plan)
