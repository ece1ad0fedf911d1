"""The rig configuration: a TOML file describing the stage, lights, sensors and pairs.

The file is read with :mod:`tomllib`, validated with pydantic and written back with ``tomli_w``.
Every validation problem becomes one :class:`ConfigError` whose message names the file, the key
path and what is allowed, e.g. ``rig.toml: stage.driver: 'dynamxel' is not one of 'dynamixel',
'zaber'``. The full reference of keys is ``docs/rig-config.md``; ``deploy/rig.example.toml`` is a
complete, loadable example.

Angles are degrees (they are typed by people); Modbus addresses are the zero-based addresses
sent on the wire (a vendor manual's "register 40001" is holding register 0).
"""

from __future__ import annotations

import itertools
import os
import tomllib
import types
import typing
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import tomli_w
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from gonio.hal import LabDirection, PairSpec
from gonio.motion import Approach

if TYPE_CHECKING:
    # At run time only pair_directions needs NumPy (imported there): reading a config, as
    # the daemon does for its own, does not load it.
    import numpy as np
    from numpy.typing import NDArray

__all__ = [
    "CalibrationConfig",
    "ConfigError",
    "DataType",
    "DesignExpectation",
    "LightConfig",
    "LightRegisters",
    "ModbusTransport",
    "PairConfig",
    "PairDirections",
    "PairFactor",
    "Register",
    "RigConfig",
    "SensorConfig",
    "SensorRegisters",
    "StageConfig",
    "dump_rig_config",
    "load_rig_config",
    "parse_rig_config",
    "read_toml",
    "register_width",
]


class ConfigError(ValueError):
    """The rig configuration is unreadable or invalid; the message says where and what to do."""


DataType = Literal["u16", "s16", "u32", "s32", "f32"]
WordOrder = Literal["big", "little"]
RegisterTable = Literal["holding", "input"]

_WIDTH: dict[str, int] = {"u16": 1, "s16": 1, "u32": 2, "s32": 2, "f32": 2}


def register_width(data_type: DataType) -> int:
    """Number of 16-bit registers a value of ``data_type`` occupies (1 or 2)."""
    return _WIDTH[data_type]


def _takes_numbers(annotation: Any) -> bool:
    """Whether a field's type is a number (bool, int, float), optionally ``| None`` or a
    list/tuple of numbers: the values TOML writes without quotes."""
    if annotation in (bool, int, float):
        return True
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    origin = typing.get_origin(annotation)
    if origin is Annotated:
        return _takes_numbers(args[0])
    if origin in (list, tuple, types.UnionType, typing.Union):
        return bool(args) and all(a is Ellipsis or _takes_numbers(a) for a in args)
    if origin is dict and len(args) == 2:
        return _takes_numbers(args[1])  # e.g. [calibration] dark = {S1 = [0.1, ...]}
    return False


def _first_text(value: Any, where: str = "") -> tuple[str, str] | None:
    """The first string inside ``value`` (a scalar, list or table) and where it sits within
    it (``""``, ``"[1]"``, ``"S1[0]"``), or None when it holds none."""
    if isinstance(value, str):
        return where, value
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, list | tuple) else ())
    for key, item in items:
        sub = f"{where}.{key}" if isinstance(key, str) else f"{where}[{key}]"
        found = _first_text(item, sub)
        if found is not None:
            return found
    return None


class NumbersNotText(BaseModel):
    """A config section where a number (or true/false) written as text is an error
    (``theta_deg = "45"``, ``port = "8600"``), which pydantic would read as the value: a
    quoted value is a hand edit or a generator's bug, and the file would not say what it
    seems to. The rig config's sections and the daemon config's share it."""

    @field_validator("*", mode="before")
    @classmethod
    def _numbers_are_not_text(cls, value: Any, info: ValidationInfo) -> Any:
        field = cls.model_fields.get(info.field_name or "")
        found = _first_text(value)
        if field is not None and found is not None and _takes_numbers(field.annotation):
            where, text = found
            what = "true or false" if field.annotation is bool else "a number"
            at = f" at {where.lstrip('.')}" if where else ""
            raise ValueError(f"expected {what}{at}, got the text {text!r}: write it without "
                             "quotes")
        return value


class _Strict(NumbersNotText):
    """Base of all config sections: unknown keys are errors (they are almost always typos),
    and so is a number written as text (:class:`NumbersNotText`), and an infinite or
    not-a-number value (TOML has ``inf`` and ``nan``: ``speed_dps = inf`` passed "> 0" and was
    refused later by the driver without the file's name; ``move_timeout_s = inf`` was taken)."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True,
                              allow_inf_nan=False)


# --------------------------------------------------------------------------- stage
class DynamixelSettings(_Strict):
    """``[stage.dynamixel]``: the servo on the bus."""

    id: Annotated[int, Field(ge=0, le=252)] = 1
    # Longest wait for a status packet, seconds; None = the SDK's (about 35 ms). Raise it for a
    # slow adapter, a long bus, or a simulator on a busy machine.
    reply_timeout_s: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)] | None = None


class ZaberSettings(_Strict):
    """``[stage.zaber]``: device number in the daisy chain and axis."""

    device: Annotated[int, Field(ge=1, le=99)] = 1
    axis: Annotated[int, Field(ge=1, le=9)] = 1


class StageConfig(_Strict):
    """``[stage]``: the rotation stage under the specimen.

    ``gear_ratio`` is motor revolutions per stage revolution (1 for a direct drive).
    ``counts_per_rev`` (Dynamixel) is encoder counts per motor revolution;
    ``microsteps_per_degree`` (Zaber) is microsteps per degree of the motor axis.
    """

    driver: Literal["dynamixel", "zaber"]
    port: Annotated[str, Field(min_length=1)]
    baudrate: Annotated[int, Field(gt=0)] | None = None
    gear_ratio: Annotated[float, Field(gt=0)] = 1.0
    counts_per_rev: Annotated[int, Field(gt=0)] = 4096
    microsteps_per_degree: Annotated[float, Field(gt=0)] | None = None
    speed_dps: Annotated[float, Field(gt=0)] = 30.0
    accel_dps2: Annotated[float, Field(gt=0)] = 60.0
    # Seconds; a stage that needs more than a minute to settle is a unit typed as ms.
    settle_s: Annotated[float, Field(ge=0, le=60, allow_inf_nan=False)] = 0.0
    approach: Approach = "positive"
    backlash_deg: Annotated[float, Field(ge=0, le=10)] = 0.0
    min_deg: float = -360.0
    max_deg: float = 360.0
    move_timeout_s: Annotated[float, Field(gt=0)] = 60.0
    dynamixel: DynamixelSettings | None = None
    zaber: ZaberSettings | None = None

    @model_validator(mode="after")
    def _check(self) -> StageConfig:
        if self.min_deg >= self.max_deg:
            raise ValueError(f"min_deg ({self.min_deg}) must be below max_deg ({self.max_deg})")
        if self.driver == "zaber" and self.microsteps_per_degree is None:
            raise ValueError(
                "the zaber driver needs microsteps_per_degree (from the stage's datasheet: "
                "microsteps per degree of the motor axis)"
            )
        other = "zaber" if self.driver == "dynamixel" else "dynamixel"
        if getattr(self, other) is not None:
            raise ValueError(
                f"[stage.{other}] is given but stage.driver is {self.driver!r}; remove the "
                "table or change the driver"
            )
        return self

    @property
    def default_baudrate(self) -> int:
        """The configured baud rate, or the vendor default for the driver."""
        if self.baudrate is not None:
            return self.baudrate
        return 57600 if self.driver == "dynamixel" else 115200

    @property
    def counts_per_degree(self) -> float:
        """Dynamixel encoder counts per degree of stage rotation."""
        return self.counts_per_rev * self.gear_ratio / 360.0

    @property
    def microsteps_per_stage_degree(self) -> float:
        """Zaber microsteps per degree of stage rotation (0 when the driver is not zaber)."""
        return (self.microsteps_per_degree or 0.0) * self.gear_ratio


# --------------------------------------------------------------------------- modbus
class ModbusTransport(_Strict):
    """``[lights.modbus]`` / ``[sensors.modbus]``: where a Modbus TCP device answers."""

    host: Annotated[str, Field(min_length=1)]
    port: Annotated[int, Field(ge=1, le=65535)] = 502
    device_id: Annotated[int, Field(ge=0, le=247)] = 1
    timeout_s: Annotated[float, Field(gt=0, le=60)] = 1.0


class Register(_Strict):
    """One value in a device's register map.

    ``physical = raw * scale``. 32-bit types take two consecutive registers starting at
    ``address``; ``word_order = "big"`` puts the most significant word first.
    """

    table: RegisterTable = "holding"
    address: Annotated[int, Field(ge=0, le=65534)]
    type: DataType = "u16"
    word_order: WordOrder = "big"
    scale: float = 1.0

    @model_validator(mode="after")
    def _check(self) -> Register:
        if self.scale == 0:
            raise ValueError("scale must not be 0 (physical = raw * scale)")
        return self

    @property
    def width(self) -> int:
        """Registers occupied (1 or 2)."""
        return register_width(self.type)


class LightRegisters(_Strict):
    """``[lights.registers]``: how a light is switched, dimmed and monitored.

    ``on_coil`` is the coil that switches the light. ``level`` (holding) takes the drive level
    as a fraction in [0, 1] after scale. ``monitor`` (input, optional) reports the measured
    output as a fraction of full output; the light is out of band when it differs from the
    commanded level by more than ``band`` (absolute fraction).
    """

    on_coil: Annotated[int, Field(ge=0, le=65535)]
    level: Register | None = None
    monitor: Register | None = None
    band: Annotated[float, Field(gt=0, le=1)] = 0.05
    watchdog: Register | None = None
    """Holding register of the controller's communication watchdog: takes a timeout in seconds
    after scale; the controller switches its outputs off when no request has reached it for
    that long. The driver arms it at connect (with the light's ``watchdog_s``) and keeps it
    fed while the light is on, so a lamp never outlives the program that switched it on."""

    @model_validator(mode="after")
    def _check(self) -> LightRegisters:
        for key in ("level", "watchdog"):
            reg = getattr(self, key)
            if reg is not None and reg.table != "holding":
                raise ValueError(f"{key} must be a holding register (it is written)")
        return self


class SensorRegisters(_Strict):
    """``[sensors.registers]``: how a sensor is exposed, triggered and read.

    A reading is: write ``exposure`` (seconds after scale), note ``sequence``, write 1 to
    ``trigger``, wait until ``sequence`` changes, then read ``values`` (one register per
    channel, in the order of the sensor's ``channels``).
    """

    values: Annotated[list[Register], Field(min_length=1)]
    exposure: Register
    trigger: Register
    sequence: Register
    gain: Register | None = None

    @model_validator(mode="after")
    def _check(self) -> SensorRegisters:
        for key in ("exposure", "trigger"):
            if getattr(self, key).table != "holding":
                raise ValueError(f"{key} must be a holding register (it is written)")
        if self.gain is not None and self.gain.table != "holding":
            raise ValueError("gain must be a holding register (it is written)")
        return self


class _Device(_Strict):
    name: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")]
    theta_deg: Annotated[float, Field(ge=0, lt=90)]
    phi_deg: float
    modbus: ModbusTransport

    @property
    def direction(self) -> LabDirection:
        """Lab direction of the device as seen from the specimen centre."""
        return LabDirection(self.theta_deg, self.phi_deg)


class LightConfig(_Device):
    """One ``[[lights]]`` entry."""

    registers: LightRegisters
    level: Annotated[float, Field(gt=0, le=1)] = 1.0
    """Drive level written at connect, fraction."""
    warmup_s: Annotated[float, Field(ge=0, le=600)] = 0.0
    """Wait after switching on before the output is checked against its band, seconds."""
    watchdog_s: Annotated[float, Field(gt=0, le=600)] = 2.0
    """Communication watchdog timeout written to ``registers.watchdog`` (if mapped), seconds."""


class ColourCalibrationConfig(_Strict):
    """``[sensors.colour_calibration]``: a chart colour calibration of a non-spectral sensor.

    Written by ``gonio colour-chart CHART.csv`` (docs/colour.md): ``XYZ = matrix @ c`` for the
    sensor's reflectance factors ``c`` (one matrix column per channel; ``method =
    "root-polynomial"``: one column per term of the readings' degree-2 root-polynomial
    expansion, six for an RGB sensor), fitted for one illuminant and observer.
    """

    matrix: Annotated[list[list[float]], Field(min_length=3, max_length=3)]
    method: Literal["linear", "root-polynomial"] = "linear"
    illuminant: Literal["D65", "D50", "A", "C", "D55", "D75", "FL2", "FL11"] = "D65"
    observer: Literal["10", "2"] = "10"
    residual_median_de00: Annotated[float, Field(ge=0)] | None = None
    residual_max_de00: Annotated[float, Field(ge=0)] | None = None
    n_patches: Annotated[int, Field(ge=0)] = 0
    source: str = ""
    loo_median_de00: Annotated[float, Field(ge=0)] | None = None
    channels: list[Annotated[str, Field(min_length=1)]] | None = None
    """The channels the matrix was fitted for, in its order (written by ``gonio
    colour-chart``); when given, the sensor's ``channels`` must be the same, in the same order."""


class SensorConfig(_Device):
    """One ``[[sensors]]`` entry.

    ``saturation_raw`` is the raw register value at which a channel is saturated (for a 16-bit
    ADC typically 65535). ``gain`` is written to the gain register at connect when one is mapped.
    ``gain_stages`` are lower gains the sensor can be switched to (written to the same
    register), in descending order: a reading that saturates at ``gain`` is taken again at the
    next stage, and so on (auto-ranging, docs/engine.md). Give the stages' true gains (the
    ratios to ``gain`` scale the readings back): nominal values when the amplifier's are
    trimmed, measured ones otherwise.
    """

    channels: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]
    registers: SensorRegisters
    saturation_raw: Annotated[float, Field(gt=0)]
    gain: Annotated[float, Field(gt=0)] = 1.0
    gain_stages: list[Annotated[float, Field(gt=0)]] = Field(default_factory=list)
    min_exposure_s: Annotated[float, Field(gt=0)] = 1e-4
    max_exposure_s: Annotated[float, Field(gt=0)] = 10.0
    # Colour (docs/colour.md): a spectral sensor's bands, or an RGB sensor's chart calibration.
    wavelengths_nm: list[Annotated[float, Field(gt=0, lt=5000)]] | None = None
    """Band centre of each channel, nm (a spectral sensor)."""
    bandwidths_nm: list[Annotated[float, Field(gt=0, lt=2000)]] | None = None
    """Full width at half maximum of each band, nm (default: the spacing of the centres)."""
    response_nm: list[Annotated[float, Field(gt=0, lt=5000)]] | None = None
    """Wavelengths of a measured response table, nm, increasing (replaces the Gaussian bands)."""
    responses: list[list[Annotated[float, Field(ge=0)]]] | None = None
    """Relative response of each channel at ``response_nm``: one row per channel."""
    colour_calibration: ColourCalibrationConfig | None = None

    @model_validator(mode="after")
    def _check_colour(self) -> SensorConfig:
        n = len(self.channels)
        for key in ("wavelengths_nm", "bandwidths_nm", "responses"):
            v = getattr(self, key)
            if v is not None and len(v) != n:
                raise ValueError(f"{key} has {len(v)} entries for {n} channels {self.channels}; "
                                 "give one per channel")
        if (self.bandwidths_nm or self.responses is not None) and self.wavelengths_nm is None:
            raise ValueError("bandwidths_nm and responses describe spectral bands: give "
                             "wavelengths_nm (each channel's band centre) too")
        if (self.responses is None) != (self.response_nm is None):
            raise ValueError("a response table needs both response_nm and responses")
        if self.response_nm is not None:
            if any(b <= a for a, b in zip(self.response_nm, self.response_nm[1:], strict=False)):
                raise ValueError("response_nm must increase")
            for row in self.responses or []:
                if len(row) != len(self.response_nm):
                    raise ValueError(f"each responses row needs {len(self.response_nm)} values "
                                     "(one per response_nm)")
                if not any(x > 0 for x in row):
                    raise ValueError("a responses row is all zero: every channel must respond "
                                     "somewhere")
        cal = self.colour_calibration
        if cal is not None:
            if cal.channels is not None and cal.channels != self.channels:
                # The matrix's columns are the chart's channels in the chart's order: under a
                # sensor of other names or order it would mix the wrong channels, silently.
                raise ValueError(
                    f"colour_calibration was fitted for channels {cal.channels}, the sensor's "
                    f"are {self.channels}; fit it again with gonio colour-chart CHART.csv "
                    f"--channels {','.join(self.channels)}")
            if self.wavelengths_nm is not None:
                raise ValueError("a spectral sensor (wavelengths_nm) gets its colour from its "
                                 "bands; drop colour_calibration or wavelengths_nm")
            if cal.method == "root-polynomial":
                if n != 3 or any(len(row) != 6 for row in cal.matrix):
                    raise ValueError(
                        "a root-polynomial colour_calibration needs a sensor of 3 channels and "
                        f"3 rows of 6 numbers (one per term; sensor channels {self.channels}); "
                        "fit it with gonio colour-chart")
            elif any(len(row) != n for row in cal.matrix):
                raise ValueError(f"colour_calibration.matrix needs 3 rows of {n} numbers (one "
                                 f"per channel {self.channels}); fit it with gonio colour-chart")
        return self

    @model_validator(mode="after")
    def _check(self) -> SensorConfig:
        if len(self.registers.values) != len(self.channels):
            raise ValueError(
                f"registers.values has {len(self.registers.values)} entries for "
                f"{len(self.channels)} channels {self.channels}; give one register per channel"
            )
        if len(set(self.channels)) != len(self.channels):
            raise ValueError(f"channel names repeat: {self.channels}")
        if self.min_exposure_s > self.max_exposure_s:
            raise ValueError(
                f"min_exposure_s ({self.min_exposure_s}) is above max_exposure_s "
                f"({self.max_exposure_s})"
            )
        if self.gain_stages:
            if self.registers.gain is None:
                raise ValueError(
                    "gain_stages need a gain register to switch to them: map "
                    "registers.gain, or remove gain_stages"
                )
            gains = [self.gain, *self.gain_stages]
            if any(b >= a for a, b in itertools.pairwise(gains)):
                raise ValueError(
                    f"gain_stages {self.gain_stages} must each be below the one before, "
                    f"starting below gain ({self.gain}): list the lower gains in descending "
                    "order"
                )
        return self

    @property
    def ranges(self) -> tuple[float, ...]:
        """Sensitivity of each range relative to range 0 (``gain``): 1, then each stage's."""
        return (1.0, *(g / self.gain for g in self.gain_stages))

    def range_gain(self, index: int) -> float:
        """The gain written to the gain register for range ``index`` (0: ``gain``)."""
        return self.gain if index == 0 else self.gain_stages[index - 1]


class PairConfig(_Strict):
    """One ``[[pairs]]`` entry: a light and a sensor measured together, by name.

    The file's form of a pair (unknown keys are refused, names are checked against the file's
    devices); :meth:`RigConfig.pair_list` turns the entries into :class:`gonio.hal.PairSpec`.
    """

    light: str
    sensor: str


class PairFactor(_Strict):
    """Per-pair calibration: BRDF (1/sr) per dark-subtracted sensor unit, one per channel."""

    light: str
    sensor: str
    factor: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=1)]


class CalibrationConfig(_Strict):
    """``[calibration]``: optional, known from a white-reference measurement.

    ``white_albedo`` is the hemispherical reflectance of the white reference (e.g. 0.99 for
    Spectralon). ``dark`` maps a sensor name to its per-channel dark level in sensor units.
    """

    white_albedo: Annotated[float, Field(gt=0, le=1)] = 0.99
    factors: list[PairFactor] = Field(default_factory=list)
    dark: dict[str, list[float]] = Field(default_factory=dict)


#: The instruments a colour design may name, as ``gonio.brdf.colour.instruments.INSTRUMENTS``
#: names them (case, spaces and dashes ignored when read). Repeated because the drivers read
#: this module and may not import the numerical core; tests/unit/test_designgap.py keeps the
#: two in agreement.
COLOUR_INSTRUMENTS: tuple[str, ...] = ("MA68", "MA98", "BYK-mac", "MultiFX10")


class DesignExpectation(_Strict):
    """``[design]``: what the design this geometry came from expects of a scan.

    Written by ``gonio design -o`` into its fragment and carried into the rig config by ``gonio
    rig apply-design``; a finished scan compares its ``predicted_log_rmse`` with
    ``expected_log_rmse`` (:mod:`gonio.designgap`, docs/science.md 7.1). The other keys say
    what that number assumes.

    Attributes
    ----------
    expected_log_rmse : the mean ``log_rmse`` of the design's simulated scans over materials
        held out of the basis (the number a scan's ``predicted_log_rmse`` estimates)
    expected_log_rmse_measured, expected_log_rmse_synthetic : the same mean over the panel's
        measured and synthetic materials
    inside_basis_log_rmse : the joint fit's expected error on the basis' own materials (a best
        case, not comparable with a scan's estimate), when the design had it
    rotations : uniform stage angles of the simulated scans
    span_deg : the arc they covered, degrees (180 or 360)
    noise : relative reading noise of the simulated scans (0.01: 1 %)
    pairs : light/sensor pairs of the design
    calibrated : the simulated scans were in 1/sr (a calibrated rig)
    materials : which materials the mean is over, in words
    colour_instrument : the multi-angle instrument the design was made for (``gonio design
        --colour``, docs/colour.md "Designing for colour"), its known name; a scan of the rig
        then reports colour at its geometries too
    colour_weight : the colour design's weight of the instrument's geometries

    ``expected_log_rmse`` may be missing (a design made without the held-out error, e.g. through
    the API or with ``--no-expected-error``): the table then only records the colour design,
    and a scan is not compared with it. A record with neither ``expected_log_rmse`` nor
    ``colour_instrument`` is refused: it would load and do nothing.
    """

    expected_log_rmse: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    expected_log_rmse_measured: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    expected_log_rmse_synthetic: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    inside_basis_log_rmse: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    rotations: Annotated[int, Field(ge=1)]
    span_deg: float = 180.0
    noise: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)] = 0.01
    pairs: Annotated[int, Field(ge=1)]
    calibrated: bool = True
    materials: str = ("held out of the basis: the shipped measured materials and one synthetic "
                      "of each library family")
    colour_instrument: str | None = None
    # le: gonio.brdf.design.colourtargets.MAX_COLOUR_WEIGHT (this layer may not import it)
    colour_weight: Annotated[float, Field(ge=0, le=1000, allow_inf_nan=False)] | None = None
    #: ``gonio design --render-mix``: the share of the renderings' cell weighting (a record)
    render_mix: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] | None = None

    @field_validator("span_deg")
    @classmethod
    def _span(cls, v: float) -> float:
        if v not in (180.0, 360.0):
            raise ValueError(f"span_deg is the arc of the design's stage angles: 180 or 360 "
                             f"degrees, got {v:g}")
        return v

    @field_validator("colour_instrument")
    @classmethod
    def _instrument(cls, v: str | None) -> str | None:
        if v is None:
            return None
        key = "".join(ch for ch in v.lower() if ch.isalnum())
        for known in COLOUR_INSTRUMENTS:
            if "".join(ch for ch in known.lower() if ch.isalnum()) == key:
                return known
        raise ValueError(f"colour_instrument: unknown instrument {v!r}; known instruments are "
                         f"{', '.join(COLOUR_INSTRUMENTS)} (the instrument 'gonio design "
                         "--colour' designed for)")

    @model_validator(mode="after")
    def _colour_pair(self) -> DesignExpectation:
        if self.colour_weight is not None and self.colour_instrument is None:
            raise ValueError("colour_weight is the weight of a colour design's instrument "
                             "geometries: give colour_instrument with it, or drop it")
        if (self.expected_log_rmse is None and self.colour_instrument is None
                and self.render_mix is None):
            # Neither a held-out error to compare a scan with nor a design choice to record
            # (colour, rendering weighting): the table would load and do nothing, so say
            # what it lacks.
            raise ValueError("a [design] record needs expected_log_rmse (the design's held-out "
                             "error, compared with every scan), colour_instrument (the "
                             "instrument 'gonio design --colour' designed for) or render_mix "
                             "('gonio design --render-mix'): add one of them, or drop the table")
        return self


class RigSection(_Strict):
    """``[rig]``."""

    name: Annotated[str, Field(min_length=1)]


class RigConfig(_Strict):
    """A whole rig configuration file, validated."""

    rig: RigSection
    stage: StageConfig
    lights: Annotated[list[LightConfig], Field(min_length=1)]
    sensors: Annotated[list[SensorConfig], Field(min_length=1)]
    pairs: Literal["all"] | list[PairConfig] = "all"
    calibration: CalibrationConfig | None = None
    design: DesignExpectation | None = None

    @model_validator(mode="after")
    def _check(self) -> RigConfig:
        errors: list[str] = []
        light_names = [x.name for x in self.lights]
        sensor_names = [x.name for x in self.sensors]
        both = light_names + sensor_names
        dup = sorted({n for n in both if both.count(n) > 1})
        if dup:
            entries = [f"lights[{k}]" for k, n in enumerate(light_names) if n in dup]
            entries += [f"sensors[{k}]" for k, n in enumerate(sensor_names) if n in dup]
            errors.append(
                f"device names must be unique across lights and sensors; repeated: {dup} "
                f"({', '.join(entries)}); give each device its own name"
            )
        # Two devices answering on the same host:port:device_id would read each other's registers.
        seen: dict[tuple[str, int, int], str] = {}
        for dev in [*self.lights, *self.sensors]:
            key = (dev.modbus.host, dev.modbus.port, dev.modbus.device_id)
            if key in seen:
                errors.append(
                    f"{dev.name} and {seen[key]} share Modbus {key[0]}:{key[1]} device_id "
                    f"{key[2]}; give each device its own device_id"
                )
            seen[key] = dev.name
        if isinstance(self.pairs, list):
            if not self.pairs:
                errors.append('pairs: empty list; list at least one pair or use pairs = "all"')
            for k, p in enumerate(self.pairs):
                errors.extend(_check_pair_names(f"pairs[{k}]", p.light, p.sensor, self))
            errors.extend(_repeated_pairs("pairs", self.pairs, "list each pair once"))
        if self.calibration is not None:
            for k, f in enumerate(self.calibration.factors):
                where = f"calibration.factors[{k}]"
                errors.extend(_check_pair_names(where, f.light, f.sensor, self))
                sensor = self.sensor(f.sensor) if f.sensor in sensor_names else None
                if sensor is not None and len(f.factor) != len(sensor.channels):
                    errors.append(
                        f"{where}.factor: {len(f.factor)} values for the "
                        f"{len(sensor.channels)} channels of {f.sensor}"
                    )
            errors.extend(_repeated_pairs(
                "calibration.factors", self.calibration.factors,
                "keep one factor per pair (the one from the latest calibration)",
            ))
            for name, levels in self.calibration.dark.items():
                if name not in sensor_names:
                    errors.append(
                        f"calibration.dark.{name}: no sensor named {name!r}; sensors are "
                        f"{_quoted(sensor_names)}"
                    )
                elif len(levels) != len(self.sensor(name).channels):
                    errors.append(
                        f"calibration.dark.{name}: {len(levels)} values for the "
                        f"{len(self.sensor(name).channels)} channels of {name}"
                    )
        if errors:
            raise ValueError("; ".join(errors))
        return self

    # ------------------------------------------------------------------ lookups
    def light(self, name: str) -> LightConfig:
        """The light called ``name``; ``KeyError`` when there is none."""
        for x in self.lights:
            if x.name == name:
                return x
        raise KeyError(name)

    def sensor(self, name: str) -> SensorConfig:
        """The sensor called ``name``; ``KeyError`` when there is none."""
        for x in self.sensors:
            if x.name == name:
                return x
        raise KeyError(name)

    def endpoints(self) -> list[str]:
        """Every device endpoint of the rig, once each: the stage port (serial device or
        pyserial URL) and each Modbus TCP ``tcp://host:port`` (devices behind one gateway share
        it). These are what one program at a time may own (:mod:`gonio.locks`)."""
        eps = [self.stage.port]
        eps += [f"tcp://{d.modbus.host}:{d.modbus.port}" for d in [*self.lights, *self.sensors]]
        return list(dict.fromkeys(eps))

    def pair_list(self) -> list[PairSpec]:
        """The measured pairs in order (every light with every sensor for ``"all"``)."""
        if self.pairs == "all":
            return [PairSpec(light=li.name, sensor=s.name) for li in self.lights
                    for s in self.sensors]
        return [PairSpec(light=p.light, sensor=p.sensor) for p in self.pairs]

    def pair_directions(self) -> list[PairDirections]:
        """Each measured pair with its light and sensor lab-frame unit vectors."""
        import numpy as np

        out = []
        for p in self.pair_list():
            wi = np.asarray(self.light(p.light).direction.vector(), dtype=float)
            wo = np.asarray(self.sensor(p.sensor).direction.vector(), dtype=float)
            out.append(PairDirections(p, wi, wo))
        return out


@dataclass(frozen=True)
class PairDirections:
    """A measured pair and its fixed lab-frame directions.

    Attributes
    ----------
    pair : PairSpec
    wi : (3,) array, unit vector from the specimen toward the light, lab frame
    wo : (3,) array, unit vector from the specimen toward the sensor, lab frame
    """

    pair: PairSpec
    wi: NDArray[np.float64]
    wo: NDArray[np.float64]


def _quoted(names: Sequence[str]) -> str:
    return ", ".join(repr(n) for n in names) if names else "(none)"


def _check_pair_names(where: str, light: str, sensor: str, cfg: RigConfig) -> list[str]:
    errors = []
    lights = [x.name for x in cfg.lights]
    sensors = [x.name for x in cfg.sensors]
    if light not in lights:
        errors.append(f"{where}.light: no light named {light!r}; lights are {_quoted(lights)}")
    if sensor not in sensors:
        errors.append(f"{where}.sensor: no sensor named {sensor!r}; sensors are {_quoted(sensors)}")
    return errors


def _repeated_pairs(key: str, entries: Sequence[PairConfig | PairFactor], fix: str) -> list[str]:
    """One error per entry of ``key`` whose light/sensor pair an earlier entry already has."""
    errors = []
    first: dict[tuple[str, str], int] = {}
    for k, e in enumerate(entries):
        j = first.setdefault((e.light, e.sensor), k)
        if j != k:
            errors.append(
                f"{key}[{k}]: {e.light}/{e.sensor} is already listed as {key}[{j}]; {fix}"
            )
    return errors


# --------------------------------------------------------------------------- files
def _loc(loc: Sequence[int | str]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + part
    return out


def _describe(err: Any) -> str:
    """One readable line for one pydantic error."""
    # Union members add their type name to the location ("pairs.list[PairConfig]"); drop it.
    loc = [p for p in err["loc"] if not (isinstance(p, str) and ("[" in p or p == "str"))]
    where = _loc(loc)
    kind = err["type"]
    given = err.get("input")
    if kind == "missing":
        what = "required key is missing"
    elif kind == "extra_forbidden":
        what = f"unknown key {loc[-1]!r}; check the spelling against docs/rig-config.md"
        where = _loc(loc[:-1]) or "(top level)"
    elif kind == "literal_error":
        expected = err.get("ctx", {}).get("expected", "")
        what = f"{given!r} is not one of {expected.replace(' or ', ', ')}"
    elif kind == "value_error":
        what = str(err["msg"]).removeprefix("Value error, ")
    else:
        what = f"{err['msg']} (got {given!r})"
        unit = _UNITS.get(str(loc[-1]).rsplit("_", 1)[-1]) if loc else None
        if unit and kind in ("less_than_equal", "less_than", "greater_than",
                             "greater_than_equal"):
            # Out of range is most often another unit typed (200 ms as settle_s = 200).
            what += f"; the value is in {unit}"
    return f"{where}: {what}" if where else what


#: Units named by the keys' suffixes, said beside an out-of-range value.
_UNITS = {"s": "seconds", "deg": "degrees", "nm": "nanometres", "dps": "degrees per second",
          "dps2": "degrees per second squared"}


#: The top-level tables of a daemon config (deploy/daemon.example.toml), none of a rig config.
DAEMON_TABLES = frozenset({"server", "auth", "limits", "paths", "results"})


def parse_rig_config(data: dict[str, Any], source: str = "rig config") -> RigConfig:
    """Validate already-parsed TOML data.

    Parameters
    ----------
    data : dict
        The TOML document as a dict.
    source : str
        Name used at the start of error messages (usually the file name).

    Raises
    ------
    ConfigError
        One line per problem, each starting with ``source``.
    """
    daemon_tables = sorted(DAEMON_TABLES & data.keys())
    if "rig" not in data and "stage" not in data and daemon_tables:
        # The daemon config passed where the rig config belongs (both sit in /etc/gonio):
        # one line that says so beats an "unknown key" for each of its tables.
        tables = ", ".join(f"[{t}]" for t in daemon_tables)
        raise ConfigError(
            f"{source}: a daemon config ({tables}), not a rig config: give it to 'gonio serve "
            "--config' (also 'gonio keys' and 'gonio rig lights-off'); where a rig config "
            "is asked for, give the rig's own file (deploy/rig.example.toml; the daemon config "
            "names it in [paths] rig_config)"
        )
    if "rig" not in data and "stage" not in data and isinstance(data.get("lights"), list):
        # A design fragment (gonio design -o) passed where a rig config belongs: one line
        # that says so beats a "required key is missing" for every device.
        raise ConfigError(
            f"{source}: a design fragment (directions, no hardware), not a rig config: it has "
            "no [rig] or [stage] table. Merge it into a rig config with 'gonio rig "
            f"apply-design {source} rig.toml', or simulate a rig with it: 'gonio sim "
            f"--geometry {source} -o rig.toml'"
        )
    try:
        return RigConfig.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            line = f"{source}: {_describe(err)}"
            if line not in lines:
                lines.append(line)
        raise ConfigError("\n".join(lines)) from None


def read_toml(
    path: str | os.PathLike[str], *, noun: str, example: str, error: type[ValueError]
) -> dict[str, Any]:
    """Read a TOML file that people write (rig and daemon configs), with one-line errors.

    Parameters
    ----------
    path : path of the file
    noun : what the file is, for messages ("rig config")
    example : the shipped example to start from, for messages
    error : the exception type to raise (a ``ValueError`` subclass the caller's users catch)

    Returns
    -------
    dict
        The TOML document.

    Raises
    ------
    error
        The file is missing, unreadable, not UTF-8 text or not TOML; the message names the
        file and what to do.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{p}: no such {noun} file; start from {example}") from None
    except UnicodeDecodeError as exc:
        raise error(
            f"{p}: not a text file (byte {exc.start} is not UTF-8); a {noun} is TOML text, "
            f"see {example}"
        ) from None
    except OSError as exc:
        raise error(f"{p}: cannot read the {noun}: {exc.strerror}") from None
    too_deep = error(
        f"{p}: arrays or tables nested more than {MAX_TOML_DEPTH} levels deep; a {noun} needs "
        f"a few levels at most, see {example}")
    if _deepest_key(text) > MAX_TOML_DEPTH:
        # tomllib's time and memory grow with the square of a dotted key's length: a
        # 100,000-part key would take minutes and gigabytes before any error.
        raise too_deep
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{p}: not valid TOML: {exc}") from None
    except RecursionError:
        # tomllib parses nested arrays and inline tables recursively.
        raise too_deep from None
    if _nesting_depth(doc) > MAX_TOML_DEPTH:
        # Parsed (dotted keys nest without recursion), but whatever walks it next (validation,
        # JSON) would recurse as deep.
        raise too_deep
    return doc


MAX_TOML_DEPTH = 64
"""Deepest nesting of tables and arrays :func:`read_toml` accepts; the configs use four."""


def _deepest_key(text: str) -> int:
    """The most parts of a dotted key or table header in TOML ``text`` (a cheap look at each
    line's key before its ``=``, quotes and multi-line strings skipped; 0 when none)."""
    deepest = 0
    in_multiline = False
    for line in text.splitlines():
        if (line.count('"""') + line.count("'''")) % 2:
            in_multiline = not in_multiline
            continue
        if in_multiline:
            continue
        key = line.lstrip()
        if not key.startswith("["):
            key = key.split("=", 1)[0] if "=" in key else ""
        dots = 0
        quote = ""
        for ch in key:
            if quote:
                quote = "" if ch == quote else quote
            elif ch in "\"'":
                quote = ch
            elif ch == ".":
                dots += 1
            elif ch == "#":
                break
        deepest = max(deepest, dots + 1 if key.strip() else 0)
    return deepest


def _nesting_depth(doc: Any) -> int:
    """Levels of tables and arrays in ``doc`` (a plain value: 0), without recursion."""
    deepest = 0
    todo: list[tuple[Any, int]] = [(doc, 1)]
    while todo:
        node, depth = todo.pop()
        if isinstance(node, dict):
            children: Any = node.values()
        elif isinstance(node, list):
            children = node
        else:
            continue
        deepest = max(deepest, depth)
        if depth > MAX_TOML_DEPTH:
            break
        todo.extend((c, depth + 1) for c in children)
    return deepest


def load_rig_config(path: str | os.PathLike[str]) -> RigConfig:
    """Read and validate a rig configuration file.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or invalid; the message names the file and the key.
    """
    data = read_toml(path, noun="rig config", example="deploy/rig.example.toml",
                     error=ConfigError)
    return parse_rig_config(data, Path(path).name)


def dump_rig_config(cfg: RigConfig, path: str | os.PathLike[str], header: str = "") -> Path:
    """Write ``cfg`` as TOML (unset optional keys are left out), after ``header`` (comment
    lines, each starting with ``#``, or nothing); returns the path."""
    p = Path(path)
    data = cfg.model_dump(mode="json", exclude_none=True)
    p.write_text(header + tomli_w.dumps(data), encoding="utf-8")
    return p
