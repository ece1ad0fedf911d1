"""Spectral sensor bands and the reflectance spectrum behind their readings.

A spectral channel reads the reflectance factor weighted by its band's response. A band is
given either by its centre and full width at half maximum (a Gaussian response, the datasheet
form of spectral sensor chips) or by a response table sampled at wavelengths. Readings become
colour in two steps:

1. Each band's response is projected onto :data:`~gonio.brdf.colour.conditions.GRID_NM` with
   linear "hat" weights, i.e. the reflectance is taken as piecewise linear between grid points;
   rows are normalised so a flat reflectance ``R`` reads ``R`` in every band (what a white
   reference calibration makes true).
2. The spectrum on the grid is the regularised least-squares solution of
   ``min ||A R - y||^2 + mu ||D R||^2`` with ``D`` the first difference: where the bands
   determine the spectrum it follows them, elsewhere (beyond the outermost bands, in gaps
   between narrow bands) it continues flat, the constant extrapolation of ASTM E308.

The spectrum then goes to XYZ by :func:`~gonio.brdf.colour.conditions.spectra_to_xyz`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.conditions import (
    GRID_NM,
    GRID_STEP_NM,
    ColourError,
    ViewingConditions,
    spectra_to_xyz,
)

FloatArray = NDArray[np.float64]

#: Weight of the smoothness term relative to the band rows (each of unit sum): small enough
#: that well-determined spectra follow the readings to better than 0.1 %, large enough to make
#: the system solvable with any number of bands.
SMOOTHNESS = 1e-4
#: Fine sampling the band responses are integrated on before projection onto the grid, nm.
_FINE_STEP_NM = 0.5


@dataclass(frozen=True)
class SpectralBands:
    """The bands of a spectral sensor, one per channel.

    Parameters
    ----------
    centres_nm : sequence of float, length C
        Centre (peak) wavelength of each band, nm.
    widths_nm : sequence of float, length C, optional
        Full width at half maximum of each band's Gaussian response, nm. Default: the spacing
        of neighbouring centres (a spectrometer's bands tile the range).
    response_nm : sequence of float, length W, optional
        Wavelengths of a response table, nm (increasing); with ``responses``, it replaces the
        Gaussian model.
    responses : (C, W) array_like, optional
        Relative response of each channel at ``response_nm`` (any scale, non-negative).
    """

    centres_nm: tuple[float, ...]
    widths_nm: tuple[float, ...] | None = None
    response_nm: tuple[float, ...] | None = None
    responses: tuple[tuple[float, ...], ...] | None = None

    def __post_init__(self) -> None:
        c = np.asarray(self.centres_nm, dtype=float)
        if c.ndim != 1 or c.size == 0 or not np.isfinite(c).all() or (c <= 0).any():
            raise ColourError(f"band centres must be positive wavelengths in nm; got {c.tolist()}")
        object.__setattr__(self, "centres_nm", tuple(float(x) for x in c))
        if self.widths_nm is None:
            object.__setattr__(self, "widths_nm", tuple(default_widths(c).tolist()))
        w = np.asarray(self.widths_nm, dtype=float)
        if w.shape != c.shape or not np.isfinite(w).all() or (w <= 0).any():
            raise ColourError(
                f"give one positive band width (FWHM, nm) per band: {c.size} centres, widths "
                f"{w.tolist()}"
            )
        object.__setattr__(self, "widths_nm", tuple(float(x) for x in w))
        if (self.responses is None) != (self.response_nm is None):
            raise ColourError("a response table needs both its wavelengths and its responses")
        if self.responses is not None and self.response_nm is not None:
            wl = np.asarray(self.response_nm, dtype=float)
            r = np.asarray(self.responses, dtype=float)
            if wl.ndim != 1 or wl.size < 2 or np.any(np.diff(wl) <= 0):
                raise ColourError("response table wavelengths must increase (nm)")
            if r.shape != (c.size, wl.size):
                raise ColourError(
                    f"response table is {r.shape}; expected {c.size} channels x {wl.size} "
                    "wavelengths"
                )
            if not np.isfinite(r).all() or (r < 0).any() or (r.sum(axis=1) <= 0).any():
                raise ColourError(
                    "responses must be finite, non-negative and positive somewhere for each "
                    "channel"
                )
            object.__setattr__(self, "response_nm", tuple(wl.tolist()))
            object.__setattr__(self, "responses", tuple(tuple(row) for row in r.tolist()))

    @property
    def n_bands(self) -> int:
        return len(self.centres_nm)

    def as_dict(self) -> dict[str, object]:
        """JSON form (the inverse of :meth:`from_dict`)."""
        out: dict[str, object] = {"centres_nm": list(self.centres_nm),
                                  "widths_nm": list(self.widths_nm or ())}
        if self.responses is not None:
            out["response_nm"] = list(self.response_nm or ())
            out["responses"] = [list(r) for r in self.responses]
        return out

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> SpectralBands:
        """Bands from :meth:`as_dict`'s form."""
        def seq(key: str) -> tuple[float, ...] | None:
            v = d.get(key)
            return None if v is None else tuple(float(x) for x in v)  # type: ignore[attr-defined]
        responses = d.get("responses")
        return cls(
            seq("centres_nm") or (), seq("widths_nm"), seq("response_nm"),
            None if responses is None
            else tuple(tuple(float(x) for x in row) for row in responses),  # type: ignore[attr-defined]
        )

    def response_matrix(self) -> FloatArray:
        """(C, G) band rows on the colour grid, each summing to 1 (step 1 above)."""
        return _response_matrix(self)

    def to_spectrum(self, values: ArrayLike) -> FloatArray:
        """Reflectance factor spectra on the colour grid behind band readings (step 2).

        Parameters
        ----------
        values : (..., C) array_like
            Reflectance factors read in each band (``pi f`` for a BRDF ``f`` in 1/sr).

        Returns
        -------
        (..., G) array on :data:`~gonio.brdf.colour.conditions.GRID_NM`
        """
        v = np.asarray(values, dtype=float)
        if v.shape[-1] != self.n_bands:
            raise ColourError(f"{v.shape[-1]} values for {self.n_bands} spectral bands")
        return v @ _solve_operator(self).T

    def to_xyz(self, values: ArrayLike, conditions: ViewingConditions) -> FloatArray:
        """(..., 3) XYZ (perfect diffuser Y = 100) of band readings (..., C)."""
        return spectra_to_xyz(self.to_spectrum(values), conditions)

    def read(self, spectra: ArrayLike) -> FloatArray:
        """What the bands read from reflectance spectra (..., G) on the grid: (..., C).

        The forward model of step 1, used by the simulator and by tests.
        """
        return np.asarray(spectra, dtype=float) @ self.response_matrix().T


def default_widths(centres_nm: ArrayLike) -> FloatArray:
    """Band widths (nm) from centre spacing: each band as wide as the gap to its neighbours.

    One band alone is given the colour grid's step.
    """
    c = np.asarray(centres_nm, dtype=float)
    if c.size == 1:
        return np.array([GRID_STEP_NM])
    order = np.argsort(c)
    gaps = np.diff(c[order])
    left = np.concatenate([[gaps[0]], gaps])
    right = np.concatenate([gaps, [gaps[-1]]])
    w = np.empty_like(c)
    w[order] = np.maximum((left + right) / 2, 1.0)
    return w


def bands_from_channels(channels: Sequence[str],
                        wavelengths_nm: Sequence[float] | None,
                        widths_nm: Sequence[float] | None = None) -> SpectralBands | None:
    """The bands of a table's channels, or None when its channels carry no wavelength.

    Raises
    ------
    ColourError
        When some channels have a wavelength and others do not.
    """
    if wavelengths_nm is None:
        return None
    wl = np.asarray(wavelengths_nm, dtype=float)
    if np.isnan(wl).all():
        return None
    if np.isnan(wl).any():
        missing = [c for c, w in zip(channels, wl, strict=True) if np.isnan(w)]
        raise ColourError(
            f"channels {missing} have no wavelength while others do; a spectral sensor gives "
            "every channel a band"
        )
    return SpectralBands(tuple(wl.tolist()), None if widths_nm is None else tuple(widths_nm))


@functools.lru_cache(maxsize=32)
def _response_matrix(bands: SpectralBands) -> FloatArray:
    lo, hi = GRID_NM[0] - GRID_STEP_NM, GRID_NM[-1] + GRID_STEP_NM
    fine = np.arange(lo, hi + _FINE_STEP_NM / 2, _FINE_STEP_NM)
    if bands.responses is not None and bands.response_nm is not None:
        table = np.asarray(bands.responses, dtype=float)
        wl = np.asarray(bands.response_nm, dtype=float)
        resp = np.stack([np.interp(fine, wl, row, left=0.0, right=0.0) for row in table])
    else:
        c = np.asarray(bands.centres_nm)[:, None]
        sigma = np.asarray(bands.widths_nm)[:, None] / (2 * np.sqrt(2 * np.log(2)))
        resp = np.exp(-0.5 * ((fine[None, :] - c) / sigma) ** 2)
    # Hat functions of the grid points: R(lambda) = sum_g R_g hat_g(lambda).
    hat = np.clip(1 - np.abs(fine[None, :] - GRID_NM[:, None]) / GRID_STEP_NM, 0.0, None)
    rows = resp @ hat.T
    sums = rows.sum(axis=1, keepdims=True)
    if (sums <= 0).any():
        bad = [bands.centres_nm[i] for i in np.flatnonzero(sums[:, 0] <= 0)]
        raise ColourError(
            f"bands at {bad} nm respond nowhere in {GRID_NM[0]:g}-{GRID_NM[-1]:g} nm; "
            "colour needs bands in the visible range"
        )
    out = rows / sums
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=32)
def _solve_operator(bands: SpectralBands) -> FloatArray:
    """(G, C) matrix taking band readings to the regularised spectrum (step 2)."""
    a = _response_matrix(bands)
    d = np.diff(np.eye(GRID_NM.size), axis=0)
    lhs = a.T @ a + SMOOTHNESS * d.T @ d
    out: FloatArray = np.asarray(np.linalg.solve(lhs, a.T), dtype=np.float64)
    out.setflags(write=False)
    return out
