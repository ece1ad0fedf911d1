"""Colour calibration of an RGB (or any non-spectral) sensor from a chart of known reflectances.

A chart is a set of patches whose reflectance spectra are known (from the chart's maker or a
reference spectrophotometer); the sensor reads each patch at one geometry. The calibration is
the ``3 x C`` matrix ``M`` minimising ``sum_p ||M c_p - XYZ_p||^2`` over the patches, with
``c_p`` the sensor's reflectance factors and ``XYZ_p`` the patch's tristimulus values under the
stated illuminant and observer (computed by colour-science from its spectrum). Its quality is
the CIEDE2000 difference between ``M c_p`` and ``XYZ_p`` on the patches themselves, reported as
median and maximum: a matrix cannot undo a sensor whose channels are not a linear transform of
the colour-matching functions (the Luther condition), and this residual says how far off it is.

A three-channel sensor may instead get a root-polynomial colour correction (Finlayson, Mackiewicz
and Hurlbert 2015, IEEE TIP 24(5)): ``XYZ = M (R, G, B, sqrt(RG), sqrt(GB), sqrt(RB))``, degree
2, fitted and applied by colour-science's ``colour.characterisation`` "Finlayson 2015" method.
Its terms scale with the reading, so like the matrix it holds at every exposure and every
reflectance level, which a BRDF's values (dark diffuse to bright specular) need; the extra terms
follow some of what a 3 x 3 matrix cannot. :func:`fit_matrix` picks between the two on the
chart alone: the form whose patches are best predicted by fits without them (leave one patch
out, median CIEDE2000), since the fit's own residual always favours more terms.

Chart file (CSV, UTF-8, one header row; documented in ``docs/colour.md``)::

    patch,R,G,B,380,390,...,730
    dark skin,0.121,0.083,0.062,0.055,0.058,...

``patch`` names the patch; every column whose header is a number is the patch's reference
reflectance factor at that wavelength (nm, increasing, at least 5); every other column is a
sensor channel's reading of the patch as a reflectance factor (``pi f``, the value a white
reference calibration gives), unless the channels are named (:func:`parse_chart`). At least
6 patches; channels named as the sensor names them. A spreadsheet's CSV (semicolons, decimal
commas) reads the same (:mod:`gonio.brdf.colour.spreadsheet`).
"""

from __future__ import annotations

import csv
import io
import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.conditions import (
    ColourError,
    ViewingConditions,
    delta_e00,
    resample,
    spectra_to_xyz,
    xyz_to_lab,
)
from gonio.brdf.colour.spreadsheet import csv_rows

with warnings.catch_warnings():
    # colour-science warns at import that its plotting needs matplotlib; gonio plots no colour.
    warnings.simplefilter("ignore")
    import colour

FloatArray = NDArray[np.float64]

#: Fewest patches a 3 x C least-squares fit is accepted from (an RGB sensor has 9 unknowns;
#: fewer than twice as many equations leaves the residual meaningless).
MIN_PATCHES = 6
#: Fewest channels a calibration is fitted for: XYZ has three dimensions, so fewer channels
#: give colours on a plane or a line through black, whatever the chart.
MIN_CHANNELS = 3
#: Largest reflectance factor a chart file may hold, as reference or reading: a matte
#: chart's patches stay below 1 (fluorescent ones a little above), while percent (or raw
#: counts) reach tens, which fitted silently into a calibration 100 times off.
MAX_FACTOR = 2.0
#: The calibration forms: a 3 x C matrix on the readings, or on their degree-2 root-polynomial
#: expansion (three channels only).
LINEAR, ROOT_POLYNOMIAL = "linear", "root-polynomial"
METHODS = (LINEAR, ROOT_POLYNOMIAL)
#: Degree of the root-polynomial expansion: 6 terms of 3 channels. Degree 3 (13 terms) fits a
#: 24-patch chart closer and predicts left-out patches worse (docs/colour.md).
ROOT_POLYNOMIAL_DEGREE = 2
#: Fewest patches the root-polynomial form is considered from (18 unknowns).
MIN_PATCHES_ROOT_POLYNOMIAL = 12


class ChartError(ColourError):
    """A chart file or calibration input is unusable; the message says what to fix."""


@dataclass(frozen=True)
class Chart:
    """A chart's patches: reference spectra and the sensor's readings.

    Attributes
    ----------
    patches : tuple of str, length P
    wavelengths_nm : (W,) array
    reflectance : (P, W) array, reference reflectance factors
    channels : tuple of str, length C
    readings : (P, C) array, the sensor's reflectance factors of each patch
    """

    patches: tuple[str, ...]
    wavelengths_nm: FloatArray
    reflectance: FloatArray
    channels: tuple[str, ...]
    readings: FloatArray

    def reference_xyz(self, conditions: ViewingConditions) -> FloatArray:
        """(P, 3) XYZ of the patches (perfect diffuser Y = 100)."""
        return spectra_to_xyz(resample(self.wavelengths_nm, self.reflectance), conditions)


@dataclass(frozen=True)
class ColourMatrix:
    """A sensor's colour calibration: channels (reflectance factors) to XYZ.

    Attributes
    ----------
    channels : tuple of str, length C
    matrix : (3, T) array; XYZ = matrix @ terms(c), perfect diffuser Y = 100, with
        ``terms(c) = c`` (T = C) for ``method="linear"`` and the degree-2 root-polynomial
        expansion (T = 6, C = 3) for ``method="root-polynomial"``
    conditions : ViewingConditions the reference XYZ were computed for
    residual_median_de00, residual_max_de00 : float
        CIEDE2000 of the fit on the chart's patches.
    n_patches : int
    source : str
        Where the calibration came from (the chart file's name).
    method : {"linear", "root-polynomial"}
    loo_median_de00 : float
        Median CIEDE2000 of each patch predicted by the fit to the other patches (NaN when not
        computed): what the calibration does on colours it was not fitted to.
    """

    channels: tuple[str, ...]
    matrix: FloatArray
    conditions: ViewingConditions
    residual_median_de00: float
    residual_max_de00: float
    n_patches: int
    source: str = ""
    method: str = LINEAR
    loo_median_de00: float = float("nan")

    def to_xyz(self, values: ArrayLike, conditions: ViewingConditions) -> FloatArray:
        """(..., 3) XYZ of reflectance factors (..., C).

        Raises
        ------
        ColourError
            When ``conditions`` differ from the ones the matrix was fitted for (a matrix holds
            for one illuminant and observer).
        """
        if conditions != self.conditions:
            raise ColourError(
                f"the colour calibration was fitted for {self.conditions.label}, not "
                f"{conditions.label}; fit it again from the chart for {conditions.label}"
            )
        v = np.asarray(values, dtype=float)
        if v.shape[-1] != len(self.channels):
            raise ColourError(
                f"{v.shape[-1]} channels for a colour calibration of {len(self.channels)} "
                f"({', '.join(self.channels)})"
            )
        return _apply(self.method, self.matrix, v)

    def as_dict(self) -> dict[str, Any]:
        """JSON form (the inverse of :meth:`from_dict`)."""
        return {
            "channels": list(self.channels), "matrix": self.matrix.tolist(),
            "illuminant": self.conditions.illuminant, "observer": self.conditions.observer,
            "residual_median_de00": self.residual_median_de00,
            "residual_max_de00": self.residual_max_de00,
            "n_patches": self.n_patches, "source": self.source, "method": self.method,
            "loo_median_de00": self.loo_median_de00,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ColourMatrix:
        """A calibration from :meth:`as_dict`'s form (rig config, result provenance)."""
        try:
            channels = tuple(str(c) for c in d["channels"])
            m = np.asarray(d["matrix"], dtype=float)
            conditions = ViewingConditions(str(d.get("illuminant", "D65")),
                                           str(d.get("observer", "10")))
            def num(key: str) -> float:
                v = d.get(key)
                return float("nan") if v is None else float(v)

            method = str(d.get("method") or LINEAR)
            out = cls(channels, m, conditions, num("residual_median_de00"),
                      num("residual_max_de00"), int(d.get("n_patches") or 0),
                      str(d.get("source") or ""), method, num("loo_median_de00"))
        except (KeyError, TypeError, ValueError) as exc:
            raise ColourError(f"colour calibration is malformed ({exc}); fit it again") from None
        if method not in METHODS:
            raise ColourError(f"colour calibration method {method!r} is unknown; use one of "
                              f"{', '.join(METHODS)}, or fit it again")
        if method == ROOT_POLYNOMIAL and len(channels) != 3:
            raise ColourError(f"a root-polynomial colour calibration needs 3 channels, not "
                              f"{len(channels)}; fit it again")
        terms = n_terms(method, len(channels))
        if m.shape != (3, terms) or not np.isfinite(m).all():
            what = ("one column per channel" if method == LINEAR
                    else "one column per root-polynomial term")
            raise ColourError(
                f"colour calibration matrix is {m.shape}; expected 3 x {terms} finite "
                f"numbers ({what})"
            )
        return out


def n_terms(method: str, n_channels: int) -> int:
    """Columns of a calibration's matrix: the channels, or the root-polynomial terms."""
    if method == ROOT_POLYNOMIAL:
        return int(np.asarray(colour.characterisation.polynomial_expansion_Finlayson2015(
            np.ones(3), degree=ROOT_POLYNOMIAL_DEGREE, root_polynomial_expansion=True)).size)
    return n_channels


def _apply(method: str, matrix: FloatArray, values: FloatArray) -> FloatArray:
    """(..., 3) XYZ of readings (..., C) through a calibration of ``method``."""
    if method == ROOT_POLYNOMIAL:
        # Readings are reflectance factors, >= 0; a noisy negative one would leave the square
        # roots undefined.
        return np.asarray(colour.apply_matrix_colour_correction(
            np.maximum(values, 0.0), matrix, method="Finlayson 2015",
            degree=ROOT_POLYNOMIAL_DEGREE, root_polynomial_expansion=True), dtype=float)
    return np.asarray(values @ matrix.T, dtype=float)


def _fit(method: str, readings: FloatArray, xyz: FloatArray) -> FloatArray:
    """(3, T) least-squares calibration of ``method`` taking ``readings`` (P, C) to ``xyz``."""
    if method == ROOT_POLYNOMIAL:
        return np.asarray(colour.matrix_colour_correction(
            np.maximum(readings, 0.0), xyz, method="Finlayson 2015",
            degree=ROOT_POLYNOMIAL_DEGREE, root_polynomial_expansion=True), dtype=float)
    sol, *_ = np.linalg.lstsq(readings, xyz, rcond=None)
    return np.asarray(sol.T, dtype=np.float64)


def loo_de00(method: str, readings: FloatArray, xyz: FloatArray,
             conditions: ViewingConditions) -> FloatArray:
    """(P,) CIEDE2000 of each patch predicted by the calibration fitted to the other patches.

    Parameters
    ----------
    method : {"linear", "root-polynomial"}
    readings : (P, C) the sensor's reflectance factors of the patches
    xyz : (P, 3) the patches' reference XYZ (perfect diffuser Y = 100)
    conditions : ViewingConditions of ``xyz``
    """
    lab = xyz_to_lab(xyz, conditions)
    out = np.empty(readings.shape[0])
    for p in range(readings.shape[0]):
        keep = np.arange(readings.shape[0]) != p
        m = _fit(method, readings[keep], xyz[keep])
        out[p] = delta_e00(xyz_to_lab(_apply(method, m, readings[p:p + 1]), conditions),
                           lab[p:p + 1])[0]
    return out


def read_chart(path: str | os.PathLike[str], channels: Sequence[str] | None = None) -> Chart:
    """Read a chart file (format in the module docstring; :func:`parse_chart`).

    Raises
    ------
    ChartError
        Naming the file, the row or column and what to change.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ChartError(f"cannot read chart file {p}: {exc}") from None
    try:
        return parse_chart(text, channels)
    except ChartError as exc:
        raise ChartError(f"{p}: {exc}") from None


#: A wavelength column's header: the number of nanometres, ``nm`` after it allowed.
_WAVELENGTH = re.compile(r"^([0-9]+(?:\.[0-9]*)?)\s*nm$", re.IGNORECASE)


def _wavelength(s: str) -> float | None:
    """The wavelength (nm) a column header names, or None for another column."""
    m = _WAVELENGTH.match(s)
    try:
        return float(m.group(1) if m else s)
    except ValueError:
        return None


def _number(s: str, n: int, patch: str, column: str, channel: bool) -> float:
    try:
        return float(s)
    except ValueError:
        hint = ("; every column not headed by a wavelength is read as a sensor channel: name "
                "the sensor's channels (--channels R,G,B) and the other columns are left out"
                if channel else "")
        raise ChartError(f"row {n} ({patch!r}), column {column!r}: {s!r} is not a number"
                         f"{hint}") from None


def parse_chart(text: str, channels: Sequence[str] | None = None) -> Chart:
    """A chart from the text of a chart file (see :func:`read_chart`).

    The text may be as a spreadsheet saves it (cells separated by semicolons or tabs, decimal
    commas, blank rows; :func:`gonio.brdf.colour.spreadsheet.csv_rows`); a wavelength header
    may end in ``nm``.

    Parameters
    ----------
    text : the file's text
    channels : the sensor's channels, optional
        Only these columns are read as channels (in the file's order; :func:`fit_matrix`
        orders them), so other columns (notes, an index) are left out; a channel with no
        column is an error. Default: every column not headed by a wavelength.
    """
    rows = csv_rows(text)
    if not rows:
        raise ChartError("the chart file is empty; see docs/colour.md for its columns")
    header = rows[0]
    if not header or header[0].lower() != "patch":
        raise ChartError("the first column must be 'patch' (the patch names)")
    wls = [_wavelength(h) for h in header]
    wl_cols = [i for i in range(1, len(header)) if wls[i] is not None]
    ch_cols = [i for i in range(1, len(header)) if wls[i] is None]
    if channels is not None:
        missing = [c for c in channels if c not in [header[i] for i in ch_cols]]
        if missing:
            raise ChartError(
                f"the chart has no column for channels {missing} (it has "
                f"{', '.join(header[i] for i in ch_cols)}); name its columns as the sensor's "
                "channels")
        ch_cols = [i for i in ch_cols if header[i] in channels]
    if len(wl_cols) < 5:
        raise ChartError(
            f"{len(wl_cols)} reference wavelength columns; give each patch's reflectance at "
            "5 or more wavelengths (columns headed by the wavelength in nm)"
        )
    if not ch_cols:
        raise ChartError("no sensor channel columns; add the sensor's reading of each patch "
                         "under a column named after its channel (R, G, B, ...)")
    wl = np.array([wls[i] for i in wl_cols], dtype=float)
    if np.any(np.diff(wl) <= 0):
        raise ChartError("reference wavelength columns must increase from left to right")
    names: list[str] = []
    refl, read = [], []
    for n, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ChartError(f"row {n} has {len(row)} fields, the header {len(header)}")
        r = [_number(row[i], n, row[0], header[i], False) for i in wl_cols]
        c = [_number(row[i], n, row[0], header[i], True) for i in ch_cols]
        if not np.isfinite(r + c).all():
            raise ChartError(f"row {n} ({row[0]!r}) holds a value that is not finite")
        names.append(row[0])
        refl.append(r)
        read.append(c)
    if len(names) < MIN_PATCHES:
        raise ChartError(f"{len(names)} patches; a colour calibration needs at least "
                         f"{MIN_PATCHES}")
    for what, values, unit in (("reference reflectances", refl, "reflectance factors"),
                               ("sensor readings", read, "reflectance factors (pi f, the "
                                "values a white-reference calibration gives)")):
        top = float(np.max(values))
        if top > MAX_FACTOR:
            raise ChartError(
                f"the {what} reach {top:g}: give them as {unit}, 1 for the perfect white "
                "(percent: divide by 100)")
    return Chart(tuple(names), wl, np.array(refl), tuple(header[i] for i in ch_cols),
                 np.array(read))


def fit_matrix(chart: Chart, conditions: ViewingConditions | None = None,
               channels: Sequence[str] | None = None, source: str = "",
               method: str | None = None) -> ColourMatrix:
    """Least-squares colour calibration from a chart, with its CIEDE2000 residual.

    Parameters
    ----------
    chart : Chart
    conditions : ViewingConditions, default D65/10
    channels : the sensor's channel order, optional
        The chart's columns are reordered to it; a channel missing from the chart is an error.
    source : str
        Recorded with the matrix.
    method : {"linear", "root-polynomial"}, optional
        The calibration's form (module docstring). Default: chosen on the chart, the form with
        the lower median leave-one-patch-out CIEDE2000 (the root-polynomial form is a
        candidate for three channels and at least :data:`MIN_PATCHES_ROOT_POLYNOMIAL`
        patches).
    """
    cond = conditions or ViewingConditions()
    readings = chart.readings
    names = chart.channels
    if channels is not None:
        missing = [c for c in channels if c not in chart.channels]
        if missing:
            raise ChartError(
                f"the chart has no column for channels {missing} (it has "
                f"{', '.join(chart.channels)}); name its columns as the sensor's channels"
            )
        idx = [chart.channels.index(c) for c in channels]
        readings = readings[:, idx]
        names = tuple(channels)
    if readings.shape[1] < MIN_CHANNELS:
        raise ChartError(
            f"{readings.shape[1]} channels ({', '.join(names)}); colour needs a sensor of at "
            f"least {MIN_CHANNELS} (CIE XYZ has three dimensions: fewer channels cannot tell "
            "colours apart that differ in the missing ones)")
    xyz = chart.reference_xyz(cond)
    if np.linalg.matrix_rank(readings) < min(readings.shape[1], 3):
        raise ChartError("the chart's readings are linearly dependent (all patches alike, or a "
                         "channel that reads nothing); measure a chart of distinct colours")
    if method is not None and method not in METHODS:
        raise ChartError(f"calibration method {method!r} is unknown; use one of "
                         f"{', '.join(METHODS)}")
    rp_possible = readings.shape[1] == 3 and readings.shape[0] >= MIN_PATCHES_ROOT_POLYNOMIAL
    if method == ROOT_POLYNOMIAL and not rp_possible:
        raise ChartError(
            f"a root-polynomial calibration needs 3 channels and at least "
            f"{MIN_PATCHES_ROOT_POLYNOMIAL} patches (this chart: {readings.shape[1]} channels, "
            f"{readings.shape[0]} patches); use the linear one")
    candidates = [method] if method is not None else (
        [LINEAR, ROOT_POLYNOMIAL] if rp_possible else [LINEAR])
    loo = {c: float(np.median(loo_de00(c, readings, xyz, cond))) for c in candidates}
    best = min(candidates, key=lambda c: loo[c])
    m = _fit(best, readings, xyz)
    de = delta_e00(xyz_to_lab(_apply(best, m, readings), cond), xyz_to_lab(xyz, cond))
    return ColourMatrix(names, m, cond, float(np.median(de)), float(np.max(de)),
                        len(chart.patches), source, best, loo[best])


def format_chart(chart: Chart) -> str:
    """The text of a chart file holding ``chart`` (the inverse of :func:`parse_chart`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["patch", *chart.channels, *(f"{x:g}" for x in chart.wavelengths_nm)])
    for name, read, refl in zip(chart.patches, chart.readings, chart.reflectance, strict=True):
        w.writerow([name, *(f"{x:.6g}" for x in read), *(f"{x:.6g}" for x in refl)])
    return buf.getvalue()
