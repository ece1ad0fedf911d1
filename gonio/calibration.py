"""From sensor readings to BRDF values: per-pair factors from a white reference.

A Lambertian reference of hemispherical albedo ``rho`` has the constant BRDF ``rho / pi``
(1/sr). Measuring it with pair ``q`` gives dark-subtracted readings ``c_q`` (sensor units, per
channel), so the pair's factor is ``k_q = (rho / pi) / c_q`` and a specimen reading ``c`` with
the same pair and exposure is the BRDF value ``k_q c``. This folds lamp power, sensor gain,
solid angle and the cosine foreshortening of each fixed pair into one number per channel,
which is what :class:`gonio.config.PairFactor` stores.

Calibrate at the exposure the scans use: sensors are not assumed to scale linearly with
exposure time, so factors are never rescaled and a scan at another exposure than the
calibration in effect is refused (:meth:`Calibration.check_exposure`). Readings a sensor took
in a lower gain range (auto-ranging, docs/engine.md) are divided by that range's relative
sensitivity first (:func:`counts`), so one factor serves every range. Without any calibration
the values stay in sensor units (factor 1), and the result file
says so.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from gonio.atomicfile import write_atomically
from gonio.hal import PairSpec
from gonio.paths import CALIBRATION_NAME
from gonio.wording import counted

if TYPE_CHECKING:
    from gonio.brdf.reconstruction.samples import Samples as BrdfSamples


class CalibrationError(ValueError):
    """A calibration measurement or file cannot be used; the message says why."""


class PartialCalibration(CalibrationError):
    """A calibration has factors for some of a plan's pairs but not all
    (:meth:`Calibration.check_covers`)."""


class ChannelMismatch(PartialCalibration):
    """A calibration's factors have another number of channels than the rig's sensors read
    (:meth:`Calibration.check_channels`): another sensor set's calibration."""


class ExposureMismatch(CalibrationError):
    """A scan reads at another exposure than the calibration in effect was measured at
    (:meth:`Calibration.check_exposure`)."""


class PairCalibration(BaseModel):
    """Factor from dark-subtracted sensor units to BRDF (1/sr) for one pair, per channel."""

    model_config = ConfigDict(frozen=True)

    light: str
    sensor: str
    factor: tuple[float, ...]

    @field_validator("factor")
    @classmethod
    def _physical(cls, factor: tuple[float, ...]) -> tuple[float, ...]:
        # A factor is (albedo / pi) / reading of a lit white reference: finite and positive.
        # Zero, negative or NaN factors would turn every reading into nonsense in 1/sr.
        if not factor:
            raise ValueError("a pair's factor needs one value per channel, got none")
        if not all(math.isfinite(v) and v > 0 for v in factor):
            raise ValueError(f"factors must be finite and positive (1/sr per sensor unit), "
                             f"got {list(factor)}")
        return factor


class Calibration(BaseModel):
    """A rig's calibration: one :class:`PairCalibration` per pair, and where it came from."""

    model_config = ConfigDict(frozen=True)

    pairs: tuple[PairCalibration, ...] = ()
    reference_albedo: float | None = None
    exposure_s: float | None = Field(default=None, description="exposure it was measured at")
    source: str = "none"
    created: str | None = Field(
        default=None, description="when it was measured (ISO 8601 UTC); None before gonio "
        "recorded it, or for factors from the rig config")

    def factor(self, light: str, sensor: str, n_channels: int) -> NDArray[np.float64]:
        """(C,) factor of a pair; ones when the pair is uncalibrated."""
        for p in self.pairs:
            if p.light == light and p.sensor == sensor:
                if len(p.factor) != n_channels:
                    raise CalibrationError(
                        f"calibration of pair {light}/{sensor} has {len(p.factor)} channels, "
                        f"the readings have {n_channels}; recalibrate the rig"
                    )
                return np.asarray(p.factor, dtype=float)
        return np.ones(n_channels)

    def measured_at_another_exposure(self, exposure_s: float) -> bool:
        """Whether factors were measured at an exposure other than ``exposure_s`` (seconds).

        False without factors or without a recorded exposure: counts are not rescaled between
        exposure times, so this is the one test :func:`exposure_warning` (before a scan) and
        :func:`gonio.finishing.exposure_mismatch` (in its result) both make.
        """
        return bool(self.pairs) and self.exposure_s is not None and not math.isclose(
            exposure_s, self.exposure_s, rel_tol=1e-6)

    @model_validator(mode="after")
    def _one_factor_per_pair(self) -> Calibration:
        seen: set[tuple[str, str]] = set()
        for p in self.pairs:
            if (p.light, p.sensor) in seen:
                raise ValueError(f"pair {p.light}/{p.sensor} has two factors; keep one")
            seen.add((p.light, p.sensor))
        return self

    def apply(self, values: NDArray[np.float64], pairs: Sequence[PairSpec]
              ) -> NDArray[np.float64]:
        """``values`` in 1/sr: the one place the factors multiply readings.

        Parameters
        ----------
        values : (n, r, C) ``raw - dark`` counts, rows in the order of ``pairs``
        pairs : the n pairs

        Returns
        -------
        (n, r, C) float64
            Each pair's row times its factor (ones for an uncalibrated pair).
        """
        v = np.asarray(values, dtype=float)
        if not pairs:
            return v
        factors = np.stack([self.factor(p.light, p.sensor, v.shape[2]) for p in pairs])
        return v * factors[:, None, :]

    def covers(self, pairs: Sequence[PairSpec]) -> bool:
        return not self.missing(pairs)

    def missing(self, pairs: Sequence[PairSpec]) -> list[PairSpec]:
        """The pairs of ``pairs`` this calibration has no factor for, in order."""
        have = {(p.light, p.sensor) for p in self.pairs}
        return [p for p in pairs if (p.light, p.sensor) not in have]

    def check_covers(self, pairs: Sequence[PairSpec], what: str = "the plan") -> None:
        """Refuse to calibrate only some of ``pairs``: a result would mix sensor units and 1/sr.

        An empty calibration (none at all) covers nothing and is accepted: every value then
        stays in sensor units, and the result says so.

        Raises
        ------
        PartialCalibration
            Naming the pairs without a factor and what to do.
        """
        missing = self.missing(pairs)
        if self.pairs and missing:
            names = ", ".join(p.label() for p in missing)
            raise PartialCalibration(
                f"the calibration in effect ({self.source}) has no factors for {len(missing)} "
                f"of the {counted(len(pairs), 'pair')} of {what}: {names}. Run a calibration "
                "job that measures them (a white reference on the stage), or measure only "
                "calibrated pairs"
            )

    def check_channels(self, pairs: Sequence[PairSpec], channels: Mapping[str, int],
                       what: str = "the plan") -> None:
        """Refuse factors with another number of channels than the sensors of ``pairs`` read:
        a calibration measured with other sensors (an RGB rig's beside 31-band
        spectrometers that have the same names and directions). Applying it fails only when
        the job finishes, after every reading was taken; this refuses the job before.

        Parameters
        ----------
        pairs : the plan's pairs
        channels : the number of channels of each sensor, by sensor name (a sensor not
            named is not checked)
        what : the plan, in words, for the message

        Raises
        ------
        ChannelMismatch
            Naming the pairs, both channel counts and what to do.
        """
        wanted = {(p.light, p.sensor) for p in pairs}
        wrong = [p for p in self.pairs if (p.light, p.sensor) in wanted
                 and p.sensor in channels and len(p.factor) != channels[p.sensor]]
        if not wrong:
            return
        names = ", ".join(p.light + "/" + p.sensor for p in wrong[:4])
        more = f" and {len(wrong) - 4} more" if len(wrong) > 4 else ""
        first = wrong[0]
        raise ChannelMismatch(
            f"the calibration in effect ({self.source}) was measured with other sensors than "
            f"{what} reads: its factors for {names}{more} have {len(first.factor)} channels, "
            f"sensor {first.sensor} reads {channels[first.sensor]}; the scan would measure "
            "every reading and then fail. Calibrate this rig again first: a calibration job "
            "with the white reference on the stage (gonio scan [--daemon URL] "
            "--white-reference ALBEDO, or the page's calibration)")

    def check_exposure(self, exposure_s: float, what: str = "the plan") -> None:
        """Refuse a scan at ``exposure_s`` (seconds) under factors measured at another
        exposure: counts are not rescaled between exposure times (sensors need not be linear
        in exposure), so its values in 1/sr would be off by about the ratio. No factors, or
        no recorded exposure (an older calibration file), accept every exposure.

        Raises
        ------
        ExposureMismatch
            Naming both exposures and how to calibrate at the plan's.
        """
        if not self.measured_at_another_exposure(exposure_s) or self.exposure_s is None:
            return
        raise ExposureMismatch(
            f"{what} reads at exposure {exposure_s:g} s, but the calibration in effect "
            f"({self.source}) was measured at {self.exposure_s:g} s; counts are not rescaled "
            f"between exposures (sensors are not assumed linear in exposure time), so its "
            f"values would be off by about {exposure_s / self.exposure_s:.3g} times. Scan at "
            f"{self.exposure_s:g} s, or calibrate at {exposure_s:g} s first: a calibration "
            f"job with exposure {exposure_s:g} s and the white reference on the stage (gonio "
            f"scan [--daemon URL] --white-reference ALBEDO --exposure {exposure_s:g}, or the "
            "page's calibration)")


def sensor_channels(rig: Any) -> dict[str, int]:
    """The number of channels of each sensor of ``rig`` by name, for
    :meth:`Calibration.check_channels`.

    Parameters
    ----------
    rig : a :class:`gonio.rigdescription.RigDescription` or a rig config: anything with
        ``sensors``, each with ``name`` and ``channels``
    """
    return {s.name: len(s.channels) for s in getattr(rig, "sensors", None) or ()}


REFERENCE_TOLERANCE = 0.10
"""How far a white reference's readings may depart from a diffuser's (relative, see
:func:`check_white_reference`): generous against noise and a reference's few per cent of
non-uniformity, far below what a specimen shows."""


def check_white_reference(
    counts: Mapping[tuple[str, str], NDArray[np.float64]],
    tolerance: float = REFERENCE_TOLERANCE,
) -> None:
    """Refuse readings that cannot come from a white diffuser (a Lambertian reference).

    Two checks that need no knowledge of the rig's gains:

    1. *Rotation*: a diffuser's BRDF is the constant ``albedo / pi``, so a pair reads the same
       at every stage angle. A pair whose readings over the angles spread by more than
       ``tolerance`` of their mean (``(max - min) / mean``, per channel) is refused.
    2. *Separability* (when lights share sensors): a diffuser's reading is
       ``E_l cos(theta_l) x g_s``, one factor per light times one per sensor, so
       ``log c[l, s]`` is ``a_l + b_s`` on every connected set of pairs. A pair whose log mean
       reading departs from the least-squares fit ``a_l + b_s`` by more than
       ``log(1 + tolerance)`` is refused. (Independent pairs, each light with one sensor,
       cannot be checked this way.)

    Parameters
    ----------
    counts : mapping (light, sensor) -> (r, C) dark-subtracted readings at r stage angles
    tolerance : float, relative

    Raises
    ------
    CalibrationError
        Naming the worst pair, by how much it departs, and what to do.
    """
    advice = ("Is the white reference on the stage (and the specimen off it)? Put it there and "
              "calibrate again (on a simulated rig: 'gonio sim-place white --rig rig.toml')")
    means: dict[tuple[str, str], NDArray[np.float64]] = {}
    worst: tuple[float, str] = (0.0, "")
    for (light, sensor), c in counts.items():
        a = np.atleast_2d(np.asarray(c, dtype=float))
        mean = np.nanmean(a, axis=0)
        means[(light, sensor)] = mean
        if a.shape[0] < 2 or np.any(mean <= 0):
            continue
        spread = float(np.nanmax((np.nanmax(a, 0) - np.nanmin(a, 0)) / mean))
        if spread > worst[0]:
            worst = (spread, f"{light}/{sensor}")
    if worst[0] > tolerance:
        raise CalibrationError(
            f"the reference does not read like a white diffuser: pair {worst[1]} changes by "
            f"{100 * worst[0]:.0f} % as the stage turns (a diffuser reads the same at every "
            f"angle; allowed {100 * tolerance:.0f} %). {advice}"
        )
    # Separability: least-squares fit of log c = a_l + b_s over the pairs.
    pairs = [p for p, m in means.items() if np.all(m > 0) and np.all(np.isfinite(m))]
    lights = sorted({p[0] for p in pairs})
    sensors = sorted({p[1] for p in pairs})
    if len(pairs) <= len(lights) + len(sensors) - 1:
        return  # no redundancy (e.g. independent pairs): the fit is exact whatever the reading
    design = np.zeros((len(pairs), len(lights) + len(sensors)))
    for q, (li, se) in enumerate(pairs):
        design[q, lights.index(li)] = 1.0
        design[q, len(lights) + sensors.index(se)] = 1.0
    logs = np.log(np.stack([means[p] for p in pairs]))  # (n, C)
    fit, *_ = np.linalg.lstsq(design, logs, rcond=None)
    resid = np.abs(logs - design @ fit).max(axis=1)
    q = int(np.argmax(resid))
    if resid[q] > np.log1p(tolerance):
        li, se = pairs[q]
        raise CalibrationError(
            f"the reference does not read like a white diffuser: pair {li}/{se} reads "
            f"{100 * np.expm1(resid[q]):.0f} % off the light-times-sensor pattern a diffuser "
            f"gives (allowed {100 * tolerance:.0f} %). {advice}"
        )


def from_reference(
    albedo: float,
    counts: Mapping[tuple[str, str], NDArray[np.float64]],
    exposure_s: float | None = None,
    source: str = "white reference",
    check: bool = True,
    created: float | None = None,
) -> Calibration:
    """Calibration from dark-subtracted readings of a white reference.

    Parameters
    ----------
    albedo : float in (0, 1]
        Hemispherical reflectance of the reference.
    counts : mapping (light, sensor) -> (r, C) array
        Dark-subtracted readings at r stage angles; averaged over angles (a rotating
        reference evens out its own non-uniformity).
    exposure_s : float, optional
    source : str
    check : bool
        Run :func:`check_white_reference` on the readings first (default).
    created : float, optional
        When the reference was read (Unix time, seconds); now when not given. Finishing
        passes the last reading's time, so a calibration rebuilt from the same readings
        (``gonio jobs rebuild``) is the same calibration, date included.

    Raises
    ------
    CalibrationError
        If any pair read zero or less (light off, sensor blocked, wrong dark level), or the
        readings cannot come from a white diffuser.
    """
    if not 0 < albedo <= 1:
        raise CalibrationError(f"reference albedo must be in (0, 1], got {albedo}")
    f_ref = albedo / math.pi
    out = []
    for (light, sensor), c in counts.items():
        mean = np.nanmean(np.atleast_2d(np.asarray(c, dtype=float)), axis=0)
        if not np.all(np.isfinite(mean)) or np.any(mean <= 0):
            raise CalibrationError(
                f"pair {light}/{sensor} read {np.round(mean, 6).tolist()} on the white "
                "reference (dark-subtracted); every channel must be positive. Check that the "
                "light works and nothing blocks the sensor, then calibrate again"
            )
        out.append(PairCalibration(light=light, sensor=sensor,
                                   factor=tuple(float(v) for v in f_ref / mean)))
    if check:
        check_white_reference(counts)
    return Calibration(pairs=tuple(out), reference_albedo=albedo, exposure_s=exposure_s,
                       source=source,
                       created=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(created)))


def from_config_factors(factors: Sequence[object], albedo: float | None = None) -> Calibration:
    """Calibration from the rig config's ``[calibration]`` factors (objects with light, sensor,
    factor attributes, as :class:`gonio.config.PairFactor`).

    Raises
    ------
    CalibrationError
        A factor is not finite and positive, or a pair repeats.
    """
    try:
        pairs = tuple(
            PairCalibration(light=str(getattr(f, "light")), sensor=str(getattr(f, "sensor")),  # noqa: B009
                            factor=tuple(float(v) for v in getattr(f, "factor")))  # noqa: B009
            for f in factors
        )
        return Calibration(pairs=pairs, reference_albedo=albedo, source="rig config")
    except ValidationError as exc:
        raise CalibrationError(
            f"the rig config's [calibration] factors are not usable: {_first_error(exc)}; "
            "correct them, or remove them and run a calibration job"
        ) from None


def _first_error(exc: ValidationError) -> str:
    """One line for the first problem pydantic found, with where it is."""
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err.get("loc", ()))
    msg = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    return f"{loc}: {msg}" if loc else msg


CALIBRATION_FILE = CALIBRATION_NAME
"""Name of the latest calibration job's factors inside a data directory (named in
:mod:`gonio.paths`, which looks for it when it picks a rig's data directory)."""


MIN_REFERENCE_FRACTION = 1e-5
"""Least reading of the white reference a factor may imply, as a fraction of the sensor's full
scale (:func:`check_plausible`): a reference that read less than this was not lit or not seen,
and its factors would multiply noise into 1/sr."""


class SensorRange(NamedTuple):
    """What a sensor can read, per channel, in sensor units of its nominal range: ``nominal``
    its full scale at ``gain`` (``saturation_raw`` times the value register's scale) and
    ``highest`` the largest value it reads at all, ``nominal`` times ``gain / g`` for its
    lowest gain stage ``g`` (auto-ranging reads a brighter light there and scales it back,
    :func:`counts`)."""

    nominal: NDArray[np.float64]
    highest: NDArray[np.float64]


def sensor_full_scale(rig_config: Any) -> dict[str, SensorRange]:
    """Each sensor's range (:class:`SensorRange`) from a :class:`gonio.config.RigConfig`; empty
    without one.

    Its gain stages count at the top only: a white reference read at a long exposure,
    saturating at ``gain`` and read again a stage lower, made a calibration that was refused
    as one no reference on the rig could have produced; the least plausible reading stays a
    fraction of the nominal range (:func:`check_plausible`).
    """
    out: dict[str, SensorRange] = {}
    for s in getattr(rig_config, "sensors", None) or ():
        scales = [abs(float(r.scale)) for r in s.registers.values]
        nominal = float(s.saturation_raw) * np.asarray(scales, dtype=float)
        gain = float(getattr(s, "gain", 1.0))
        lowest = min([gain, *(float(g) for g in getattr(s, "gain_stages", None) or ())])
        out[str(s.name)] = SensorRange(nominal, nominal * (gain / lowest))
    return out


def check_plausible(cal: Calibration,
                    full_scale: Mapping[str, SensorRange | NDArray[np.float64]],
                    where: str) -> None:
    """Refuse factors that no white reference on this rig can have produced.

    A factor ``k`` says the reference read ``(albedo / pi) / k`` (dark-subtracted, sensor
    units). That reading must lie between :data:`MIN_REFERENCE_FRACTION` of the sensor's
    nominal full scale and the largest value it reads (above that it saturates in its lowest
    gain stage). Sensors not in ``full_scale`` are not checked.

    Parameters
    ----------
    cal : the calibration
    full_scale : sensor name -> its :class:`SensorRange` (:func:`sensor_full_scale`), or a
        (C,) full scale in sensor units for a sensor without gain stages
    where : the file or setting it came from, for the message

    Raises
    ------
    CalibrationError
        Naming the pair, the reading its factor implies and the sensor's range.
    """
    albedo = cal.reference_albedo if cal.reference_albedo is not None else 1.0
    for p in cal.pairs:
        span = full_scale.get(p.sensor)
        if span is None:
            continue
        nominal, top = (span if isinstance(span, SensorRange)
                        else (np.asarray(span, float), np.asarray(span, float)))
        if len(top) != len(p.factor):
            continue
        implied = (albedo / math.pi) / np.asarray(p.factor, dtype=float)
        low = MIN_REFERENCE_FRACTION * nominal
        if np.any(implied > top) or np.any(implied < low):
            raise CalibrationError(
                f"{where}: the factors of pair {p.light}/{p.sensor} {list(p.factor)} mean the "
                f"white reference read {np.round(implied, 6).tolist()} sensor units, outside "
                f"what sensor {p.sensor} can read ({np.round(low, 6).tolist()} to "
                f"{np.round(top, 6).tolist()}); they cannot come from a calibration of this "
                "rig. Run a calibration job again"
            )


def load_calibration(path: Path) -> Calibration:
    """Read and validate a calibration file (:data:`CALIBRATION_FILE`, ``--calibration``).

    Raises
    ------
    CalibrationError
        The file cannot be read, is not JSON, or is not a valid calibration (factors not
        finite and positive, a pair twice); the message names the file and what to do.
    """
    path = Path(path)
    advice = ("Move it aside (keep it for inspection) and run a calibration job again, or "
              "restore it from a backup")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"calibration file {path} cannot be read ({exc}). {advice}"
                               ) from None
    try:
        return Calibration.model_validate_json(text)
    except ValidationError as exc:
        raise CalibrationError(
            f"calibration file {path} is damaged or not a calibration ({_first_error(exc)}). "
            f"{advice}"
        ) from None


def save_calibration(cal: Calibration, path: Path, full_scale: Mapping[str, Any] | None = None
                     ) -> None:
    """Write ``cal`` to ``path`` so that a crash at any moment leaves the old file or the new
    one, never a torn one: a temporary file, flushed to disk, then renamed over ``path``.

    ``cal`` is validated first (:class:`Calibration` checks its factors; with ``full_scale``,
    :func:`check_plausible` too): a file this writes is one :func:`load_calibration` accepts.
    """
    cal = Calibration.model_validate(cal.model_dump())
    if full_scale:
        check_plausible(cal, full_scale, str(path))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # A full disk leaves the calibration in effect the old one, and no torn temporary file
    # keeps the space the user is about to free.
    write_atomically(path, cal.model_dump_json(indent=2), sync_dir=True)


def calibration_in_effect(data_dir: Path, rig_config: Any = None) -> Calibration:
    """The calibration scans use: the latest calibration job's factors in ``data_dir``, else the
    rig config's ``[calibration]`` factors, else none (values stay in sensor units).

    Parameters
    ----------
    data_dir : folder where calibration jobs write :data:`CALIBRATION_FILE`
    rig_config : gonio.config.RigConfig, optional

    Raises
    ------
    CalibrationError
        The file is damaged, or its factors (or the rig config's) are not finite and positive
        or not plausible for the rig's sensors (:func:`check_plausible`): never applied.
    """
    path = Path(data_dir) / CALIBRATION_FILE
    full_scale = sensor_full_scale(rig_config)
    if path.exists():
        cal = load_calibration(path)
        check_plausible(cal, full_scale, f"calibration file {path}")
        return cal
    conf = getattr(rig_config, "calibration", None)
    if conf is not None and getattr(conf, "factors", None):
        cal = from_config_factors(conf.factors, conf.white_albedo)
        check_plausible(cal, full_scale, "the rig config's [calibration] factors")
        return cal
    return Calibration()


def counts(reading: Any) -> NDArray[np.float64]:
    """(C,) dark-subtracted values of one reading in its sensor's nominal range, sensor units.

    ``(raw - dark) / range_scale``: a reading taken in a lower range (auto-ranging, its dark
    read in the same range) is scaled back by that range's sensitivity relative to range 0,
    so calibration factors, measured in any range, apply to readings in every range. Readings
    without ``range_scale`` (older records) were taken in range 0.
    """
    scale = float(getattr(reading, "range_scale", 1.0))
    return np.subtract(np.asarray(reading.raw, dtype=float),
                       np.asarray(reading.dark, dtype=float)) / scale


def readings_array(
    readings: Sequence[Any],
    pairs: Sequence[PairSpec],
    angle_indices: Sequence[int],
    n_channels: int,
    calibration: Calibration | None = None,
) -> NDArray[np.float64]:
    """A job's readings as one ``(n pairs, r angles, C)`` array: the one place they become one.

    Parameters
    ----------
    readings : ReadingRow-like objects (angle_index, light, sensor, raw, dark)
    pairs : the n pairs, in the order of the rows
    angle_indices : the r angles (store ``angle_index``), in the order of the columns;
        readings at other angles are left out
    n_channels : C
    calibration : factors applied to ``raw - dark`` (BRDF, 1/sr); None keeps sensor units

    Returns
    -------
    (n, r, C) float64
        ``raw - dark`` (times the pair's factor); NaN where a pair has no reading at an angle
        (a reading with fewer channels fills only its own).
    """
    col = {k: j for j, k in enumerate(angle_indices)}
    row = {(p.light, p.sensor): q for q, p in enumerate(pairs)}
    vals = np.full((len(pairs), len(col), n_channels), np.nan)
    for r in readings:
        q = row.get((r.light, r.sensor))
        j = col.get(r.angle_index)
        if q is None or j is None:
            continue
        c = counts(r)
        vals[q, j, : c.size] = c
    return vals if calibration is None else calibration.apply(vals, pairs)


def calibrated_samples(
    readings: Sequence[Any],
    pairs: Sequence[PairSpec],
    light_dirs: NDArray[np.float64],
    sensor_dirs: NDArray[np.float64],
    channels: Sequence[str],
    calibration: Calibration,
) -> CalibratedScan:
    """Arrange a job's readings as calibrated samples ``(n pairs, r angles, C)``.

    Parameters
    ----------
    readings : ReadingRow-like objects (angle_index, commanded_deg, light, sensor, raw, dark)
    pairs : the job's n pairs, in order
    light_dirs, sensor_dirs : (n, 3) lab unit vectors of the pairs
    channels : C channel names
    calibration : factors applied to ``raw - dark``

    Returns
    -------
    CalibratedScan
        Stage angles are the distinct specimen rotations (``commanded_deg mod 360``), sorted.

    Raises
    ------
    CalibrationError
        When a pair has no reading at some angle (an incomplete job cannot be reconstructed).
    """
    angle_of: dict[int, float] = {}
    for r in readings:
        angle_of.setdefault(r.angle_index, float(r.commanded_deg) % 360.0)
    order = sorted(angle_of, key=lambda k: angle_of[k])
    vals = readings_array(readings, pairs, order, len(channels), calibration)
    missing = np.argwhere(np.isnan(vals).any(axis=2))
    if missing.size:
        q, j = missing[0]
        raise CalibrationError(
            f"pair {pairs[q].label()} has no reading at stage angle "
            f"{angle_of[order[j]]:g} deg; the job's readings are incomplete"
        )
    return CalibratedScan(
        pairs=[(p.light, p.sensor) for p in pairs],
        light_dirs=np.asarray(light_dirs, dtype=float),
        sensor_dirs=np.asarray(sensor_dirs, dtype=float),
        stage_angles_deg=np.asarray([angle_of[k] for k in order]),
        values=vals,
        channels=tuple(channels),
        calibration=calibration.model_dump(),
    )


@dataclass
class CalibratedScan:
    """A scan's calibrated readings as the rig took them: ``values[q, j, c]`` of pair q (named
    lab directions) at specimen rotation j (degrees, as stored in result files).

    The reconstruction's view of the same numbers is :meth:`to_samples` (grid cells, lab
    half-vector azimuths, radians): :class:`gonio.brdf.reconstruction.samples.Samples`, the one
    samples type of the numerical core.

    Attributes
    ----------
    pairs : list of (light, sensor)
    light_dirs, sensor_dirs : (n, 3) lab unit vectors
    stage_angles_deg : (r,) degrees
    values : (n, r, C) 1/sr (sensor units when uncalibrated)
    channels : tuple of str
    calibration : the calibration used, as a JSON-able dict
    """

    pairs: list[tuple[str, str]]
    light_dirs: NDArray[np.float64]
    sensor_dirs: NDArray[np.float64]
    stage_angles_deg: NDArray[np.float64]
    values: NDArray[np.float64]
    channels: tuple[str, ...]
    calibration: dict[str, Any] = field(default_factory=dict)

    def to_samples(self, provenance: dict[str, Any] | None = None) -> BrdfSamples:
        """The same readings as the numerical core's samples: each pair's slice cell and lab
        half-vector azimuth (:func:`~gonio.brdf.reconstruction.reconstruct.pair_cells`), stage
        angles in radians.

        Raises
        ------
        gonio.brdf.reconstruction.errors.ReconstructionError
            When a pair's directions are not unit vectors above the specimen.
        """
        from gonio.brdf.reconstruction.reconstruct import pair_cells
        from gonio.brdf.reconstruction.samples import Samples as BrdfSamples

        cells, ph_lab = pair_cells(self.light_dirs, self.sensor_dirs)
        return BrdfSamples(cells, ph_lab, np.deg2rad(self.stage_angles_deg), self.values,
                           self.channels, dict(provenance or {}))


def uncalibrated_warning(cal: Calibration, pairs: Sequence[PairSpec]) -> str | None:
    """What a scan of ``pairs`` under ``cal`` loses when ``cal`` does not cover every pair
    (None when it does): said by every dry run (the page's Check plan, ``gonio scan
    --dry-run``) so an uncalibrated scan is never a surprise."""
    if cal.covers(pairs):
        return None
    if cal.pairs:
        # Not a scan in sensor units: submission refuses it (a result is calibrated in full
        # or not at all), so the dry run must not say it would run.
        missing = sorted({f"{p.light}/{p.sensor}" for p in pairs}
                         - {f"{p.light}/{p.sensor}" for p in cal.pairs})
        return (f"not calibrated: the calibration in effect ({cal.source}) has no factors "
                f"for pair(s) {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''} "
                f"({len(missing)} of the plan's pairs), so the scan would be refused when "
                "submitted: calibrate those pairs (a calibration job with the white reference "
                "on the stage), or list only calibrated pairs in the plan")
    what = "no calibration is in effect on this rig"
    return (f"uncalibrated: {what}, so this scan's values stay in sensor units, not 1/sr; its "
            "rendering, exports and error numbers are not those of the material (run a "
            "calibration job with the white reference on the stage first)")


def exposure_warning(cal: Calibration, exposure_s: float) -> str | None:
    """What a scan at ``exposure_s`` under ``cal`` gets wrong when ``cal`` was measured at
    another exposure (None when it was not, or the exposure is not recorded): said by the dry
    runs and ``gonio scan`` before anything is measured. Counts are not rescaled between
    exposure times (sensors need not be linear in exposure), so the values would be off by
    about the ratio; :func:`gonio.finishing.exposure_mismatch` says it again in the result."""
    if not cal.measured_at_another_exposure(exposure_s) or cal.exposure_s is None:
        return None
    return (f"exposure: the calibration in effect ({cal.source}) was measured at "
            f"{cal.exposure_s:g} s and this scan reads at {exposure_s:g} s; counts are not "
            f"rescaled between exposures, so its values in 1/sr would be off by about "
            f"{exposure_s / cal.exposure_s:.3g} times, and such a scan is refused: scan at "
            f"{cal.exposure_s:g} s, or "
            f"calibrate at {exposure_s:g} s first")


def uncalibrated_refusal(cal: Calibration, pairs: Sequence[PairSpec],
                         rig_data_dir: Path | None, data_dir: Path) -> str | None:
    """Why a scan of ``pairs`` needs the user's explicit acceptance, or None.

    It does when no calibration is in effect (``cal`` has no factors) although the rig's own
    data directory (``gonio scan``'s, :func:`gonio.paths.scan_data_dir`) holds one: most likely
    a daemon or a scan started on another data directory, so the morning's calibration is not
    applied. A calibration in effect that covers some of the pairs but not all is not a case
    for acceptance: submission refuses it, naming the missing pairs (a result is calibrated
    in full or not at all).

    Parameters
    ----------
    cal : the calibration in effect
    pairs : the scan's pairs
    rig_data_dir : the rig's own data directory (None when unknown)
    data_dir : the data directory the scan runs on
    """
    if cal.pairs or cal.covers(pairs) or rig_data_dir is None:
        return None
    own = Path(rig_data_dir)
    if own.resolve() == Path(data_dir).resolve() or not (own / CALIBRATION_FILE).is_file():
        return None
    return (f"this scan would be uncalibrated although the rig was calibrated: "
            f"{own / CALIBRATION_FILE} holds this rig's calibration, and it is not the one in "
            f"effect here (data directory {data_dir})")
