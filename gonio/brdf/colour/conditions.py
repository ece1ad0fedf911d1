"""Viewing conditions and the colorimetric transforms, all computed by ``colour-science``.

A reflectance factor spectrum ``R(lambda)`` (1 for the perfect reflecting diffuser) becomes
tristimulus values by ASTM E308 weighting (the practice of colour-measuring instruments) under
a stated illuminant and observer, normalised so the perfect diffuser has ``Y = 100``. CIELAB is
relative to the same illuminant's white for the same observer; colour differences are CIEDE2000.
The default conditions are D65 and the CIE 1964 10 degree observer, what paint and plastics
labs quote.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.errors import ColourError


@functools.cache
def _colour() -> ModuleType:
    """colour-science, imported on first use: it takes about half a second, which every
    ``gonio`` command paid at start (the CLI's parser imports this module) for a colour
    computation few commands make."""
    with warnings.catch_warnings():
        # colour-science warns at import that its plotting needs matplotlib; gonio plots no
        # colour.
        warnings.simplefilter("ignore")
        import colour
    return colour


FloatArray = NDArray[np.float64]
__all__ = ["ColourError", "ViewingConditions", "delta_e00", "resample", "sd_to_xyz",
           "spectra_to_xyz", "xyz_to_lab"]

#: The wavelength grid spectra are integrated on, nm: ASTM E308's 10 nm tables span 360-780.
GRID_START_NM, GRID_END_NM, GRID_STEP_NM = 360.0, 780.0, 10.0
GRID_NM: FloatArray = np.arange(GRID_START_NM, GRID_END_NM + GRID_STEP_NM / 2, GRID_STEP_NM)
GRID_NM.setflags(write=False)

#: Observer names users may give, mapped to colour-science's names.
OBSERVERS: dict[str, str] = {
    "10": "CIE 1964 10 Degree Standard Observer",
    "2": "CIE 1931 2 Degree Standard Observer",
}
#: Illuminants offered (colour-science holds their spectra and white points).
ILLUMINANTS: tuple[str, ...] = ("D65", "D50", "A", "C", "D55", "D75", "FL2", "FL11")


@dataclass(frozen=True)
class ViewingConditions:
    """Illuminant and observer of every colour number.

    Parameters
    ----------
    illuminant : str
        CIE illuminant name, one of :data:`ILLUMINANTS`.
    observer : str
        ``"10"`` (CIE 1964 10 degree) or ``"2"`` (CIE 1931 2 degree).
    """

    illuminant: str = "D65"
    observer: str = "10"

    def __post_init__(self) -> None:
        if self.illuminant not in ILLUMINANTS:
            raise ColourError(
                f"unknown illuminant {self.illuminant!r}; use one of {', '.join(ILLUMINANTS)}"
            )
        if self.observer not in OBSERVERS:
            raise ColourError(
                f"unknown observer {self.observer!r}; use '10' (CIE 1964 10 degree) or "
                "'2' (CIE 1931 2 degree)"
            )

    @property
    def observer_name(self) -> str:
        """colour-science's name of the observer."""
        return OBSERVERS[self.observer]

    @property
    def label(self) -> str:
        """``"D65/10"``: the usual short form on colour reports."""
        return f"{self.illuminant}/{self.observer}"

    def as_dict(self) -> dict[str, str]:
        """JSON form: illuminant, observer (short and colour-science's name)."""
        return {"illuminant": self.illuminant, "observer": self.observer,
                "observer_name": self.observer_name}

    @property
    def white_xy(self) -> FloatArray:
        """(2,) chromaticity of the illuminant for the observer (colour-science's table)."""
        xy = _colour().CCS_ILLUMINANTS[self.observer_name][self.illuminant]
        return np.asarray(xy, float)

    @property
    def white_xyz(self) -> FloatArray:
        """(3,) XYZ of the perfect diffuser, Y = 100, by the same weighting as every sample."""
        return _white_xyz(self)


@functools.lru_cache(maxsize=16)
def _weights(conditions: ViewingConditions) -> FloatArray:
    """(3, G) ASTM E308 weights on :data:`GRID_NM`: XYZ = weights @ R (perfect diffuser Y=100).

    Obtained from colour-science by weighting the unit spectra of the grid one at a time
    (ASTM E308 weighting is linear in the reflectance), so a batch of spectra costs one
    matrix product instead of one library call each.
    """
    cmfs = _colour().MSDS_CMFS[conditions.observer_name]
    illuminant = _colour().SDS_ILLUMINANTS[conditions.illuminant]
    # The perfect diffuser fixes the normalisation k; unit spectra reuse it (E308's k depends
    # only on the illuminant and observer).
    white = _colour().SpectralDistribution(np.ones_like(GRID_NM), GRID_NM)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        k = 100.0 / float(_colour().sd_to_XYZ(white, cmfs, illuminant, method="ASTM E308",
                                           k=1.0)[1])
        eye = _colour().MultiSpectralDistributions(np.eye(GRID_NM.size), GRID_NM)
        w = np.asarray(_colour().msds_to_XYZ(eye, cmfs, illuminant, method="ASTM E308", k=k),
                       dtype=float)
    return np.ascontiguousarray(w.reshape(GRID_NM.size, 3).T)


@functools.lru_cache(maxsize=16)
def _white_xyz(conditions: ViewingConditions) -> FloatArray:
    return _weights(conditions).sum(axis=1)


def spectra_to_xyz(reflectance: ArrayLike, conditions: ViewingConditions) -> FloatArray:
    """XYZ of reflectance factor spectra on :data:`GRID_NM`.

    Parameters
    ----------
    reflectance : (..., G) array_like
        Reflectance factors (1 = perfect diffuser) at the :data:`GRID_NM` wavelengths.
    conditions : ViewingConditions

    Returns
    -------
    (..., 3) array, perfect diffuser Y = 100
    """
    r = np.asarray(reflectance, dtype=float)
    if r.shape[-1] != GRID_NM.size:
        raise ColourError(
            f"spectra have {r.shape[-1]} samples; expected {GRID_NM.size} "
            f"({GRID_START_NM:g}-{GRID_END_NM:g} nm every {GRID_STEP_NM:g} nm)"
        )
    return r @ _weights(conditions).T


def sd_to_xyz(wavelengths_nm: ArrayLike, reflectance: ArrayLike,
              conditions: ViewingConditions) -> FloatArray:
    """XYZ of one reflectance spectrum given at any wavelengths (colour-science's own path).

    The spectrum is aligned by colour-science (interpolated, ends extrapolated as constant,
    ASTM E308's practice) and weighted by ASTM E308. For reference values and reflectance data
    given at other sampling than :data:`GRID_NM`.

    Returns
    -------
    (3,) array, perfect diffuser Y = 100
    """
    sd = _colour().SpectralDistribution(np.asarray(reflectance, float),
                                     np.asarray(wavelengths_nm, float))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xyz = _colour().sd_to_XYZ(sd, _colour().MSDS_CMFS[conditions.observer_name],
                               _colour().SDS_ILLUMINANTS[conditions.illuminant],
                               method="ASTM E308")
    return np.asarray(xyz, dtype=float)


def resample(wavelengths_nm: ArrayLike, values: ArrayLike) -> FloatArray:
    """Spectra given at ``wavelengths_nm`` on :data:`GRID_NM`, aligned by colour-science.

    Parameters
    ----------
    wavelengths_nm : (W,) array_like, increasing
    values : (..., W) array_like

    Returns
    -------
    (..., G) array: interpolated inside the given range (colour-science's default
    interpolator for its spectra; linear below 6 samples, where a spline is not defined),
    constant outside it
    """
    wl = np.asarray(wavelengths_nm, dtype=float)
    v = np.asarray(values, dtype=float)
    flat = v.reshape(-1, wl.size)
    shape = _colour().SpectralShape(GRID_START_NM, GRID_END_NM, GRID_STEP_NM)
    if wl.ndim != 1 or wl.size < 2 or np.any(np.diff(wl) <= 0):
        raise ColourError(
            f"spectral wavelengths must be at least 2 increasing values in nm; got {wl.tolist()}"
        )
    if v.shape[-1] != wl.size:
        raise ColourError(f"{v.shape[-1]} spectral values for {wl.size} wavelengths")
    out = np.empty((flat.shape[0], GRID_NM.size))
    kwargs: dict[str, Any] = {"extrapolator_kwargs": {"method": "Constant"}}
    if wl.size < 6:
        kwargs["interpolator"] = _colour().LinearInterpolator
    for i, row in enumerate(flat):
        sd = _colour().SpectralDistribution(row, wl)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sd = sd.copy().align(shape, **kwargs)
        out[i] = sd.values
    return out.reshape(*v.shape[:-1], GRID_NM.size)


def xyz_to_lab(xyz: ArrayLike, conditions: ViewingConditions) -> FloatArray:
    """CIELAB of XYZ (perfect diffuser Y = 100) relative to the conditions' white.

    The reference white is the perfect diffuser weighted by the same ASTM E308 table as the
    samples (E308's practice), so a perfect diffuser is exactly L* = 100, a* = b* = 0.

    Parameters
    ----------
    xyz : (..., 3) array_like

    Returns
    -------
    (..., 3) array: L*, a*, b*
    """
    x = np.asarray(xyz, dtype=float) / 100.0
    white = _colour().XYZ_to_xy(conditions.white_xyz / 100.0)
    return np.asarray(_colour().XYZ_to_Lab(x, white), dtype=float)


def delta_e00(lab_1: ArrayLike, lab_2: ArrayLike) -> FloatArray:
    """CIEDE2000 colour difference (``kL = kC = kH = 1``) of broadcastable (..., 3) CIELAB."""
    return np.asarray(_colour().delta_E(np.asarray(lab_1, float), np.asarray(lab_2, float),
                                     method="CIE 2000"), dtype=float)


def library_version() -> str:
    """The colour-science version that computed the numbers (for provenance)."""
    return str(_colour().__version__)


def describe(conditions: ViewingConditions) -> dict[str, Any]:
    """What a colour number was computed with: conditions, weighting and library version."""
    return {**conditions.as_dict(), "weighting": "ASTM E308",
            "wavelengths_nm": [GRID_START_NM, GRID_END_NM, GRID_STEP_NM],
            "library": f"colour-science {library_version()}"}
