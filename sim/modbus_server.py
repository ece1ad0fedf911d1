"""A real pymodbus TCP server playing every lamp controller and sensor module of a rig.

Each simulated device answers under its own Modbus device id on one loopback port, with the
register map of its rig-config entry (:class:`gonio.config.LightRegisters`,
:class:`gonio.config.SensorRegisters`). The server runs ``serve_forever`` as a task of an event
loop in a background thread, so synchronous tests and a daemon running its own loop can both
talk to it. Built on pymodbus' ``SimDevice`` register model (3.16+): a device ``action``
hook sees every request, which is where the physics happens:

* a coil write switches a lamp; a level write dims it;
* a write of a non-zero value to a sensor's trigger register starts an exposure: the reading is
  computed from :mod:`gonio.sim.specimen` with the stage angle and the lamps on at that moment,
  and published (values updated, ``sequence`` incremented) once the exposure time, divided by
  ``time_scale``, has passed in wall time; the trigger register reads back 0 (self-clearing);
* input registers (values, sequence, lamp monitor) are refreshed on every read;
* a lamp controller with a ``watchdog`` register has a communication watchdog: writing a
  timeout (seconds after scale, 0 = off) arms it, and when no request has reached that device
  for longer, the lamp switches off by itself (``watchdog_trips`` counts it), as an I/O module
  falls back to its safe state when its master goes silent;
* every answered request is counted per device (:meth:`ModbusRigServer.request_counts`) and
  the latest are kept in order (:meth:`ModbusRigServer.recent_requests`), so tests and
  benchmarks can see how many round trips an operation costs and in which order they went.

Faults, settable from any thread: :meth:`ModbusRigServer.silence` (a device stops answering
for a while; requests hang so the client times out), :meth:`ModbusRigServer.set_lamp_output`
(a lamp's real output drifts, so its monitor leaves the band and the light it gives changes)
and :meth:`ModbusRigServer.force_saturation` (a sensor reports full scale).

A request for a device id the server does not have is answered as a Modbus TCP gateway answers
one for a device that does not reply: exception 0x0B, gateway target device failed to respond
(:class:`_Gateway`; pymodbus' own simulator core answered 4, device failure, and the project's
notes say nothing else).

Register values are encoded here with :mod:`struct`, independently of the driver's decoder.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from gonio.config import LightRegisters, Register, SensorRegisters
from gonio.sim.specimen import NoiseModel, Specimen, expected_counts, sample_counts

__all__ = ["AngleSource", "ModbusRigServer", "SimHolderSpec", "SimLampSpec", "SimSensorSpec"]

_FMT = {"u16": ">H", "s16": ">h", "u32": ">I", "s32": ">i", "f32": ">f"}
_COIL_FC = (1, 5, 15)
_HOLDING_WRITE_FC = (6, 16, 23)
_INPUT_READ_FC = (4,)
# pymodbus answers these writes by reading the written registers back through the same
# action hook (values=None): that second call is part of the same request, not a new one.
_ECHOED_WRITE_FC = (5, 6, 23)


class AngleSource(Protocol):
    """Where the stage is now (a :class:`gonio.sim.motion.StageMotion`)."""

    def position_deg(self) -> float: ...


def to_words(reg: Register, physical: float) -> list[int]:
    """The 16-bit words a device stores for ``physical`` (raw = physical / scale)."""
    raw = physical / reg.scale
    fmt = _FMT[reg.type]
    if reg.type != "f32":
        bits = 16 * (2 if reg.type[1:] == "32" else 1)
        signed = reg.type[0] == "s"
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        raw = min(max(round(raw), lo), hi)  # a real ADC/register saturates, it does not wrap
        data = struct.pack(fmt, int(raw))
    else:
        data = struct.pack(fmt, float(raw))
    words = [int.from_bytes(data[k : k + 2], "big") for k in range(0, len(data), 2)]
    return words[::-1] if reg.word_order == "little" else words


def from_words(reg: Register, words: Sequence[int]) -> float:
    """Physical value (raw * scale) of the words a client wrote."""
    w = list(words)[::-1] if reg.word_order == "little" else list(words)
    data = b"".join(int(x).to_bytes(2, "big") for x in w)
    return float(struct.unpack(_FMT[reg.type], data)[0]) * reg.scale


@dataclass
class SimLampSpec:
    """A simulated lamp controller.

    Attributes
    ----------
    name : str
    device_id : int, Modbus device id (1-247)
    registers : LightRegisters, its register map
    direction : (3,) unit vector toward the lamp, lab frame
    irradiance : float
        At full level, counts per (1/sr) per second at sensor gain 1 (see ``sim.specimen``).
    """

    name: str
    device_id: int
    registers: LightRegisters
    direction: Sequence[float]
    irradiance: float
    on: bool = False
    level: float = 1.0
    output_factor: float = 1.0  # 1 = healthy; fault injection changes it
    watchdog_s: float = 0.0  # communication watchdog timeout (0 = not armed), wall seconds
    last_request: float = 0.0  # time.monotonic() of the last request this device received
    watchdog_trips: int = 0  # times the watchdog switched the lamp off


@dataclass
class Exposure:
    """One triggered exposure of a simulated sensor.

    What the sensor sees is fixed at the trigger (the lamps on, the stage angle, the gain,
    the exposure time, the specimen); its counts are drawn from it by ``render`` once, during
    the exposure (or when published, whichever comes first). A real sensor module
    acknowledges a trigger at once; rendering before the acknowledgement would put the
    simulator's own computing time between the triggers of a light's sensors, time a scan on
    the real rig does not spend.
    """

    ready: float  # time.monotonic() when the counts are published
    render: Callable[[], list[float]]
    counts: list[float] | None = None

    def rendered(self) -> list[float]:
        """The counts, drawn now if they were not yet."""
        if self.counts is None:
            self.counts = self.render()
        return self.counts


@dataclass
class SimSensorSpec:
    """A simulated triggered sensor module.

    Attributes
    ----------
    name : str
    device_id : int
    registers : SensorRegisters
    direction : (3,) unit vector toward the sensor, lab frame
    noise : NoiseModel (its ``saturation`` is the ADC full scale, raw counts)
    """

    name: str
    device_id: int
    registers: SensorRegisters
    direction: Sequence[float]
    noise: NoiseModel = field(default_factory=NoiseModel)
    exposure_s: float = 0.01
    gain: float = 1.0
    sequence: int = 0
    values: list[float] = field(default_factory=list)
    pending: Exposure | None = None  # the exposure under way
    saturate: bool = False
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))


@dataclass
class SimHolderSpec:
    """The simulated specimen holder: what is on the stage, switchable over Modbus.

    Holding 0 (``u16``): 0 = the specimen, 1 = the white reference; holding 1 (``u16``): the
    reference's albedo in per mille. A write of holding 0 calls ``load(code, albedo)`` (with the
    albedo of holding 1 as written in the same request, else as stored); reads return
    ``state()``.

    Attributes
    ----------
    device_id : int
    state : callable returning (code, albedo)
    load : callable taking (code, albedo)
    """

    device_id: int
    state: Any
    load: Any


def _span(regs: Sequence[Register], table: str) -> int:
    """Registers needed to cover every mapped address of ``table`` from 0 (at least 1)."""
    ends = [r.address + r.width for r in regs if r.table == table]
    return max([1, *ends])


class _Gateway:
    """The server's device store (pymodbus' ``SimCore``), answering for unknown ids as a gateway.

    ``SimCore`` looks up an unknown device id as device 0 and, having none, fails with a
    ``KeyError`` that pymodbus answers with exception 4 (device failure). A Modbus TCP gateway
    answers a request for a device that does not reply with 0x0B (gateway target device failed
    to respond): raising ``NoSuchIdException`` makes pymodbus' request handler answer so.
    """

    def __init__(self, core: Any) -> None:
        self._core = core

    def device_ids(self) -> list[int]:
        """The ids of the devices served."""
        return list(self._core.device_ids())

    def _check(self, device_id: int) -> None:
        if device_id not in self._core.devices:
            raise NoSuchIdException(f"no device {device_id}")

    async def async_getValues(self, device_id: int, func_code: int, address: int,
                              count: int = 1) -> Any:
        """Read from device ``device_id``; an unknown id is the gateway's 0x0B."""
        self._check(device_id)
        return await self._core.async_getValues(device_id, func_code, address, count)

    async def async_setValues(self, device_id: int, func_code: int, address: int,
                              values: Any) -> Any:
        """Write to device ``device_id``; an unknown id is the gateway's 0x0B."""
        self._check(device_id)
        return await self._core.async_setValues(device_id, func_code, address, values)


class ModbusRigServer:
    """All lamps and sensors of a simulated rig behind one Modbus TCP server.

    Parameters
    ----------
    specimen : Specimen
        The specimen the sensors look at.
    stage : AngleSource
        Reports the current stage angle, degrees.
    lamps, sensors : sequences of SimLampSpec / SimSensorSpec
        Device ids must be unique and non-zero.
    time_scale : float
        Sim seconds per wall second: an exposure of ``t`` completes after ``t / time_scale``.
    seed : int
        Seeds every sensor's noise generator (sensor ``k`` uses ``(seed, k)``).
    host, port : str, int
        Where to listen; port 0 picks a free port (see :attr:`port` after :meth:`start`).
    """

    def __init__(
        self,
        specimen: Specimen,
        stage: AngleSource,
        lamps: Sequence[SimLampSpec],
        sensors: Sequence[SimSensorSpec],
        *,
        time_scale: float = 1.0,
        seed: int = 0,
        host: str = "127.0.0.1",
        port: int = 0,
        holder: SimHolderSpec | None = None,
    ) -> None:
        ids = [d.device_id for d in lamps] + [d.device_id for d in sensors]
        ids += [holder.device_id] if holder is not None else []
        if len(set(ids)) != len(ids) or 0 in ids:
            raise ValueError(f"simulated Modbus device ids must be unique and non-zero: {ids}")
        if time_scale <= 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.specimen = specimen
        self.stage = stage
        self.lamps = {x.name: x for x in lamps}
        self.sensors = {x.name: x for x in sensors}
        for k, s in enumerate(sensors):
            if len(s.registers.values) != specimen.n_channels:
                raise ValueError(
                    f"sensor {s.name} maps {len(s.registers.values)} channels but the "
                    f"specimen's BRDF has {specimen.n_channels}"
                )
            s.rng = np.random.default_rng([seed, k])
            if not s.values:
                s.values = [0.0] * len(s.registers.values)
        self.holder = holder
        self.time_scale = time_scale
        self.host = host
        self.port = port
        self._lock = threading.RLock()
        self._silent_until: dict[str, float] = {}
        self._requests = dict.fromkeys([*self.lamps, *self.sensors], 0)
        self._recent: collections.deque[tuple[str, int, int]] = collections.deque(maxlen=1000)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: ModbusTcpServer | None = None
        self._watchdog_task: asyncio.Task[None] | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> ModbusRigServer:
        """Start listening in a background thread; returns self with :attr:`port` set."""
        if self._thread is not None:
            return self
        loop = asyncio.new_event_loop()
        self._loop = loop
        self._thread = threading.Thread(target=loop.run_forever, name="sim-modbus", daemon=True)
        self._thread.start()
        try:
            asyncio.run_coroutine_threadsafe(self._serve(), loop).result(timeout=10)
        except BaseException:
            self.close()
            raise
        return self

    async def _serve(self) -> None:
        devices = [self._lamp_device(x) for x in self.lamps.values()]
        devices += [self._sensor_device(x) for x in self.sensors.values()]
        if self.holder is not None:
            devices.append(self._holder_device(self.holder))
        server = ModbusTcpServer(context=devices, address=(self.host, self.port))
        # Duck-typed for the two calls the request handler makes (pymodbus types the
        # attribute as its own store classes).
        server.context = cast(Any, _Gateway(server.context))
        cannot = OSError(f"the simulated Modbus server cannot listen on {self.host}:{self.port} "
                         "(is the port in use? choose another, or 0 for any free port)")
        try:
            await server.serve_forever(background=True)
        except RuntimeError:  # pymodbus' "Could not start listen"
            raise cannot from None
        self._watchdog_task = asyncio.create_task(self._watchdogs(), name="sim-lamp-watchdogs")
        sockets = getattr(server.transport, "sockets", None)
        if not sockets:
            raise cannot
        self.port = int(sockets[0].getsockname()[1])
        self._server = server

    def close(self) -> None:
        """Stop the server and its thread; safe to call twice."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        with self._lock:
            self._silent_until.clear()  # let hung requests finish
        if self._server is not None and loop.is_running():
            server = self._server

            async def _stop() -> None:
                await server.shutdown()
                current = asyncio.current_task()
                for task in asyncio.all_tasks():
                    if task is not current:
                        task.cancel()

            # A broken server must not keep the loop (and the thread) alive.
            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(_stop(), loop).result(timeout=5)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout=5)
        if not thread.is_alive():
            loop.close()
        self._loop = self._thread = self._server = None

    def __enter__(self) -> ModbusRigServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ faults
    def silence(self, name: str, duration_s: float | None) -> None:
        """Make device ``name`` stop answering for ``duration_s`` wall seconds (None: until
        :meth:`clear_faults`). Requests to it hang, so clients time out."""
        self._device_name_check(name)
        with self._lock:
            self._silent_until[name] = (
                float("inf") if duration_s is None else time.monotonic() + duration_s
            )

    def set_lamp_output(self, name: str, factor: float) -> None:
        """Scale lamp ``name``'s real output by ``factor`` (1 = healthy; 0.5 = half output)."""
        if name not in self.lamps:
            raise KeyError(f"no simulated lamp named {name!r}; lamps are {sorted(self.lamps)}")
        with self._lock:
            self.lamps[name].output_factor = float(factor)

    def force_saturation(self, name: str, on: bool = True) -> None:
        """Make sensor ``name`` report full scale on every channel (a blinding reflection)."""
        if name not in self.sensors:
            raise KeyError(
                f"no simulated sensor named {name!r}; sensors are {sorted(self.sensors)}"
            )
        with self._lock:
            self.sensors[name].saturate = on

    def clear_faults(self) -> None:
        """Back to healthy devices."""
        with self._lock:
            self._silent_until.clear()
            for lamp in self.lamps.values():
                lamp.output_factor = 1.0
            for s in self.sensors.values():
                s.saturate = False

    def _device_name_check(self, name: str) -> None:
        if name not in self.lamps and name not in self.sensors:
            raise KeyError(
                f"no simulated device named {name!r}; devices are "
                f"{sorted([*self.lamps, *self.sensors])}"
            )

    async def _wait_if_silent(self, name: str) -> None:
        while True:
            with self._lock:
                until = self._silent_until.get(name, 0.0)
            if time.monotonic() >= until:
                return
            await asyncio.sleep(0.01)

    # ------------------------------------------------------------------ lamps
    WATCHDOG_TICK_S = 0.02
    """How often armed lamp watchdogs are checked, wall seconds."""

    async def _watchdogs(self) -> None:
        while True:
            await asyncio.sleep(self.WATCHDOG_TICK_S)
            now = time.monotonic()
            with self._lock:
                for lamp in self.lamps.values():
                    silent_s = now - lamp.last_request
                    if lamp.watchdog_s > 0 and lamp.on and silent_s > lamp.watchdog_s:
                        lamp.on = False
                        lamp.watchdog_trips += 1

    def _lamp_device(self, lamp: SimLampSpec) -> SimDevice:
        regs = lamp.registers
        mapped = [r for r in (regs.level, regs.monitor, regs.watchdog) if r is not None]
        holding = _span(mapped, "holding")
        inputs = _span(mapped, "input")
        coils = (regs.on_coil // 16 + 1) * 16

        async def action(
            fc: int,
            start: int,
            address: int,
            count: int,
            registers: list[int],
            values: list[int] | list[bool] | None,
        ) -> ExcCodes | None:
            await self._wait_if_silent(lamp.name)
            with self._lock:
                self._count(lamp.name, fc, address, values)
                lamp.last_request = time.monotonic()
                if fc in _COIL_FC and values is not None:
                    if address <= regs.on_coil < address + len(values):
                        lamp.on = bool(values[regs.on_coil - address])
                elif fc in _COIL_FC:
                    # A read shows the lamp's real state (the watchdog may have cleared it).
                    # Coils are bit-addressed: 16 to a word of the block's image.
                    word, bit = regs.on_coil // 16 - start, regs.on_coil % 16
                    registers[word] = (registers[word] & ~(1 << bit)) | (int(lamp.on) << bit)
                elif fc in _HOLDING_WRITE_FC and values is not None:
                    image = self._merged(registers, start, address, values)
                    written = range(address, address + len(values))
                    if regs.watchdog is not None and regs.watchdog.address in written:
                        timeout = self._read_image(regs.watchdog, image, start)
                        if timeout < 0:
                            return ExcCodes.ILLEGAL_VALUE
                        lamp.watchdog_s = timeout
                    if regs.level is not None and regs.level.address in written:
                        level = self._read_image(regs.level, image, start)
                        if not 0.0 <= level <= 1.0:
                            return ExcCodes.ILLEGAL_VALUE
                        lamp.level = level
                elif fc in _INPUT_READ_FC and regs.monitor is not None:
                    output = lamp.level * lamp.output_factor if lamp.on else 0.0
                    self._store(registers, start, regs.monitor, output)
            return None

        return SimDevice(
            id=lamp.device_id,
            simdata=(
                [SimData(0, count=coils, values=False, datatype=DataType.BITS)],
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=holding, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, count=inputs, values=0, datatype=DataType.REGISTERS)],
            ),
            action=action,
        )

    # ------------------------------------------------------------------ specimen holder
    def _holder_device(self, holder: SimHolderSpec) -> SimDevice:
        code_reg = Register(table="holding", address=0, type="u16")
        albedo_reg = Register(table="holding", address=1, type="u16", scale=0.001)

        async def action(
            fc: int,
            start: int,
            address: int,
            count: int,
            registers: list[int],
            values: list[int] | list[bool] | None,
        ) -> ExcCodes | None:
            with self._lock:
                if fc in _HOLDING_WRITE_FC and values is not None:
                    image = self._merged(registers, start, address, values)
                    code = int(self._read_image(code_reg, image, start))
                    albedo = self._read_image(albedo_reg, image, start)
                    if address > 0:  # only the albedo was written: nothing moves
                        return None
                    if code not in (0, 1) or (code == 1 and not 0 < albedo <= 1):
                        return ExcCodes.ILLEGAL_VALUE
                    holder.load(code, albedo)
                elif fc == 3:
                    code, albedo = holder.state()
                    self._store(registers, start, code_reg, float(code))
                    self._store(registers, start, albedo_reg, float(albedo))
            return None

        return SimDevice(
            id=holder.device_id,
            simdata=(
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=2, values=[0, 990], datatype=DataType.REGISTERS)],
                [SimData(0, count=1, values=0, datatype=DataType.REGISTERS)],
            ),
            action=action,
        )

    # ------------------------------------------------------------------ sensors
    def _sensor_device(self, sensor: SimSensorSpec) -> SimDevice:
        regs = sensor.registers
        mapped = [*regs.values, regs.exposure, regs.trigger, regs.sequence]
        mapped += [regs.gain] if regs.gain is not None else []
        holding = _span(mapped, "holding")
        inputs = _span(mapped, "input")

        async def action(
            fc: int,
            start: int,
            address: int,
            count: int,
            registers: list[int],
            values: list[int] | list[bool] | None,
        ) -> ExcCodes | None:
            await self._wait_if_silent(sensor.name)
            with self._lock:
                self._count(sensor.name, fc, address, values)
                self._publish_if_ready(sensor)
                if fc in _HOLDING_WRITE_FC and values is not None:
                    return self._sensor_write(sensor, start, address, registers, values)
                # Value and sequence registers live in either table; refresh them on any read.
                if fc in (3, 4):
                    table = "input" if fc == 4 else "holding"
                    for reg, v in zip(regs.values, sensor.values, strict=True):
                        if reg.table == table:
                            # A sensor register holds raw counts: physical = counts * scale.
                            self._store(registers, start, reg, v * reg.scale)
                    if regs.sequence.table == table:
                        self._store(
                            registers, start, regs.sequence, sensor.sequence * regs.sequence.scale
                        )
            return None

        return SimDevice(
            id=sensor.device_id,
            simdata=(
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=holding, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, count=inputs, values=0, datatype=DataType.REGISTERS)],
            ),
            action=action,
        )

    def _sensor_write(
        self,
        sensor: SimSensorSpec,
        start: int,
        address: int,
        registers: list[int],
        values: list[int] | list[bool],
    ) -> ExcCodes | None:
        regs = sensor.registers
        image = self._merged(registers, start, address, values)
        written = range(address, address + len(values))

        def touched(reg: Register) -> bool:
            return reg.address in written or reg.address + reg.width - 1 in written

        if touched(regs.exposure):
            exposure = self._read_image(regs.exposure, image, start)
            if not exposure > 0:
                return ExcCodes.ILLEGAL_VALUE
            sensor.exposure_s = exposure
        if regs.gain is not None and touched(regs.gain):
            gain = self._read_image(regs.gain, image, start)
            if not gain > 0:
                return ExcCodes.ILLEGAL_VALUE
            sensor.gain = gain
        if touched(regs.trigger) and self._read_image(regs.trigger, image, start) != 0:
            self._trigger(sensor)
            # Self-clearing command register: what is stored (and read back) is 0.
            a = regs.trigger.address - address
            for k in range(regs.trigger.width):
                if 0 <= a + k < len(values):
                    values[a + k] = 0  # type: ignore[call-overload]
        return None

    def _trigger(self, sensor: SimSensorSpec) -> None:
        if sensor.pending is not None:
            # A trigger before the last exposure was published: draw its counts first, so
            # the sensor's noise is drawn in trigger order whatever the timing.
            sensor.pending.rendered()
        angle = self.stage.position_deg()
        lights = [
            (
                np.asarray(lamp.direction, dtype=float),
                lamp.irradiance * lamp.level * lamp.output_factor,
            )
            for lamp in self.lamps.values()
            if lamp.on
        ]
        specimen, gain, exposure_s = self.specimen, sensor.gain, sensor.exposure_s
        saturate = sensor.saturate

        def render() -> list[float]:
            signal = expected_counts(specimen, lights, sensor.direction, angle, gain, exposure_s)
            counts = sample_counts(signal, exposure_s, sensor.noise, sensor.rng)
            if saturate:
                counts = np.full_like(counts, sensor.noise.saturation)
            return [float(c) for c in counts]

        wall_s = exposure_s / self.time_scale
        sensor.pending = exposure = Exposure(time.monotonic() + wall_s, render)
        # Drawn halfway through the exposure, when the link is idle (the trigger's reply
        # goes out first); on this server's loop, under the device lock.
        asyncio.get_running_loop().call_later(wall_s / 2, self._render, exposure)

    def _render(self, exposure: Exposure) -> None:
        with self._lock:
            exposure.rendered()

    def _publish_if_ready(self, sensor: SimSensorSpec) -> None:
        if sensor.pending is not None and time.monotonic() >= sensor.pending.ready:
            sensor.values = sensor.pending.rendered()
            sensor.pending = None
            seq = sensor.registers.sequence
            bits = 16 * seq.width - (1 if seq.type[0] == "s" else 0)
            sensor.sequence = (sensor.sequence + 1) % (1 << bits)

    # ------------------------------------------------------------------ register images
    @staticmethod
    def _merged(
        registers: list[int], start: int, address: int, values: list[int] | list[bool]
    ) -> list[int]:
        # The action runs before pymodbus stores the written values: decode from a copy
        # with the write applied.
        image = list(registers)
        for k, v in enumerate(values):
            image[address - start + k] = int(v)
        return image

    @staticmethod
    def _read_image(reg: Register, image: list[int], start: int) -> float:
        a = reg.address - start
        return from_words(reg, image[a : a + reg.width])

    @staticmethod
    def _store(registers: list[int], start: int, reg: Register, physical: float) -> None:
        a = reg.address - start
        registers[a : a + reg.width] = to_words(reg, physical)

    def _count(self, name: str, fc: int, address: int, values: object) -> None:
        if not (fc in _ECHOED_WRITE_FC and values is None):
            self._requests[name] += 1
            self._recent.append((name, fc, address))

    # ------------------------------------------------------------------ inspection
    def request_counts(self) -> dict[str, int]:
        """Requests answered per device since the server started (round trips on the wire)."""
        with self._lock:
            return dict(self._requests)

    def recent_requests(self) -> list[tuple[str, int, int]]:
        """The last 1000 requests in arrival order: (device name, function code, address)."""
        with self._lock:
            return list(self._recent)

    def snapshot(self) -> dict[str, Any]:
        """Current device states (for tests and the CLI's status line)."""
        with self._lock:
            return {
                "lamps": {n: (x.on, x.level, x.output_factor) for n, x in self.lamps.items()},
                "watchdogs": {n: (x.watchdog_s, x.watchdog_trips) for n, x in self.lamps.items()},
                "sensors": {n: (x.sequence, list(x.values)) for n, x in self.sensors.items()},
            }
