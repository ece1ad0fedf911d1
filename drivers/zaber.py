"""Rotation stage on a Zaber controller speaking the Zaber ASCII protocol, through pyserial.

The transport is any pyserial URL (``serial.serial_for_url``): a serial device such as
``/dev/ttyUSB0``, ``socket://host:port`` for controllers on Ethernet (or the simulator), or
``loop://`` in experiments. Every command carries a message ID so a late reply to an earlier,
timed-out command can never be mistaken for the answer to the current one.

Reply flags map to typed faults: ``F*`` flags (stall, driver disabled, encoder error, ...) raise
:class:`~gonio.hal.StageFault` and persist until ``warnings clear`` (:meth:`clear_faults`);
``WR``/``WH`` (no reference position) make :meth:`move_to` home first. A reply that is not a
Zaber ASCII line (wrong baud rate, binary protocol, line noise) raises
:class:`~gonio.hal.DeviceUnavailable` quoting the raw line.

Units (Zaber convention): positions in microsteps; ``maxspeed`` = microsteps/s x 1.6384;
``accel`` = microsteps/s^2 x 1.6384 / 10000. The optional ``:CC`` message checksum is not used.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
import re
import termios
import time
from dataclasses import dataclass
from typing import Any

import serial

from gonio.drivers._arrival import poll_delay
from gonio.drivers._ownership import bus_lock, claim
from gonio.drivers._rest import RestPosition
from gonio.drivers._serialport import lock_refused, open_failure
from gonio.drivers._stage_settings import check_motion_settings, check_target
from gonio.hal import DeviceInUse, DeviceUnavailable, StageFault, StageStatus, TravelLimits
from gonio.hal import Stage as _Stage
from gonio.motion import approach_waypoints, move_time

SPEED_FACTOR = 1.6384
ACCEL_FACTOR = 1.6384 / 10_000

# Fault flags: what they mean and whether clearing them is expected to let the stage run again.
FAULT_FLAGS: dict[str, tuple[str, bool]] = {
    "FD": ("driver disabled (over-temperature, over-voltage or overload)", True),
    "FQ": ("encoder error", False),
    "FS": ("stalled and stopped", True),
    "FT": ("excessive twist", True),
    "FB": ("stream bounds error", True),
    "FP": ("interpolated path deviation", True),
    "FE": ("limit error", True),
}
NO_REFERENCE_FLAGS = ("WR", "WH")

_REPLY = re.compile(
    r"^@(?P<device>\d{2}) (?P<axis>\d+) (?:(?P<id>\d{1,2}) )?(?P<verdict>OK|RJ) "
    r"(?P<state>BUSY|IDLE) (?P<flag>[A-Z]{2}|--)(?: (?P<data>.*))?$"
)


@dataclass(frozen=True)
class Reply:
    """One parsed reply line."""

    device: int
    axis: int
    msg_id: int | None
    ok: bool
    busy: bool
    flag: str | None
    data: str

    @classmethod
    def parse(cls, line: str) -> Reply | None:
        m = _REPLY.match(line)
        if m is None:
            return None
        return cls(
            device=int(m["device"]),
            axis=int(m["axis"]),
            msg_id=int(m["id"]) if m["id"] is not None else None,
            ok=m["verdict"] == "OK",
            busy=m["state"] == "BUSY",
            flag=None if m["flag"] == "--" else m["flag"],
            data=m["data"] or "",
        )


class ZaberStage(_Stage):
    """A Zaber rotary stage (one axis of a controller) as a :class:`gonio.hal.Stage`.

    Parameters
    ----------
    name : str
        Device name in the rig config.
    url : str
        pyserial port or URL (``/dev/ttyUSB0``, ``socket://10.0.0.5:55550``).
    baudrate : int
        Serial baud rate (115200 on current firmware; 9600 on old devices). Ignored for sockets.
    device : int
        Device number on the daisy chain, 1-99.
    axis : int
        Axis number on the device, >= 1.
    microsteps_per_degree : float
        Microsteps per degree of stage rotation (from the stage model's data sheet).
    limits : TravelLimits
        Allowed stage angles, degrees.
    speed_dps, accel_dps2 : float
        Travel speed (degrees/s) and acceleration (degrees/s^2), written as ``maxspeed`` and
        ``accel`` at connect.
    settle_s : float
        Wait after each move, seconds.
    approach : {"positive", "negative", "none"}
        Side from which targets are approached; ``backlash_deg`` is the overshoot.
    move_timeout_s : float
        Default limit for one move (and for homing), seconds.
    reply_timeout_s : float
        Time to wait for one reply line, seconds.
    retries : int
        Attempts per command when replies time out.
    poll_interval_s : float
        Interval between status polls while a move is predicted to be under way, seconds;
        from the predicted end (trapezoidal profile at ``speed_dps`` and ``accel_dps2``) on,
        the driver polls every 2 ms (:mod:`gonio.drivers._arrival`).
    """

    def __init__(
        self,
        name: str,
        url: str,
        *,
        baudrate: int = 115200,
        device: int = 1,
        axis: int = 1,
        microsteps_per_degree: float,
        limits: TravelLimits,
        speed_dps: float,
        accel_dps2: float,
        settle_s: float = 0.0,
        approach: str = "positive",
        backlash_deg: float = 0.0,
        move_timeout_s: float = 60.0,
        reply_timeout_s: float = 0.5,
        retries: int = 3,
        poll_interval_s: float = 0.02,
    ) -> None:
        self.name = name
        self.url = url
        self.baudrate = int(baudrate)
        if not 1 <= device <= 99:
            raise ValueError(f"{name}: Zaber device number must be 1-99, got {device}")
        if axis < 1:
            raise ValueError(f"{name}: Zaber axis must be >= 1, got {axis}")
        if not math.isfinite(microsteps_per_degree) or microsteps_per_degree <= 0:
            raise ValueError(
                f"{name}: microsteps_per_degree must be > 0, got {microsteps_per_degree}"
            )
        check_motion_settings(
            name, limits=limits, speed_dps=speed_dps, accel_dps2=accel_dps2, approach=approach,
            backlash_deg=backlash_deg, move_timeout_s=move_timeout_s, retries=retries,
            poll_interval_s=poll_interval_s,
        )
        if not reply_timeout_s > 0:
            raise ValueError(f"{name}: reply_timeout_s must be > 0, got {reply_timeout_s}")
        self.device = int(device)
        self.axis = int(axis)
        self.mpd = float(microsteps_per_degree)
        self.limits = limits
        self.speed_dps = float(speed_dps)
        self.accel_dps2 = float(accel_dps2)
        self.settle_s = float(settle_s)
        self.approach = approach
        self.backlash_deg = float(backlash_deg)
        self.move_timeout_s = float(move_timeout_s)
        self.reply_timeout_s = float(reply_timeout_s)
        self.retries = int(retries)
        self.poll_interval_s = float(poll_interval_s)
        self.resolution_deg = 1.0 / self.mpd
        self.maxspeed = max(1, round(self.speed_dps * self.mpd * SPEED_FACTOR))
        self.accel = max(1, round(self.accel_dps2 * self.mpd * ACCEL_FACTOR))
        # What the stage really runs: maxspeed and accel back in degrees.
        self._profile_dps = (self.maxspeed / (self.mpd * SPEED_FACTOR),
                             self.accel / (self.mpd * ACCEL_FACTOR))
        self._port: Any = None
        self._claim: Any = None  # this process's lock on the port or URL (gonio.locks)
        self._lock = bus_lock(url)
        self._ids = itertools.cycle(range(100))
        self._op_lock = asyncio.Lock()
        # Where the last move came to rest (gonio.drivers._rest).
        self._rest = RestPosition(self.approach, self.backlash_deg)

    @property
    def profile_dps(self) -> tuple[float, float]:
        """(speed deg/s, acceleration deg/s^2) of ``maxspeed`` and ``accel`` as written: the
        configured values rounded to the device's units."""
        return self._profile_dps

    # ------------------------------------------------------------------ transport
    def _open(self) -> None:
        # A local serial device is opened exclusively (flock); URLs have no such flag.
        extra = {} if "://" in self.url else {"exclusive": True}
        try:
            self._port = serial.serial_for_url(
                self.url, baudrate=self.baudrate, timeout=self.reply_timeout_s, **extra
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            if "exclusively lock" in str(exc):
                raise DeviceInUse(self.name, lock_refused(self.url)) from exc
            raise DeviceUnavailable(
                self.name,
                f"{open_failure(self.url, exc)}; check the cable or network and the url in "
                "the rig config",
                code="port",
            ) from exc

    def _exchange(self, command: str) -> Reply:
        """Send one command and return its reply (worker thread; retries on timeouts)."""
        with self._lock:
            last = "no reply"
            for _attempt in range(self.retries):
                msg_id = next(self._ids)
                line = f"/{self.device} {self.axis} {msg_id} {command}".rstrip() + "\n"
                try:
                    if self._port is None:
                        self._open()
                    self._port.reset_input_buffer()
                    self._port.write(line.encode("ascii"))
                    reply = self._read_reply(msg_id)
                except DeviceUnavailable as exc:
                    if exc.code in ("garbled", "port", "in_use"):
                        raise  # retrying cannot fix a wrong url or a foreign protocol
                    last = str(exc)
                    continue
                except (serial.SerialException, OSError, termios.error) as exc:
                    # A vanished port fails in termios (tcflush: EIO), not in pyserial; the
                    # next attempt reopens it, and says so if it is gone.
                    last = f"port error: {exc}"
                    self._drop_port()
                    continue
                if reply is not None:
                    return reply
                last = f"no reply within {self.reply_timeout_s:g} s"
        raise DeviceUnavailable(
            self.name,
            f"{command or 'status poll'!r}: device {self.device} on {self.url} did not answer "
            f"after {self.retries} attempts ({last}); check power, cable, device number and "
            f"baud rate ({self.baudrate})",
            code="timeout",
        )

    def _read_reply(self, msg_id: int) -> Reply | None:
        deadline = time.monotonic() + self.reply_timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            self._port.timeout = remaining
            raw = self._port.read_until(b"\n")
            if not raw.endswith(b"\n"):
                return None
            text = raw.decode("ascii", errors="replace").strip()
            if not text or text[0] in "#!":
                continue  # info lines and unsolicited alerts are not replies
            reply = Reply.parse(text)
            if reply is None:
                raise DeviceUnavailable(
                    self.name,
                    f"unparseable reply {raw!r} from {self.url}; is the device in ASCII "
                    f"protocol mode at {self.baudrate} baud?",
                    code="garbled",
                )
            if reply.device == self.device and reply.msg_id == msg_id:
                return reply
            # A reply to an earlier command that timed out: skip it.

    def _drop_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()

    async def _send(self, command: str) -> Reply:
        return await asyncio.to_thread(self._exchange, command)

    async def _ok(self, command: str) -> Reply:
        """Send ``command``; raise on a rejection."""
        reply = await self._send(command)
        if not reply.ok:
            raise StageFault(
                self.name,
                f"{command!r} rejected by the controller ({reply.data}, flag "
                f"{reply.flag or '--'})",
                code=f"rejected:{reply.data}",
                recoverable=False,
            )
        return reply

    async def _warnings(self) -> list[str]:
        reply = await self._ok("warnings")
        words = reply.data.split()
        return words[1:] if words else []

    def _raise_faults(self, flags: list[str]) -> None:
        faults = [f for f in flags if f in FAULT_FLAGS]
        if not faults:
            return
        reasons = "; ".join(f"{f}: {FAULT_FLAGS[f][0]}" for f in faults)
        raise StageFault(
            self.name,
            f"controller reports {reasons}; it persists until clear_faults() "
            "('warnings clear')",
            code="+".join(faults),
            recoverable=all(FAULT_FLAGS[f][1] for f in faults),
        )

    # ------------------------------------------------------------------ Device
    async def connect(self) -> None:
        self._rest.forget()
        if self._claim is None:
            self._claim = claim(self.name, self.url)
        try:
            await self._connect()
        except BaseException:
            await self.close()
            raise

    async def _connect(self) -> None:
        async with self._op_lock:
            try:
                await self._send("")
            except DeviceUnavailable as exc:
                if exc.code in ("garbled", "port", "in_use"):
                    raise
                raise DeviceUnavailable(
                    self.name,
                    f"Zaber device {self.device} does not answer on {self.url}; check power, "
                    f"cable, device number and baud rate ({self.baudrate})",
                    code="no_answer",
                ) from exc
            await self._ok(f"set maxspeed {self.maxspeed}")
            await self._ok(f"set accel {self.accel}")

    async def close(self) -> None:
        self._rest.forget()

        def _close() -> None:
            with self._lock:
                self._drop_port()

        await asyncio.to_thread(_close)
        owned, self._claim = self._claim, None
        if owned is not None:
            owned.release()

    # ------------------------------------------------------------------ Stage
    async def position(self) -> float:
        reply = await self._ok("get pos")
        try:
            return int(reply.data.split()[0]) / self.mpd
        except (ValueError, IndexError):
            raise DeviceUnavailable(
                self.name, f"'get pos' returned {reply.data!r}, not a position", code="garbled"
            ) from None

    async def home(self) -> None:
        self._rest.forget()
        async with self._op_lock:
            await self._home_locked(None)

    async def _home_locked(self, timeout_s: float | None) -> None:
        self._rest.forget()
        self._raise_faults(await self._warnings())
        await self._ok("home")
        limit = self.move_timeout_s if timeout_s is None else timeout_s
        await self._wait_idle(time.monotonic() + limit, limit, "homing")
        flags = await self._warnings()
        self._raise_faults(flags)
        if any(f in NO_REFERENCE_FLAGS for f in flags):
            raise StageFault(self.name, "homing finished without a reference position",
                             code="WR")

    async def move_to(self, angle_deg: float, timeout_s: float | None = None) -> float:
        return await self._rest.track(self._move(angle_deg, timeout_s))

    async def _move(self, angle_deg: float, timeout_s: float | None) -> float:
        check_target(self.name, self.limits, angle_deg, [angle_deg])
        limit = self.move_timeout_s if timeout_s is None else float(timeout_s)
        deadline = time.monotonic() + limit
        flags = await self._warnings()
        self._raise_faults(flags)
        if any(f in NO_REFERENCE_FLAGS for f in flags):
            async with self._op_lock:
                await self._home_locked(limit)
        # The last rest position may save a request (the axis reports itself idle at the
        # target, so a wrong guess never makes a wrong arrival).
        current = await self._rest.start(self.position)
        waypoints = approach_waypoints(current, angle_deg, self.approach, self.backlash_deg)
        check_target(self.name, self.limits, angle_deg, waypoints)
        here = current
        for wp in waypoints:
            await self._ok(f"move abs {round(wp * self.mpd)}")
            expected_end = time.monotonic() + move_time(wp - here, *self._profile_dps)
            idle = await self._wait_idle(deadline, limit, f"move to {wp:g} deg", expected_end)
            here = wp
        if idle.flag is not None:
            # The reply flag is only the highest-priority warning: fetch them all. "--" means
            # there are none, so the extra request is skipped then.
            self._raise_faults(await self._warnings())
        if self.settle_s > 0:
            await asyncio.sleep(self.settle_s)
            return await self.position()
        try:  # the idle poll's reply carries the position at rest
            return int(idle.data.split()[0]) / self.mpd
        except (ValueError, IndexError):
            return await self.position()

    async def _wait_idle(
        self, deadline: float, limit: float, what: str, expected_end: float | None = None
    ) -> Reply:
        """Poll until the axis is idle; returns the idle reply (its flag is the top warning,
        its data the position in microsteps: each poll is a ``get pos``, so the reply that
        shows the axis idle also says where it came to rest)."""
        while True:
            reply = await self._send("get pos")
            if reply.flag in FAULT_FLAGS:
                self._raise_faults([reply.flag])
            if not reply.busy:
                return reply
            now = time.monotonic()
            if now > deadline:
                with contextlib.suppress(Exception):
                    await self.stop()
                raise DeviceUnavailable(
                    self.name, f"{what} did not finish within {limit:g} s", code="timeout"
                )
            await asyncio.sleep(poll_delay(now, expected_end, self.poll_interval_s))

    async def stop(self) -> None:
        self._rest.forget()
        await self._send("stop")

    async def emergency_stop(self) -> None:
        """Stop at once without deceleration (``estop``)."""
        self._rest.forget()
        await self._send("estop")

    async def status(self) -> StageStatus:
        reply = await self._send("")
        flags = await self._warnings()
        return StageStatus(
            position_deg=await self.position(),
            moving=reply.busy,
            homed=not any(f in NO_REFERENCE_FLAGS for f in flags),
            faults=tuple(f for f in flags if f in FAULT_FLAGS),
            detail={"warnings": flags},
            # Its zero is its home sensor: homing again (the driver does it before a move
            # when the device asks, WR/WH) finds the same zero after a power cycle.
            zero_lost_at_power_up=False,
        )

    async def clear_faults(self) -> None:
        self._rest.forget()
        async with self._op_lock:
            await self._ok("warnings clear")
            self._raise_faults(await self._warnings())
