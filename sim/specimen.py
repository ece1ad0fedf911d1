"""The physics of a simulated reading: a specimen's BRDF seen by fixed lamps and a sensor.

A sensor at lab direction ``wo`` integrating for ``t`` seconds while lamps ``l`` at lab
directions ``wi_l`` shine with irradiance ``E_l`` (scaled by their drive level) on a specimen
turned to stage angle ``alpha`` records, per channel, in raw ADC counts::

    signal = sum_l E_l level_l f(wi_l', wo') cos(theta_i,l) * gain * t
    counts = clip(round(signal + dark + noise), 0, saturation)

where ``wi', wo'`` are the lab directions expressed in the specimen frame
(:func:`gonio.brdf.tables.geometry.lab_to_specimen`), ``dark = dark_offset + dark_rate * t`` and the
noise is Gaussian with variance ``shot_gain * (signal + dark_rate t) + read_noise**2`` (the
Gaussian limit of photon shot noise plus read noise). ``E_l`` is in counts per (1/sr) per
second at gain 1, so it folds the lamp power and the sensor's responsivity into one number;
the inverse (what a calibration recovers) is in :func:`brdf_from_counts`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables.geometry import lab_to_specimen

__all__ = [
    "BRDFLike",
    "NoiseModel",
    "Specimen",
    "brdf_from_counts",
    "expected_counts",
    "sample_counts",
]

FloatArray = NDArray[np.float64]


class BRDFLike(Protocol):
    """Anything that evaluates a BRDF in the specimen frame (a ``BRDFTable``, an analytic model)."""

    def eval(self, wi: ArrayLike, wo: ArrayLike) -> Any:
        """(..., C) BRDF values, 1/sr, for (..., 3) unit vectors ``wi``, ``wo``."""
        ...


@dataclass(frozen=True)
class NoiseModel:
    """Sensor noise and dark signal, in raw counts.

    Attributes
    ----------
    dark_offset : float
        Counts with no light and zero exposure (ADC offset).
    dark_rate : float
        Dark current, counts per second of exposure.
    read_noise : float
        Standard deviation of the read-out noise, counts.
    shot_gain : float
        Counts per photo-electron: the shot-noise variance is ``shot_gain * signal``. 0 turns
        shot noise off.
    saturation : float
        Largest count the ADC can report (full scale).
    """

    dark_offset: float = 100.0
    dark_rate: float = 20.0
    read_noise: float = 2.0
    shot_gain: float = 0.5
    saturation: float = 65535.0

    @classmethod
    def noiseless(cls, saturation: float = 65535.0) -> NoiseModel:
        """No dark signal and no noise: counts equal the rounded signal."""
        return cls(0.0, 0.0, 0.0, 0.0, saturation)

    def dark(self, exposure_s: float) -> float:
        """Mean dark counts for an exposure of ``exposure_s`` seconds."""
        return self.dark_offset + self.dark_rate * exposure_s

    def sigma(self, signal: ArrayLike, exposure_s: float) -> FloatArray:
        """Standard deviation of the counts around ``signal + dark``, counts."""
        s = np.maximum(np.asarray(signal, dtype=float), 0.0) + self.dark_rate * exposure_s
        return np.asarray(np.sqrt(self.shot_gain * s + self.read_noise**2), dtype=float)


class Specimen:
    """A specimen on the stage: its BRDF and how lab directions reach it.

    Parameters
    ----------
    brdf : BRDFLike
        Evaluated in the specimen frame.
    """

    def __init__(self, brdf: BRDFLike) -> None:
        self.brdf = brdf
        probe = np.asarray(brdf.eval(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])))
        self.n_channels = int(probe.shape[-1]) if probe.ndim else 1

    def brdf_lab(self, wi_lab: ArrayLike, wo_lab: ArrayLike, stage_deg: float) -> FloatArray:
        """BRDF for lab-frame directions with the stage at ``stage_deg`` degrees.

        Parameters
        ----------
        wi_lab, wo_lab : (..., 3) array_like, unit vectors in the lab frame
        stage_deg : float, degrees

        Returns
        -------
        (..., C) array, 1/sr; 0 below the horizon or where the BRDF is undefined (NaN).
        """
        alpha = np.deg2rad(stage_deg)
        wi = lab_to_specimen(wi_lab, alpha)
        wo = lab_to_specimen(wo_lab, alpha)
        f = np.asarray(self.brdf.eval(wi, wo), dtype=float)
        if f.ndim == wi.ndim - 1:  # a single-channel model returning (...,)
            f = f[..., None]
        return np.nan_to_num(np.maximum(f, 0.0), nan=0.0)


def expected_counts(
    specimen: Specimen,
    lights: Sequence[tuple[ArrayLike, float]],
    wo_lab: ArrayLike,
    stage_deg: float,
    gain: float,
    exposure_s: float,
) -> FloatArray:
    """Noise-free signal (dark not included) of one exposure, counts per channel.

    Parameters
    ----------
    specimen : Specimen
    lights : sequence of (wi_lab (3,), irradiance)
        The lamps that are on: lab direction toward each and its irradiance times drive level,
        counts per (1/sr) per second at gain 1.
    wo_lab : (3,) array_like, unit vector toward the sensor, lab frame
    stage_deg : float, degrees
    gain : float, sensor gain (dimensionless)
    exposure_s : float, seconds

    Returns
    -------
    (C,) array, counts
    """
    out = np.zeros(specimen.n_channels)
    wo = np.asarray(wo_lab, dtype=float)
    for wi_lab, irradiance in lights:
        wi = np.asarray(wi_lab, dtype=float)
        cos_i = max(float(wi[2]), 0.0)  # the stage normal is the lab z axis
        f = specimen.brdf_lab(wi, wo, stage_deg)
        out += irradiance * f * cos_i
    return out * gain * exposure_s


def sample_counts(
    signal: ArrayLike, exposure_s: float, noise: NoiseModel, rng: np.random.Generator
) -> FloatArray:
    """One noisy, quantized, clipped reading from a noise-free ``signal``.

    Parameters
    ----------
    signal : (C,) array_like, counts (from :func:`expected_counts`)
    exposure_s : float, seconds
    noise : NoiseModel
    rng : numpy Generator (seeded by the caller for reproducible runs)

    Returns
    -------
    (C,) array of whole counts in ``[0, noise.saturation]``
    """
    s = np.asarray(signal, dtype=float)
    mean = s + noise.dark(exposure_s)
    counts = mean + rng.standard_normal(s.shape) * noise.sigma(s, exposure_s)
    return np.asarray(np.clip(np.rint(counts), 0.0, noise.saturation), dtype=float)


def brdf_from_counts(
    counts: ArrayLike,
    dark: ArrayLike,
    irradiance: float,
    wi_lab: ArrayLike,
    gain: float,
    exposure_s: float,
) -> FloatArray:
    """Invert :func:`expected_counts` for one lamp: BRDF (1/sr) from dark-subtracted counts.

    ``f = (counts - dark) / (E cos(theta_i) gain t)``; this is what a calibrated rig does.
    """
    cos_i = float(np.asarray(wi_lab, dtype=float)[2])
    if cos_i <= 0:
        raise ValueError("the light is at or below the horizon; no BRDF can be recovered")
    c = np.asarray(counts, dtype=float) - np.asarray(dark, dtype=float)
    return np.asarray(c / (irradiance * cos_i * gain * exposure_s), dtype=float)
