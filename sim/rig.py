"""A whole simulated rig from one call: stage, lamps, sensors and the specimen between them.

:func:`start_sim_rig` starts the stage physics (:class:`gonio.sim.motion.StageMotion`), a stage
simulator speaking the real wire protocol (Dynamixel Protocol 2.0 on a pseudo-terminal, or
Zaber ASCII on a pseudo-terminal or TCP), and one Modbus TCP server for every lamp and sensor
(:mod:`gonio.sim.modbus_server`), then writes a :class:`gonio.config.RigConfig` that points at
them. The daemon and the tests run the real drivers against that config, so everything below
the :mod:`gonio.hal` interfaces is exercised as with hardware.

Every simulator runs in its own thread, so a ``SimRig`` works from synchronous code and from
inside a running event loop alike (:func:`start_sim_rig_async` only moves the start-up off the
loop).
"""

from __future__ import annotations

import asyncio
import math
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from gonio.brdf.materials import library
from gonio.brdf.models.analytic import GGX, Lambert, LobeSum
from gonio.brdf.tables.table import BRDFTable
from gonio.config import (
    DynamixelSettings,
    LightConfig,
    LightRegisters,
    ModbusTransport,
    PairConfig,
    Register,
    RigConfig,
    RigSection,
    SensorConfig,
    SensorRegisters,
    StageConfig,
    dump_rig_config,
)
from gonio.hal import LabDirection
from gonio.sim.faults import FAULT_HELP, FaultPlan
from gonio.sim.modbus_server import ModbusRigServer, SimHolderSpec, SimLampSpec, SimSensorSpec
from gonio.sim.motion import StageMotion
from gonio.sim.specimen import BRDFLike, NoiseModel, Specimen
from gonio.wording import SIM_CONFIG_HEADER

__all__ = [
    "DEFAULT_LIGHTS",
    "DEFAULT_SENSORS",
    "FAULT_HELP",
    "WHITE_REFERENCE_ALBEDO",
    "SimRig",
    "SimRigOptions",
    "default_material",
    "resolve_material",
    "start_sim_rig",
    "start_sim_rig_async",
    "white_reference",
]

# Three lamps and four sensors over the hemisphere (theta, phi) in degrees; no lamp shares a
# mount with a sensor (every two devices >= 14 degrees apart). The twelve pairs put five half
# angles between 7 and 11 degrees, at different azimuths about the mirror direction, and the
# rest out to 57 degrees: the default material's streak is read on both its long and its short
# side near the peak, which is what lets the reconstruction render its shape. Chosen by
# rendering (HDR-FLIP and the streak's length) among random rigs, then checked on the held-out
# panel (docs/science.md section 5.1); the rig it replaced had two pairs near the peak (5 and
# 6 degrees) and rendered a round spot with an X-shaped artefact.
DEFAULT_LIGHTS: tuple[tuple[float, float], ...] = ((45.0, 134.0), (17.0, 189.0), (58.0, 321.0))
DEFAULT_SENSORS: tuple[tuple[float, float], ...] = (
    (69.0, 132.0),
    (25.0, 40.0),
    (36.0, 291.0),
    (24.0, 306.0),
)

ADC_FULL_SCALE = float(2**20 - 1)
"""Simulated sensors have a 20-bit ADC: values are u32 registers that saturate here."""
#: The simulated photodiodes' lower gain stages (their amplifier switches by decades): with the
#: default irradiance and exposure, gain 1 saturates above about 5 1/sr, gain 0.001 above
#: about 5000 1/sr, which covers the specular peaks of polished metals (auto-ranging).
SENSOR_GAIN_STAGES = (0.1, 0.01, 0.001)

SIM_REPLY_TIMEOUT_S = 0.5
"""Reply timeout of the simulated Dynamixel's driver: generous, for busy test machines."""

WHITE_REFERENCE_ALBEDO = 0.99
"""Hemispherical albedo of the simulated white reference (a sintered-PTFE-like target)."""

HOLDER_DEVICE_ID = 247
"""Modbus device id of the simulated specimen holder (what is on the stage; not in the rig
config: a real rig has a person there). Holding 0 ``u16``: 0 = the specimen, 1 = the white
reference; holding 1 ``u16``: the white reference's albedo in per mille. Writing holding 0
swaps what is on the stage (``gonio sim-place``)."""

ON_STAGE_SPECIMEN = "specimen"
ON_STAGE_WHITE = "white reference"


def white_reference(albedo: float = WHITE_REFERENCE_ALBEDO,
                    channels: Sequence[str] = ("R", "G", "B")) -> Lambert:
    """A Lambertian white reference: ``f = albedo / pi`` (1/sr) in every channel."""
    if not 0.0 < albedo <= 1.0:
        raise ValueError(f"white reference albedo must be in (0, 1], got {albedo}")
    return Lambert((albedo,) * len(channels), channels=tuple(channels), name="white-reference")


class _WhiteReference:
    """A white reference on the simulated stage (marks it apart from a specimen)."""

    def __init__(self, model: Lambert) -> None:
        self.model = model
        self.channels = model.channels
        self.name = "white-reference"

    def eval(self, wi: Any, wo: Any) -> Any:
        return self.model.eval(wi, wo)


#: The default material's name, as results and the page show it; ``--material`` takes it too.
DEFAULT_MATERIAL_NAME = "sim-brushed"


def default_material() -> BRDFLike:
    """A brushed, slightly coloured dielectric: Lambert base plus an anisotropic GGX lobe."""
    return LobeSum(
        (Lambert((0.35, 0.25, 0.15)), GGX(alpha_x=0.15, alpha_y=0.45)),
        name=DEFAULT_MATERIAL_NAME,
    )


def resolve_material(material: str | os.PathLike[str] | BRDFLike | None) -> BRDFLike:
    """The specimen's BRDF from a model object, a table file (``.npz``) or a library name.

    Raises
    ------
    ValueError
        The file is not a BRDF table or the name is not in :mod:`gonio.brdf.materials.library`.
    """
    if material is None:
        return default_material()
    if not isinstance(material, (str, os.PathLike)):
        return material  # a model or table object: anything with eval(wi, wo)
    text = os.fspath(material)
    if text.endswith(".npz") or Path(text).is_file():
        return BRDFTable.load(text)
    if text == DEFAULT_MATERIAL_NAME:  # the name the page and the results give the default
        return default_material()
    from gonio.sim.spectral import SPECTRAL_MATERIALS, spectral_specimen

    if text in SPECTRAL_MATERIALS:  # read by a 31-band spectrometer (docs/colour.md)
        return spectral_specimen(text)
    # An unknown name raises the library's own ValueError, which suggests close names; a
    # misspelt spectral material ("metalic-blue-paint") was answered with the library's
    # families alone, so the error names the spectral materials too.
    try:
        return library.get_material(text)
    except library.LibraryError as exc:
        import difflib

        close = difflib.get_close_matches(text, SPECTRAL_MATERIALS, n=1)
        hint = f"did you mean {close[0]}? " if close else ""
        raise library.LibraryError(
            f"{exc}; {hint}spectral materials (read by 31-band sensors, docs/colour.md): "
            f"{', '.join(SPECTRAL_MATERIALS)}") from None


@dataclass
class SimRigOptions:
    """What to simulate.

    Attributes
    ----------
    stage : {"dynamixel", "zaber"}
    zaber_transport : {"pty", "tcp"}
    material : model object, ``.npz`` table path, library name, or None (default material)
    noise : NoiseModel, or None for noiseless sensors (still quantised and clipped)
    time_scale : float
        Sim seconds per wall second for stage motion and exposures.
    faults : sequence of str
        Faults active from the start (see ``FAULT_HELP``).
    lights, sensors : sequences of (theta_deg, phi_deg)
        Lab directions of the lamps and sensors.
    light_names, sensor_names : sequences of str, or None
        Device names (default ``L1, L2, ...`` and ``S1, S2, ...``).
    pairs : sequence of (light, sensor) names, or None
        The measured pairs written to the rig config (None: ``pairs = "all"``).
    irradiance : float
        Per lamp at full level, counts per (1/sr) per second at gain 1.
    seed : int
        Seeds the sensor noise.
    speed_dps, accel_dps2, settle_s : stage physics
    stage_gear : float
        Motor turns per stage turn of the simulated Dynamixel (1: direct drive); a geared
        servo loses whole motor turns (``360 / gear`` stage degrees) at a power cycle.
    stage_eeprom : path or None
        Where the simulated Dynamixel keeps its EEPROM (the Homing Offset: the stage's zero)
        across restarts, as a real servo does (:class:`gonio.sim.dynamixel_device.XSeriesServo`);
        None: factory values at each start. ``gonio serve --sim`` keeps it in its data
        directory.
    lamp_watchdog_s : float or None
        Communication watchdog timeout the rig config asks the lamp controllers for, wall
        seconds (None: the config maps no watchdog, the lamps stay as the last request left
        them, as on controllers without one).
    name : rig name in the config
    config_path : where to write the rig config (None: not written)
    modbus_port : TCP port of the simulated Modbus bus on 127.0.0.1 (0: any free one; choose
        one on a shared lab machine whose firewall allows only known ports)
    """

    stage: Literal["dynamixel", "zaber"] = "dynamixel"
    zaber_transport: Literal["pty", "tcp"] = "pty"
    material: Any = None
    noise: NoiseModel | None = field(default_factory=lambda: NoiseModel(saturation=ADC_FULL_SCALE))
    time_scale: float = 1.0
    faults: Sequence[str] = ()
    lights: Sequence[tuple[float, float]] = DEFAULT_LIGHTS
    sensors: Sequence[tuple[float, float]] = DEFAULT_SENSORS
    light_names: Sequence[str] | None = None
    sensor_names: Sequence[str] | None = None
    pairs: Sequence[tuple[str, str]] | None = None
    irradiance: float = 2.0e7
    seed: int = 0
    speed_dps: float = 60.0
    accel_dps2: float = 240.0
    settle_s: float = 0.02
    lamp_watchdog_s: float | None = 2.0
    name: str = "sim"
    config_path: str | os.PathLike[str] | None = None
    modbus_port: int = 0
    stage_eeprom: str | os.PathLike[str] | None = None
    stage_gear: float = 1.0

    def check(self) -> None:
        """``ValueError`` with a clear message for an impossible option."""
        if self.stage not in ("dynamixel", "zaber"):
            raise ValueError(f"stage {self.stage!r}: use 'dynamixel' or 'zaber'")
        if self.zaber_transport not in ("pty", "tcp"):
            raise ValueError(f"zaber transport {self.zaber_transport!r}: use 'pty' or 'tcp'")
        if not self.time_scale > 0:
            raise ValueError(f"time scale must be > 0, got {self.time_scale}")
        if not (math.isfinite(self.stage_gear) and self.stage_gear > 0):
            raise ValueError(f"stage gear must be a positive number of motor turns per stage "
                             f"turn, got {self.stage_gear}")
        if not 0 <= self.modbus_port <= 65535:
            raise ValueError(f"Modbus port {self.modbus_port}: use 1 to 65535, or 0 for any "
                             "free port")
        if not self.irradiance > 0:
            raise ValueError(f"irradiance must be > 0, got {self.irradiance}")
        if self.lamp_watchdog_s is not None and not 0.001 <= self.lamp_watchdog_s <= 65.0:
            raise ValueError(f"lamp watchdog must be 0.001 to 65 s (a u16 of milliseconds), "
                             f"got {self.lamp_watchdog_s}")
        if not self.lights or not self.sensors:
            raise ValueError("a simulated rig needs at least one light and one sensor")
        for kind, dirs in (("light", self.lights), ("sensor", self.sensors)):
            for theta, _phi in dirs:
                if not 0.0 <= theta < 90.0:
                    raise ValueError(
                        f"{kind} at theta {theta} deg: must be in [0, 90) (above the specimen)"
                    )
        if len(self.lights) + len(self.sensors) > HOLDER_DEVICE_ID - 1:
            raise ValueError(f"at most {HOLDER_DEVICE_ID - 1} simulated Modbus devices (one "
                             "device id each)")
        for kind, names, dirs in (("light", self.light_names, self.lights),
                                  ("sensor", self.sensor_names, self.sensors)):
            if names is not None and len(names) != len(dirs):
                raise ValueError(f"{len(names)} {kind} names for {len(dirs)} {kind}s")


def _light_registers(watchdog: bool = True) -> LightRegisters:
    return LightRegisters(
        on_coil=0,
        level=Register(table="holding", address=0, type="u16", scale=0.001),
        monitor=Register(table="input", address=0, type="u16", scale=0.001),
        band=0.05,
        # Communication watchdog timeout in milliseconds (0 = off).
        watchdog=(Register(table="holding", address=1, type="u16", scale=0.001)
                  if watchdog else None),
    )


def _sensor_registers(n_channels: int) -> SensorRegisters:
    # 32-bit counts with the low word first, as on many ADC modules: exercises word order.
    values = [
        Register(table="input", address=2 * k, type="u32", word_order="little")
        for k in range(n_channels)
    ]
    return SensorRegisters(
        values=values,
        exposure=Register(table="holding", address=0, type="u32", scale=1e-6),
        gain=Register(table="holding", address=2, type="f32"),
        trigger=Register(table="holding", address=4, type="u16"),
        sequence=Register(table="input", address=100, type="u16"),
    )


class SimRig:
    """A running simulated rig; build it with :func:`start_sim_rig`.

    Attributes
    ----------
    config : RigConfig
        Points at the simulators; give it to :func:`gonio.drivers.factory.build_rig`.
    config_path : Path or None
    motion : StageMotion
    stage_faults : FaultPlan
    modbus : ModbusRigServer
    specimen : Specimen
    noise : NoiseModel
    irradiance : dict of light name -> irradiance at full level
    """

    def __init__(self, options: SimRigOptions) -> None:
        options.check()
        self.options = options
        self._specimen_lock = threading.Lock()
        self.specimen = Specimen(resolve_material(options.material))
        self.noise = options.noise or NoiseModel.noiseless(ADC_FULL_SCALE)
        self.motion = StageMotion(
            speed_dps=options.speed_dps,
            accel_dps2=options.accel_dps2,
            settle_s=options.settle_s,
            time_scale=options.time_scale,
        )
        self.stage_faults = FaultPlan()
        self.stage_handle: Any = None
        self.modbus: ModbusRigServer | None = None
        self.config_path: Path | None = None
        channels = list(
            getattr(self.specimen.brdf, "channels", None)
            or [f"C{k}" for k in range(self.specimen.n_channels)]
        )
        self.light_names = list(options.light_names or
                                [f"L{k + 1}" for k in range(len(options.lights))])
        self.sensor_names = list(options.sensor_names or
                                 [f"S{k + 1}" for k in range(len(options.sensors))])
        # What is on the stage: the specimen, or the white reference for a calibration. The
        # specimen's BRDF is kept while the reference is on, to put it back.
        self.on_stage = ON_STAGE_SPECIMEN
        self.reference_albedo = WHITE_REFERENCE_ALBEDO
        self._specimen_brdf: BRDFLike = self.specimen.brdf
        self.irradiance = dict.fromkeys(self.light_names, options.irradiance)
        try:
            self._start_stage()
            self._start_modbus()
            self.config = self._build_config(channels)
            if options.config_path is not None:
                self.config_path = dump_rig_config(self.config, options.config_path,
                                                   header=SIM_CONFIG_HEADER)
            for spec in options.faults:
                self.apply_fault(spec)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ start-up
    def _start_stage(self) -> None:
        if self.options.stage == "dynamixel":
            from gonio.sim.dynamixel_device import start_dynamixel_sim

            self.stage_handle = start_dynamixel_sim(
                self.motion, dxl_id=1, counts_per_degree=4096 / 360.0 * self.options.stage_gear,
                faults=self.stage_faults,
                eeprom_file=self.options.stage_eeprom,
            )
            self._stage_port = str(self.stage_handle.port)
        else:
            from gonio.sim.zaber_device import DEFAULT_MICROSTEPS_PER_DEGREE, start_zaber_sim

            self._microsteps = DEFAULT_MICROSTEPS_PER_DEGREE
            self.stage_handle = start_zaber_sim(
                self.motion,
                transport=self.options.zaber_transport,
                microsteps_per_degree=self._microsteps,
                device=1,
                faults=self.stage_faults,
            )
            self._stage_port = str(self.stage_handle.url)

    def _start_modbus(self) -> None:
        o = self.options
        lamps = [
            SimLampSpec(
                name, k + 1, _light_registers(), LabDirection(*d).vector(), self.irradiance[name]
            )
            for k, (name, d) in enumerate(zip(self.light_names, o.lights, strict=True))
        ]
        first = len(lamps) + 1
        sensors = [
            SimSensorSpec(
                name,
                first + k,
                _sensor_registers(self.specimen.n_channels),
                LabDirection(*d).vector(),
                self.noise,
            )
            for k, (name, d) in enumerate(zip(self.sensor_names, o.sensors, strict=True))
        ]
        self.modbus = ModbusRigServer(
            self.specimen, self.motion, lamps, sensors, time_scale=o.time_scale, seed=o.seed,
            holder=SimHolderSpec(HOLDER_DEVICE_ID, self._holder_state, self._holder_load),
            port=o.modbus_port,
        ).start()

    def _build_config(self, channels: list[str]) -> RigConfig:
        o = self.options
        assert self.modbus is not None

        def transport(device_id: int) -> ModbusTransport:
            return ModbusTransport(
                host=self.modbus.host if self.modbus else "127.0.0.1",
                port=self.modbus.port if self.modbus else 502,
                device_id=device_id,
                timeout_s=0.5,
            )

        if o.stage == "dynamixel":
            stage = StageConfig(
                driver="dynamixel",
                port=self._stage_port,
                baudrate=57600,
                # The simulator answers from a Python thread: on a saturated machine that can
                # take longer than the SDK's 35 ms (SIM_REPLY_TIMEOUT_S).
                dynamixel=DynamixelSettings(reply_timeout_s=SIM_REPLY_TIMEOUT_S),
                counts_per_rev=4096,
                gear_ratio=o.stage_gear,
                speed_dps=o.speed_dps,
                accel_dps2=o.accel_dps2,
                approach="none",
                min_deg=-360.0,
                max_deg=720.0,
                move_timeout_s=60.0,
            )
        else:
            stage = StageConfig(
                driver="zaber",
                port=self._stage_port,
                baudrate=115200,
                microsteps_per_degree=self._microsteps,
                speed_dps=o.speed_dps,
                accel_dps2=o.accel_dps2,
                approach="none",
                min_deg=-360.0,
                max_deg=720.0,
                move_timeout_s=60.0,
            )
        lights = [
            LightConfig(
                name=name,
                theta_deg=d[0],
                phi_deg=d[1],
                modbus=transport(k + 1),
                registers=_light_registers(watchdog=o.lamp_watchdog_s is not None),
                watchdog_s=o.lamp_watchdog_s or 2.0,
            )
            for k, (name, d) in enumerate(zip(self.light_names, o.lights, strict=True))
        ]
        first = len(lights) + 1
        # A spectral specimen is read by spectral sensors: their bands go in the config.
        bands = getattr(self.specimen.brdf, "bands", None)
        spectral: dict[str, Any] = {} if bands is None else {
            "wavelengths_nm": list(bands.centres_nm), "bandwidths_nm": list(bands.widths_nm)}
        sensors = [
            SensorConfig(
                name=name,
                theta_deg=d[0],
                phi_deg=d[1],
                modbus=transport(first + k),
                channels=channels,
                registers=_sensor_registers(len(channels)),
                saturation_raw=self.noise.saturation,
                gain=1.0,
                gain_stages=list(SENSOR_GAIN_STAGES),
                min_exposure_s=1e-4,
                max_exposure_s=5.0,
                **spectral,
            )
            for k, (name, d) in enumerate(zip(self.sensor_names, o.sensors, strict=True))
        ]
        pairs: Any = "all" if o.pairs is None else [
            PairConfig(light=a, sensor=b) for a, b in o.pairs
        ]
        return RigConfig(
            rig=RigSection(name=o.name), stage=stage, lights=lights, sensors=sensors, pairs=pairs
        )

    # ------------------------------------------------------------------ faults
    def _power_cycle_stage(self, off_s: float) -> None:
        """The Dynamixel loses power for ``off_s`` wall seconds: it answers nothing, then
        powers up as after a reboot (torque and LED off, whole motor turns forgotten; its
        EEPROM, the Homing Offset with it, kept)."""
        if self.options.stage != "dynamixel":
            raise ValueError("stage-power-cycle is simulated for the dynamixel stage only")
        if not (math.isfinite(off_s) and 0 <= off_s <= 3600):
            raise ValueError(f"stage-power-cycle: off for 0 to 3600 s, got {off_s}")
        handle = self.stage_handle
        self.stage_faults.set(silent=True)

        def power_up() -> None:
            handle.servo.reboot()
            self.stage_faults.set(silent=False)

        timer = threading.Timer(off_s, power_up)
        timer.daemon = True
        timer.start()

    def apply_fault(self, spec: str) -> None:
        """Inject a fault given as text (see ``FAULT_HELP``), e.g. ``"silence:S2:1.5"``.

        Raises
        ------
        ValueError
            Unknown fault or device name, or a bad number.
        """
        assert self.modbus is not None
        kind, _, rest = spec.partition(":")
        args = rest.split(":") if rest else []
        try:
            if kind == "silence" and len(args) in (1, 2):
                self.modbus.silence(args[0], float(args[1]) if len(args) == 2 else None)
            elif kind == "lamp-drift" and len(args) == 2:
                self.modbus.set_lamp_output(args[0], float(args[1]))
            elif kind == "saturate" and len(args) == 1:
                self.modbus.force_saturation(args[0])
            elif kind == "stage-silent" and not args:
                self.stage_faults.set(silent=True)
            elif kind == "stage-overload" and not args:
                self.stage_faults.set(overload_next_move=True)
            elif kind == "stage-stall" and not args:
                self.stage_faults.set(stall_next_move=True)
            elif kind == "stage-power-cycle" and len(args) <= 1:
                self._power_cycle_stage(float(args[0]) if args else 1.0)
            else:
                raise ValueError(f"fault {spec!r} is not understood; faults are: {FAULT_HELP}")
        except KeyError as exc:
            raise ValueError(f"fault {spec!r}: {exc.args[0]}") from None
        except ValueError as exc:
            if "not understood" in str(exc):
                raise
            raise ValueError(f"fault {spec!r}: {exc}; faults are: {FAULT_HELP}") from None

    def clear_faults(self) -> None:
        """Healthy devices again (a tripped stage still needs the driver's recovery)."""
        if self.modbus is not None:
            self.modbus.clear_faults()
        self.stage_faults.clear()

    # ------------------------------------------------------------------ specimen
    def place_specimen(self, material: str | os.PathLike[str] | BRDFLike | None) -> Specimen:
        """Put another specimen on the stage, while the rig runs (thread-safe).

        Readings triggered after this call see the new BRDF; a reading in progress keeps the
        one it started with (each exposure evaluates the specimen once).

        Parameters
        ----------
        material : as :attr:`SimRigOptions.material` (model, ``.npz`` table, library name,
            None for the default material)

        Returns
        -------
        Specimen
            The specimen that was on the stage before (give its ``brdf`` back to restore it).

        Raises
        ------
        ValueError
            The material is unknown, or has a different number of channels than the rig's
            sensors report.
        """
        new = Specimen(resolve_material(material))
        with self._specimen_lock:
            old = self.specimen
            if new.n_channels != old.n_channels:
                raise ValueError(
                    f"the new specimen has {new.n_channels} channels, the simulated sensors "
                    f"report {old.n_channels}; use a material with {old.n_channels} channels"
                )
            # One attribute assignment each: the Modbus thread sees the old or the new specimen,
            # never a mix.
            self.specimen = new
            if self.modbus is not None:
                self.modbus.specimen = new
            if not isinstance(new.brdf, _WhiteReference):
                self._specimen_brdf = new.brdf
                self.on_stage = ON_STAGE_SPECIMEN
        return old

    def place_white_reference(self, albedo: float = WHITE_REFERENCE_ALBEDO) -> Specimen:
        """Put a Lambertian white reference of ``albedo`` on the stage (for calibration).

        Returns the specimen that was on the stage before, as :meth:`place_specimen`.
        """
        channels = list(
            getattr(self.specimen.brdf, "channels", None)
            or [f"C{k}" for k in range(self.specimen.n_channels)]
        )
        old = self.place_specimen(_WhiteReference(white_reference(albedo, channels)))
        self.on_stage = ON_STAGE_WHITE
        self.reference_albedo = albedo
        return old

    def load(self, what: str, albedo: float = WHITE_REFERENCE_ALBEDO) -> str:
        """Put the white reference (``what = "white"``) or the rig's specimen back
        (``"specimen"``) on the stage; returns a sentence saying what is there now.

        The specimen is the last one placed with :meth:`place_specimen` (or the rig's
        material), kept while the reference is on the stage.

        Raises
        ------
        ValueError
            Unknown ``what`` or an albedo outside (0, 1].
        """
        if what in ("white", "white-reference", ON_STAGE_WHITE):
            self.place_white_reference(albedo)
        elif what == ON_STAGE_SPECIMEN:
            self.place_specimen(self._specimen_brdf)
        else:
            raise ValueError(f"cannot put {what!r} on the stage; use 'white' or 'specimen'")
        return self.describe_stage()

    def describe_stage(self) -> str:
        """What the simulated stage holds, as a sentence."""
        if self.on_stage == ON_STAGE_WHITE:
            return f"the white reference (albedo {self.reference_albedo:g})"
        name = getattr(self._specimen_brdf, "name", None) or "the specimen"
        return f"the specimen ({name})"

    def _holder_state(self) -> tuple[int, float]:
        return (1 if self.on_stage == ON_STAGE_WHITE else 0), self.reference_albedo

    def _holder_load(self, code: int, albedo: float) -> None:
        self.load("white" if code == 1 else ON_STAGE_SPECIMEN, albedo)

    # ------------------------------------------------------------------ ground truth
    def true_brdf(self, light: str, sensor: str, stage_deg: float) -> np.ndarray:
        """The specimen's BRDF (C,) in 1/sr seen by a pair at a stage angle (for checks)."""
        wi = np.asarray(self.config.light(light).direction.vector())
        wo = np.asarray(self.config.sensor(sensor).direction.vector())
        return self.specimen.brdf_lab(wi, wo, stage_deg)

    def expected_counts_per_brdf(
        self, light: str, sensor: str, exposure_s: float, level: float = 1.0, gain: float = 1.0
    ) -> float:
        """Dark-subtracted counts per unit BRDF for a pair: ``E level cos(ti) gain t``."""
        theta = self.config.light(light).theta_deg
        return self.irradiance[light] * level * math.cos(math.radians(theta)) * gain * exposure_s

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Stop every simulator; safe to call twice."""
        if self.modbus is not None:
            self.modbus.close()
            self.modbus = None
        if self.stage_handle is not None:
            self.stage_handle.close()
            self.stage_handle = None

    def __enter__(self) -> SimRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_sim_rig(options: SimRigOptions | None = None) -> SimRig:
    """Start a simulated rig (see :class:`SimRigOptions`); close it with ``SimRig.close()``."""
    return SimRig(options or SimRigOptions())


async def start_sim_rig_async(options: SimRigOptions | None = None) -> SimRig:
    """:func:`start_sim_rig` without blocking the running event loop during start-up."""
    return await asyncio.to_thread(start_sim_rig, options)
