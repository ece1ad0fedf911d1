"""Lights and sensors on Modbus TCP, driven from the register map in the rig config.

Built on pymodbus' ``AsyncModbusTcpClient`` (3.10+ keyword ``device_id=``). Devices that sit
behind the same gateway share one connection through a :class:`ModbusPool`; a Modbus TCP
connection must not carry two requests at once, so every request holds the connection's
``asyncio.Lock``. After any transport failure the connection is dropped and the next request
reconnects, so a device that comes back is used again without restarting the daemon.

Register values are decoded here (``physical = raw * scale``); the simulator in
``gonio.sim.modbus_server`` has its own independent encoder so that each can catch the other's
mistakes.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Any, TypeVar

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from gonio.config import LightConfig, Register, SensorConfig
from gonio.drivers._ownership import claim
from gonio.hal import (
    DeviceFault,
    DeviceUnavailable,
    LabDirection,
    LampOutOfBand,
    Light,
    LightStatus,
    Sensor,
    SensorReading,
    SensorStatus,
)

__all__ = ["ModbusConnection", "ModbusLight", "ModbusPool", "ModbusSensor", "one_request"]

T = TypeVar("T")

_DATATYPE = {
    "u16": AsyncModbusTcpClient.DATATYPE.UINT16,
    "s16": AsyncModbusTcpClient.DATATYPE.INT16,
    "u32": AsyncModbusTcpClient.DATATYPE.UINT32,
    "s32": AsyncModbusTcpClient.DATATYPE.INT32,
    "f32": AsyncModbusTcpClient.DATATYPE.FLOAT32,
}
_RAW_RANGE = {
    "u16": (0, 0xFFFF),
    "s16": (-0x8000, 0x7FFF),
    "u32": (0, 0xFFFFFFFF),
    "s32": (-0x80000000, 0x7FFFFFFF),
}
# A Modbus read returns at most 125 registers; larger spans are read register by register.
_MAX_SPAN = 125


def one_request(regs: Sequence[Register]) -> bool:
    """True when :meth:`_ModbusDevice.read_many_raw` reads all of ``regs`` in one request."""
    if not regs or len({r.table for r in regs}) != 1:
        return False
    lo = min(r.address for r in regs)
    hi = max(r.address + r.width for r in regs)
    return hi - lo <= _MAX_SPAN


# --------------------------------------------------------------------------- codec
def decode(reg: Register, words: Sequence[int]) -> float:
    """Raw value of ``reg`` from its ``reg.width`` registers (before scale)."""
    value = AsyncModbusTcpClient.convert_from_registers(
        list(words), _DATATYPE[reg.type], word_order=reg.word_order
    )
    return float(value)  # type: ignore[arg-type]


def encode(reg: Register, physical: float, what: str) -> list[int]:
    """Registers holding ``physical / scale``; ``ValueError`` when it does not fit the type."""
    raw: float = physical / reg.scale
    if reg.type != "f32":
        lo, hi = _RAW_RANGE[reg.type]
        raw = round(raw)
        if not lo <= raw <= hi:
            raise ValueError(
                f"{what}: {physical} is {raw} raw units at scale {reg.scale}, outside the "
                f"{reg.type} range [{lo}, {hi}]; change the value or the register's scale"
            )
        return AsyncModbusTcpClient.convert_to_registers(
            int(raw), _DATATYPE[reg.type], word_order=reg.word_order
        )
    return AsyncModbusTcpClient.convert_to_registers(
        float(raw), _DATATYPE[reg.type], word_order=reg.word_order
    )


# --------------------------------------------------------------------------- transport
class ModbusConnection:
    """One Modbus TCP connection, used by one request at a time, reconnected on failure.

    Parameters
    ----------
    host, port : where the device (or gateway) listens
    timeout_s : float
        Per-request time limit, seconds; a request that takes longer raises
        :class:`DeviceUnavailable` and drops the connection.
    """

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        self.host = host
        self.port = port
        self.timeout_s = timeout_s
        self._client: AsyncModbusTcpClient | None = None
        self._claim: Any = None  # this process's lock on the endpoint, from first use to close
        self._lock = asyncio.Lock()
        self.users = 0
        # Changes whenever the link is dropped or established: state a device kept for this
        # link (a sensor's last sequence number) is only valid within the generation it was
        # read in, since the device may have restarted in between.
        self.generation = 0

    def _drop(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
            self.generation += 1

    async def _connected(self, device: str) -> AsyncModbusTcpClient:
        if self._client is not None and self._client.connected:
            return self._client
        if self._claim is None:
            # Before any byte goes out: a second program on this endpoint would interleave its
            # requests with ours (sensor triggers, lamp coils) and corrupt both programs' data.
            self._claim = claim(device, f"tcp://{self.host}:{self.port}")
        self._drop()
        # pymodbus' own reconnect loop is off (reconnect_delay=0): this class reconnects on
        # the next request instead, so a dead device never keeps a background task busy.
        client = AsyncModbusTcpClient(
            self.host, port=self.port, timeout=self.timeout_s, retries=0, reconnect_delay=0
        )
        try:
            ok = await asyncio.wait_for(client.connect(), self.timeout_s + 0.5)
        except (TimeoutError, OSError, ModbusException):
            ok = False
        if not ok:
            client.close()
            raise DeviceUnavailable(
                device,
                f"no Modbus TCP connection to {self.host}:{self.port}; check that the device "
                "is powered and the host/port in the rig config",
                code="connect",
            )
        self._client = client
        self.generation += 1
        return client

    async def request(
        self, device: str, what: str, call: Callable[[AsyncModbusTcpClient], Awaitable[Any]],
        device_id: int | None = None,
    ) -> Any:
        """Run one request under the connection lock and check the reply.

        ``device_id``, the Modbus id the request goes to, is named when no reply comes (a
        device id nobody answers to, on a serial line behind a gateway that passes silence on).

        Raises
        ------
        DeviceUnavailable
            No connection, no reply within ``timeout_s`` or a broken reply (recoverable).
        DeviceFault
            The device answered with a Modbus exception (wrong address in the register map:
            not recoverable).
        """
        async with self._lock:
            client = await self._connected(device)
            try:
                # asyncio.timeout, unlike wait_for, runs the call in this task: no extra task
                # and loop turns per request, which a scan pays hundreds of times an angle set.
                async with asyncio.timeout(self.timeout_s + 0.5):
                    reply = await call(client)
            except (TimeoutError, ModbusException, OSError) as exc:
                self._drop()
                at = (f"device_id {device_id} at {self.host}:{self.port}"
                      if device_id is not None else f"{self.host}:{self.port}")
                check = (f"; check that a device with id {device_id} is there, powered and "
                         "wired (modbus.device_id in the rig config)"
                         if device_id is not None else "")
                raise DeviceUnavailable(
                    device,
                    f"{what}: no valid reply from {at} within "
                    f"{self.timeout_s:g} s ({type(exc).__name__}: {exc}){check}",
                    code="timeout",
                ) from None
        task = asyncio.current_task()
        if task is not None and task.cancelling():
            # pymodbus can complete a request whose task was cancelled while it waited for the
            # reply, dropping the cancellation: honour it here, or a cancelled exposure would
            # run on and be taken for the next one.
            raise asyncio.CancelledError
        if reply.isError():
            raise DeviceFault(
                device,
                f"{what}: {self._refusal(reply)}",
                code="modbus_exception",
                recoverable=False,
            )
        return reply

    def _refusal(self, reply: Any) -> str:
        """What a Modbus exception reply means and where to look, by its exception code.

        Only an illegal address (code 2) points at the register map: a device id with no
        device behind it (a gateway's codes 10 and 11, as gonio's simulator answers too, or
        code 4 from a server that has no such device, as pymodbus' own simulator core does) is
        the ``device_id`` or the wiring.
        """
        code = getattr(reply, "exception_code", None)
        dev = getattr(reply, "dev_id", None)
        at = f"device_id {dev} at {self.host}:{self.port}"
        raw = f"Modbus exception {code}"
        if code == 2:
            return (f"{at} has no such register ({raw}, illegal data address); check this "
                    "address in the rig config's register map")
        if code == 1:
            return (f"{at} does not support this request ({raw}, illegal function); check "
                    "the register's table in the rig config's register map")
        if code == 3:
            return (f"{at} refused the value written ({raw}, illegal data value); check the "
                    "register's type and scale in the rig config's register map")
        if code in (10, 11):
            return (f"no device answers as {at} ({raw}, gateway: no path or no response); "
                    "check modbus.device_id in the rig config and the device's wiring and "
                    "power")
        if code == 4:
            return (f"{at} reports a device failure ({raw}); check that a device with this "
                    "id is there (modbus.device_id in the rig config: a server without it "
                    "can answer so) and that it works")
        return (f"{at} refused the request ({raw}: {reply}); check this device's entry in "
                "the rig config")

    def close(self) -> None:
        self._drop()
        owned, self._claim = self._claim, None
        if owned is not None:
            owned.release()


class ModbusPool:
    """Shares one :class:`ModbusConnection` per ``host:port`` among the devices of a rig."""

    def __init__(self) -> None:
        self._conns: dict[tuple[str, int], ModbusConnection] = {}

    def acquire(self, host: str, port: int, timeout_s: float) -> ModbusConnection:
        """The connection for ``host:port`` (its timeout is the largest asked for)."""
        conn = self._conns.get((host, port))
        if conn is None:
            conn = self._conns[(host, port)] = ModbusConnection(host, port, timeout_s)
        conn.timeout_s = max(conn.timeout_s, timeout_s)
        conn.users += 1
        return conn

    def release(self, conn: ModbusConnection) -> None:
        """One user is done; the last one closes the socket."""
        conn.users -= 1
        if conn.users <= 0:
            conn.close()
            self._conns.pop((conn.host, conn.port), None)


class _ModbusDevice:
    """Register access for one device id on a (possibly shared) connection."""

    def __init__(
        self,
        name: str,
        host: str,
        port: int,
        device_id: int,
        timeout_s: float,
        pool: ModbusPool | None,
    ) -> None:
        self.name = name
        self._pool = pool if pool is not None else ModbusPool()
        self._addr = (host, port, timeout_s)
        self._device_id = device_id
        self._conn: ModbusConnection | None = None
        # When the last request this device answered was sent (monotonic seconds): a device's
        # communication watchdog restarts at every request that reaches it.
        self.last_request = float("-inf")

    async def _request(self, what: str, call: Callable[[AsyncModbusTcpClient], Awaitable[Any]]
                       ) -> Any:
        sent = time.monotonic()
        reply = await self._connection().request(self.name, what, call, self._device_id)
        self.last_request = sent
        return reply

    def _connection(self) -> ModbusConnection:
        if self._conn is None:
            self._conn = self._pool.acquire(*self._addr)
        return self._conn

    @property
    def generation(self) -> int:
        """Changes whenever the underlying link drops or connects (0 before the first)."""
        return self._conn.generation if self._conn is not None else 0

    def release(self) -> None:
        """Give the connection back to the pool (the last user closes it)."""
        if self._conn is not None:
            self._pool.release(self._conn)
            self._conn = None

    async def _read_words(self, table: str, address: int, count: int) -> list[int]:
        dev = self._device_id

        async def call(c: AsyncModbusTcpClient) -> Any:
            if table == "input":
                return await c.read_input_registers(address, count=count, device_id=dev)
            return await c.read_holding_registers(address, count=count, device_id=dev)

        what = f"read {table} registers {address}..{address + count - 1}"
        reply = await self._request(what, call)
        words = list(reply.registers)
        if len(words) < count:
            raise DeviceUnavailable(self.name, f"{what}: short reply {words}", code="short")
        return words[:count]

    async def read_raw(self, reg: Register) -> float:
        return decode(reg, await self._read_words(reg.table, reg.address, reg.width))

    async def read_many_raw(self, regs: Sequence[Register]) -> list[float]:
        """Raw values of several registers, one request per table when they are close."""
        out: dict[int, float] = {}
        for table in ("holding", "input"):
            idx = [k for k, r in enumerate(regs) if r.table == table]
            if not idx:
                continue
            lo = min(regs[k].address for k in idx)
            hi = max(regs[k].address + regs[k].width for k in idx)
            if hi - lo <= _MAX_SPAN:
                words = await self._read_words(table, lo, hi - lo)
                for k in idx:
                    a = regs[k].address - lo
                    out[k] = decode(regs[k], words[a : a + regs[k].width])
            else:
                for k in idx:
                    out[k] = await self.read_raw(regs[k])
        return [out[k] for k in range(len(regs))]

    async def write(self, reg: Register, physical: float, what: str) -> None:
        words = encode(reg, physical, f"{self.name}: {what}")
        dev = self._device_id

        async def call(c: AsyncModbusTcpClient) -> Any:
            if len(words) == 1:
                return await c.write_register(reg.address, words[0], device_id=dev)
            return await c.write_registers(reg.address, words, device_id=dev)

        await self._request(f"write {what} at {reg.address}", call)

    async def write_coil(self, address: int, value: bool) -> None:
        dev = self._device_id

        async def call(c: AsyncModbusTcpClient) -> Any:
            return await c.write_coil(address, value, device_id=dev)

        await self._request(f"write coil {address}", call)

    async def read_coil(self, address: int) -> bool:
        dev = self._device_id

        async def call(c: AsyncModbusTcpClient) -> Any:
            return await c.read_coils(address, count=1, device_id=dev)

        reply = await self._request(f"read coil {address}", call)
        return bool(reply.bits[0])


# --------------------------------------------------------------------------- light
class ModbusLight(Light):
    """A light switched by a coil, optionally dimmed and monitored through registers.

    Parameters
    ----------
    config : LightConfig
        The ``[[lights]]`` entry.
    pool : ModbusPool, optional
        Shared connections of the rig; a private one when omitted.
    """

    def __init__(self, config: LightConfig, pool: ModbusPool | None = None) -> None:
        self.name = config.name
        self.direction = LabDirection(config.theta_deg, config.phi_deg)
        self.config = config
        m = config.modbus
        self._io = _ModbusDevice(config.name, m.host, m.port, m.device_id, m.timeout_s, pool)
        self._level = config.level
        self._on = False
        self._last_output = float("nan")  # last monitored output, fraction (for messages)
        self._feeder: asyncio.Task[None] | None = None

    async def connect(self) -> None:
        """Check the device answers, write the configured drive level, arm the watchdog."""
        regs = self.config.registers
        self._on = await self._io.read_coil(regs.on_coil)
        if regs.level is not None:
            await self._io.write(regs.level, self._level, "level")
        if regs.watchdog is not None:
            await self._io.write(regs.watchdog, self.config.watchdog_s, "watchdog timeout")

    async def close(self) -> None:
        self._feed(False)
        self._io.release()

    def _feed(self, on: bool) -> None:
        """While the light is on, make sure a request reaches its controller at least every
        third of the watchdog timeout (a long exposure sends it nothing otherwise); when this
        process dies the feeding stops and the controller switches the lamp off. Any request
        to the controller restarts its watchdog, so a feed is sent only after a third of the
        timeout without one: during a scan the lamp's own requests (switching, the output
        check) keep it fed, and no feed queues on the shared link before a sensor's trigger
        or poll."""
        if self.config.registers.watchdog is None:
            return
        if on and self._feeder is None:
            self._feeder = asyncio.create_task(self._feed_loop(), name=f"{self.name}-watchdog")
        elif not on and self._feeder is not None:
            self._feeder.cancel()
            self._feeder = None

    async def _feed_loop(self) -> None:
        period = self.config.watchdog_s / 3.0
        coil = self.config.registers.on_coil
        while True:
            wait = self._io.last_request + period - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
                continue
            try:
                await self._io.read_coil(coil)
            except DeviceFault:  # the engine sees a dead link by itself
                await asyncio.sleep(period)

    async def set_on(self, on: bool) -> None:
        """Switch the light; when switching on with a monitor, check the output band.

        The coil write is acknowledged by the device, so only the monitor is read back (one
        request instead of a full :meth:`status`).

        Raises
        ------
        LampOutOfBand
            After ``warmup_s`` the monitored output differs from the level by more than
            ``band`` (recoverable: a lamp may recover after a longer warm-up).
        """
        if on:
            await self.switch_on()
            return
        await self._io.write_coil(self.config.registers.on_coil, False)
        self._on = False
        self._feed(False)

    async def switch_on(self, *, check: bool = True) -> None:
        """Write the coil, wait ``warmup_s`` and, with ``check``, :meth:`check_output`.

        ``check=False`` leaves the monitor read to the caller (one request fewer before the
        exposure; the engine reads it while the sensors integrate)."""
        regs = self.config.registers
        await self._io.write_coil(regs.on_coil, True)
        self._on = True
        self._feed(True)
        if regs.monitor is not None and self.config.warmup_s > 0:
            await asyncio.sleep(self.config.warmup_s)
        if check:
            await self.check_output()

    async def check_output(self) -> None:
        """Read the monitor (one request; nothing without a monitor register) and raise
        :class:`LampOutOfBand` when the output differs from the level by more than ``band``."""
        regs = self.config.registers
        if regs.monitor is None:
            return
        self._last_output = await self._io.read_raw(regs.monitor) * regs.monitor.scale
        if abs(self._last_output - self._level) > regs.band:
            raise LampOutOfBand(
                self.name,
                f"output {self._last_output:.3f} is outside {self._level:.3f} +- "
                f"{regs.band:.3f}; check the lamp or lengthen warmup_s",
                code="out_of_band",
            )

    async def set_level(self, level: float) -> None:
        """Drive level, fraction in [0, 1]; ``ValueError`` outside or without a level register."""
        if not 0.0 <= level <= 1.0:
            raise ValueError(f"{self.name}: level {level} is outside [0, 1]")
        if self.config.registers.level is None:
            raise ValueError(
                f"{self.name}: this light has no level register in the rig config; it can "
                "only be switched on and off"
            )
        await self._io.write(self.config.registers.level, level, "level")
        self._level = level

    async def status(self) -> LightStatus:
        """Coil state, level and (with a monitor register) whether the output is in band."""
        regs = self.config.registers
        on = await self._io.read_coil(regs.on_coil)
        self._on = on
        in_band = True
        if regs.monitor is not None:
            self._last_output = await self._io.read_raw(regs.monitor) * regs.monitor.scale
            expected = self._level if on else 0.0
            in_band = abs(self._last_output - expected) <= regs.band
        return LightStatus(
            on=on,
            level=self._level,
            in_band=in_band,
            faults=() if in_band else ("out_of_band",),
        )


# --------------------------------------------------------------------------- sensor
class ModbusSensor(Sensor):
    """A triggered multi-channel sensor (photodiode/ADC module) on Modbus.

    One exposure: write 1 to ``trigger``, wait the exposure time, then poll until the
    ``sequence`` register differs from its value before the trigger, and take the ``values``.

    Round trips are what a scan pays for on a shared link, so the driver keeps them few:

    * the sequence number before the trigger is the one seen at the end of the previous
      exposure (or at connect), not read again. It is forgotten after any error, cancellation
      or reconnect, and then read afresh, so a reading is only accepted when the sequence moved
      after this driver's own trigger. This assumes nothing else triggers the sensor while the
      driver is connected (the daemon owns the rig);
    * when ``sequence`` and ``values`` sit in one register table within one request's reach
      (125 registers), each poll reads them together: the reply that shows the new sequence
      number carries that exposure's values (a device publishes them as one snapshot: that is
      what the sequence register is for). Otherwise the values are read after the poll.

    Parameters
    ----------
    config : SensorConfig
        The ``[[sensors]]`` entry.
    pool : ModbusPool, optional
        Shared connections of the rig; a private one when omitted.
    poll_s : float, optional
        Interval between polls once the exposure time has passed, seconds. By default 2 % of
        the exposure, kept within [1 ms, 20 ms]: the first poll after the exposure nearly
        always finds the result, and a late one costs little next to the exposure.
    """

    def __init__(
        self, config: SensorConfig, pool: ModbusPool | None = None, poll_s: float | None = None
    ) -> None:
        self.name = config.name
        self.direction = LabDirection(config.theta_deg, config.phi_deg)
        self.channels = tuple(config.channels)
        self.min_exposure_s = config.min_exposure_s
        self.max_exposure_s = config.max_exposure_s
        self.ranges = config.ranges
        self.config = config
        m = config.modbus
        self._io = _ModbusDevice(config.name, m.host, m.port, m.device_id, m.timeout_s, pool)
        if poll_s is not None and not poll_s > 0:
            raise ValueError(f"{config.name}: poll_s must be > 0 seconds, got {poll_s}")
        self._poll_s = poll_s
        self._exposure_s: float | None = None
        # Range whose gain the register holds, and the connection generation it was written
        # in (a reconnect may mean a restarted device, back at its own default gain).
        self._range: int | None = None
        self._range_generation = -1
        regs = config.registers
        self._poll_regs = [regs.sequence, *regs.values]
        self._poll_carries_values = one_request(self._poll_regs)
        # Last sequence number seen and the connection generation it was read in.
        self._seq: float | None = None
        self._seq_generation = -1

    async def connect(self) -> None:
        """Check the device answers, note its sequence number and write the configured gain."""
        self._seq = None
        self._range = None
        await self._note_sequence()
        if self.config.registers.gain is not None:
            await self._io.write(self.config.registers.gain, self.config.gain, "gain")
            self._range, self._range_generation = 0, self._io.generation
        self._exposure_s = None

    async def close(self) -> None:
        self._seq = None
        self._io.release()

    async def _note_sequence(self) -> float:
        seq = await self._io.read_raw(self.config.registers.sequence)
        self._seq, self._seq_generation = seq, self._io.generation
        return seq

    def poll_interval(self, exposure_s: float) -> float:
        """Seconds between result polls for an exposure of ``exposure_s`` seconds."""
        if self._poll_s is not None:
            return self._poll_s
        return min(max(0.02 * exposure_s, 0.001), 0.02)

    async def _poll(self, before: float) -> tuple[float, list[float] | None]:
        """(sequence, values); values are None while the sequence has not moved."""
        if self._poll_carries_values:
            seq, *values = await self._io.read_many_raw(self._poll_regs)
            return seq, (values if seq != before else None)
        seq = await self._io.read_raw(self.config.registers.sequence)
        if seq == before:
            return seq, None
        return seq, await self._io.read_many_raw(self.config.registers.values)

    def _check_link(self) -> None:
        """Refuse an exposure whose link dropped or reconnected after ``sequence`` was noted:
        the device may have restarted, and its sequence number with it."""
        if self._seq_generation != self._io.generation:
            raise DeviceUnavailable(
                self.name,
                "the Modbus connection was re-established during the exposure; the reading "
                "is discarded and taken again",
                code="reconnected",
                # The link dropped because of some request's failure, often another device's
                # on the same gateway: that device's fault is the one to report.
                secondary=True,
            )

    async def _expose_once(self, exposure_s: float) -> list[float]:
        regs = self.config.registers
        try:
            if self._seq is None or self._seq_generation != self._io.generation:
                await self._note_sequence()
            before = self._seq
            assert before is not None
            await self._io.write(regs.trigger, 1 * regs.trigger.scale, "trigger")
            t0 = time.monotonic()
            await asyncio.sleep(exposure_s)
            # A sensor that accepted the trigger but never finishes is as dead as one that
            # does not answer: give it the exposure plus one request timeout, then give up.
            deadline = t0 + exposure_s + self.config.modbus.timeout_s
            interval = self.poll_interval(exposure_s)
            while True:
                seq, values = await self._poll(before)
                self._check_link()
                if values is not None:
                    self._seq = seq
                    return values
                if time.monotonic() > deadline:
                    raise DeviceUnavailable(
                        self.name,
                        f"no new reading {exposure_s + self.config.modbus.timeout_s:.3g} s "
                        "after the trigger (the sequence register did not change); check the "
                        "trigger and sequence addresses",
                        code="no_data",
                    )
                await asyncio.sleep(interval)
        except BaseException:
            # An interrupted or failed exposure may still complete later and move the
            # sequence: never judge the next exposure against a number from before it.
            self._seq = None
            raise

    async def read(self, exposure_s: float, averages: int = 1) -> SensorReading:
        """Mean of ``averages`` exposures of ``exposure_s`` seconds, in physical units.

        Raises
        ------
        ValueError
            ``exposure_s`` outside ``[min_exposure_s, max_exposure_s]`` or ``averages < 1``.
        DeviceUnavailable
            The sensor stopped answering or never finished the exposure.
        """
        return await self.read_in_range(exposure_s, averages, 0)

    async def read_in_range(self, exposure_s: float, averages: int,
                            range_index: int) -> SensorReading:
        """:meth:`read` at the gain of range ``range_index`` (``gain``, then ``gain_stages``).

        The gain register is written only when the range changes, so a scan that needs no
        ranging sends nothing more; after a failed request the register is written again.

        Raises
        ------
        ValueError
            As :meth:`read`, or ``range_index`` is not one of :attr:`ranges`.
        DeviceUnavailable
            The sensor stopped answering or never finished the exposure.
        """
        if not self.min_exposure_s <= exposure_s <= self.max_exposure_s:
            raise ValueError(
                f"{self.name}: exposure {exposure_s:g} s is outside this sensor's range "
                f"[{self.min_exposure_s:g}, {self.max_exposure_s:g}] s (min_exposure_s / "
                "max_exposure_s in the rig config)"
            )
        if averages < 1:
            raise ValueError(f"{self.name}: averages must be at least 1, got {averages}")
        if not 0 <= range_index < len(self.ranges):
            raise ValueError(
                f"{self.name}: no range {range_index}; it has {len(self.ranges)} (gain and "
                "gain_stages in the rig config)"
            )
        regs = self.config.registers
        if regs.gain is not None and (self._range != range_index
                                      or self._range_generation != self._io.generation):
            self._range = None  # unknown until the write is acknowledged
            await self._io.write(regs.gain, self.config.range_gain(range_index), "gain")
            self._range, self._range_generation = range_index, self._io.generation
        if self._exposure_s != exposure_s:
            await self._io.write(regs.exposure, exposure_s, "exposure")
            self._exposure_s = exposure_s
        sums = [0.0] * len(self.channels)
        saturated = False
        for _ in range(averages):
            raw = await self._expose_once(exposure_s)
            saturated |= any(r >= self.config.saturation_raw for r in raw)
            for k, (r, reg) in enumerate(zip(raw, regs.values, strict=True)):
                sums[k] += r * reg.scale
        return SensorReading(
            values=tuple(s / averages for s in sums),
            saturated=saturated,
            exposure_s=exposure_s,
            averages=averages,
            range_index=range_index,
            range_scale=self.ranges[range_index],
        )

    async def status(self) -> SensorStatus:
        """``ok`` when the sensor answers; the fault code otherwise (never raises for that)."""
        try:
            await self._io.read_raw(self.config.registers.sequence)
        except DeviceFault as exc:
            return SensorStatus(ok=False, faults=(exc.code,))
        return SensorStatus(ok=True)
