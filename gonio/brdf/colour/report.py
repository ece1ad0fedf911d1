"""The colour numbers a colour lab reads, from a reconstructed BRDF table.

At each instrument geometry (:mod:`~gonio.brdf.colour.instruments`) the table's BRDF ``f``
(1/sr, per channel) becomes the reflectance factor ``R = pi f`` (1 for the perfect diffuser,
what multi-angle spectrophotometers report), then XYZ and CIELAB under the stated conditions:
spectral channels through their bands (:class:`~gonio.brdf.colour.spectral.SpectralBands`), other
sensors through a chart calibration (:class:`~gonio.brdf.colour.chart.ColourMatrix`). A sensor
with neither has no colour: its report holds the channel reflectance factors labelled
``"uncalibrated sensor RGB"`` and no CIELAB.

The table is read between its 5 degree cells in ``log(f + f0)`` (:func:`log_lookup`), not in
``f``: gloss lobes fall off exponentially with angle. Along the half-vector's polar angle
``th`` (across the gloss lobe) the logarithm is interpolated by a Catmull-Rom cubic through the
four nearest cells, continued through the pole (``th = -5`` degrees is ``th = 5`` at the
opposite azimuth), and multilinearly along the other three angles. Every instrument geometry
falls halfway between two ``th`` cells (aspecular ``a`` puts the half vector at ``a / 2``), where
a straight line in the logarithm misses a lobe's curvature: on the true materials tabulated on
the grid (``bench/bench_colour.py``, MA98, 11 spectral specimens) linear interpolation of ``f``
is off by up to 10 ΔE00, of ``log f`` by up to 6.7 (median 0.31), the cubic by up to 2.6
(median 0.04). The cubic reproduces a logarithm quadratic in ``th`` (a Gaussian lobe) exactly.
Where one of the four cells is invalid the lookup falls back to the multilinear one.
The shared lookup of pictures and exports (:mod:`gonio.brdf.tables.interpolation`) clamps
``th`` at the pole instead of continuing through it, which on the same specimens raises the
worst MA98 error of the lookup from 2.6 to 6.7 ΔE00 (at 15as-5, half vector 2.5 degrees from
the normal); docs/colour.md "Why not the shared lookup".

Flop index (X-Rite): ``FI = 2.69 (L*15 - L*110)^1.11 / (L*45)^0.86`` from the 45 degree
incidence readings at aspecular 15, 45 and 110 degrees; where ``L*15 <= L*110`` (no flop) it
is 0.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.chart import ColourMatrix
from gonio.brdf.colour.conditions import (
    ColourError,
    ViewingConditions,
    delta_e00,
    describe,
    xyz_to_lab,
)
from gonio.brdf.colour.direct import ScanReadings, direct_values
from gonio.brdf.colour.instruments import DEFAULT_INSTRUMENTS, Geometry, geometries
from gonio.brdf.colour.spectral import SpectralBands
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]

CIELAB = "CIELAB"
UNCALIBRATED = "uncalibrated sensor RGB"
#: X-Rite's flop index constants.
FLOP_SCALE, FLOP_DIFF_EXP, FLOP_L45_EXP = 2.69, 1.11, 0.86


class ToXYZ(Protocol):
    """Channels to XYZ: spectral bands or a chart calibration."""

    def to_xyz(self, values: ArrayLike, conditions: ViewingConditions) -> FloatArray: ...


#: Offset of the logarithm in :func:`log_lookup`, 1/sr: far below any colour-relevant BRDF
#: (a reflectance factor of 3e-4), so dark cells do not pull the interpolation to -inf.
LOG_OFFSET = 1e-4


def log_lookup(table: BRDFTable, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
    """BRDF of ``table`` at direction pairs, interpolated in ``log(f + f0)``.

    Cubic (Catmull-Rom) along ``th``, multilinear along ``ph``, ``td`` and ``pd``
    (:func:`_log_cubic_th`); where a cell it needs is invalid, multilinear along all four
    (:func:`log_lookup_linear`). Module docstring.

    Parameters
    ----------
    table : BRDFTable, (C, 72, 18, 18, 36), 1/sr
    wi, wo : (N, 3) unit vectors in the specimen frame

    Returns
    -------
    (N, C) array, 1/sr; NaN where no neighbour is valid, 0 below the horizon
    """
    i = np.asarray(wi, dtype=float).reshape(-1, 3)
    o = np.asarray(wo, dtype=float).reshape(-1, 3)
    out = log_lookup_linear(table, i, o)
    cubic, ok = _log_cubic_th(table, i, o)
    use = ok & (i[:, 2] > 0) & (o[:, 2] > 0)
    out[use] = cubic[use]
    return out


def _catmull_rom(t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Weights of the cells at offsets -1, 0, 1, 2 for a point ``t`` (0-1) of the way from
    cell 0 to cell 1 (Catmull-Rom: Keys' cubic with a = -1/2, exact for quadratics)."""
    t2, t3 = t * t, t * t * t
    return ((-t3 + 2 * t2 - t) / 2, (3 * t3 - 5 * t2 + 2) / 2, (-3 * t3 + 4 * t2 + t) / 2,
            (t3 - t2) / 2)


def _log_cubic_th(table: BRDFTable, i: FloatArray, o: FloatArray
                  ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """``log(f + f0)`` blended by Catmull-Rom along ``th`` and multilinearly along the other
    angles, back to ``f``; and where all 64 cells were valid.

    Returns
    -------
    (N, C) array, 1/sr (meaningless where not valid); (N,) bool
    """
    th, ph, td, pd = geo.directions_to_half_diff(i, o)
    n_pts = i.shape[0]
    # Along th: cells i0-1 .. i0+2. Cell -1 is the half vector 5 degrees past the pole, which
    # is cell 1 at the opposite azimuth (ph + pi); beyond the last cell the last one repeats.
    u = np.clip(np.asarray(th, float).ravel() / geo.STEP, 0.0, geo.N_TH - 1)
    i0 = np.minimum(np.floor(u).astype(np.intp), geo.N_TH - 2)
    th_cells = []
    for k, w in zip((-1, 0, 1, 2), _catmull_rom(u - i0), strict=True):
        idx = i0 + k
        flip = idx < 0
        th_cells.append((np.where(flip, -idx, np.minimum(idx, geo.N_TH - 1)), w, flip))
    lin = []
    for a, n, period in ((ph, geo.N_PH, 2 * np.pi), (td, geo.N_TD, 0.0),
                         (pd, geo.N_PD, np.pi)):
        x = np.asarray(a, dtype=float).ravel()
        if period:
            v = np.mod(x, period) / geo.STEP
            j0 = np.floor(v).astype(np.intp)
            lin.append(((j0 % n, 1.0 - (v - j0)), ((j0 + 1) % n, v - j0)))
        else:
            v = np.clip(x / geo.STEP, 0.0, n - 1)
            j0 = np.minimum(np.floor(v).astype(np.intp), n - 2)
            lin.append(((j0, 1.0 - (v - j0)), (j0 + 1, v - j0)))
    acc = np.zeros((n_pts, table.n_channels))
    ok = np.ones(n_pts, dtype=bool)
    half_turn = geo.N_PH // 2
    for ti, tw, flip in th_cells:
        for pi_, pw in lin[0]:
            phi = np.where(flip, (pi_ + half_turn) % geo.N_PH, pi_)
            for di, dw in lin[1]:
                for qi, qw in lin[2]:
                    w = tw * pw * dw * qw
                    v = np.asarray(table.values[:, phi, ti, di, qi], dtype=float).T
                    good = np.isfinite(v).all(axis=1)
                    ok &= good | (w == 0)
                    acc += w[:, None] * np.log(np.maximum(np.where(good[:, None], v, 0.0), 0.0)
                                               + LOG_OFFSET)
    out = np.maximum(np.exp(acc) - LOG_OFFSET, 0.0)
    return out, ok


def log_lookup_linear(table: BRDFTable, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
    """BRDF of ``table`` at direction pairs, interpolated multilinearly in ``log(f + f0)``.

    The same cells and weights as :meth:`BRDFTable.eval_half_diff` (periodic in ``ph`` and
    ``pd``, clamped in ``th`` and ``td``, invalid neighbours left out), blended in the
    logarithm.

    Parameters
    ----------
    table : BRDFTable, (C, 72, 18, 18, 36), 1/sr
    wi, wo : (N, 3) unit vectors in the specimen frame

    Returns
    -------
    (N, C) array, 1/sr; NaN where no neighbour is valid, 0 below the horizon
    """
    i = np.asarray(wi, dtype=float).reshape(-1, 3)
    o = np.asarray(wo, dtype=float).reshape(-1, 3)
    th, ph, td, pd = geo.directions_to_half_diff(i, o)
    axes = []
    for a, n, period in ((ph, geo.N_PH, 2 * np.pi), (th, geo.N_TH, 0.0),
                         (td, geo.N_TD, 0.0), (pd, geo.N_PD, np.pi)):
        x = np.asarray(a, dtype=float).ravel()
        if period:
            u = np.mod(x, period) / geo.STEP
            i0 = np.floor(u).astype(np.intp)
            axes.append((i0 % n, (i0 + 1) % n, u - i0))
        else:
            u = np.clip(x / geo.STEP, 0.0, n - 1)
            i0 = np.minimum(np.floor(u).astype(np.intp), n - 2)
            axes.append((i0, i0 + 1, u - i0))
    acc = np.zeros((i.shape[0], table.n_channels))
    wsum = np.zeros(i.shape[0])
    for idx, w in geo.lattice_corners(axes):
        v = np.asarray(table.values[:, idx[0], idx[1], idx[2], idx[3]], dtype=float).T
        ok = np.isfinite(v).all(axis=1) & (w > 0)
        acc[ok] += w[ok, None] * np.log(np.maximum(v[ok], 0.0) + LOG_OFFSET)
        wsum[ok] += w[ok]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.exp(acc / wsum[:, None]) - LOG_OFFSET
    out[wsum <= 1e-12] = np.nan
    out = np.maximum(out, 0.0)
    out[(i[:, 2] <= 0) | (o[:, 2] <= 0)] = 0.0
    return out


def flop_index(l15: ArrayLike, l45: ArrayLike, l110: ArrayLike) -> FloatArray:
    """X-Rite flop index from L* at aspecular 15, 45 and 110 degrees (broadcastable)."""
    a, b, c = (np.asarray(x, dtype=float) for x in (l15, l45, l110))
    diff = np.maximum(a - c, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(FLOP_SCALE * diff ** FLOP_DIFF_EXP / b ** FLOP_L45_EXP, dtype=float)


def conversion_label(conversion: ToXYZ | None) -> str:
    """How channels became colour, as reports state it."""
    if isinstance(conversion, SpectralBands):
        return f"spectral bands ({conversion.n_bands})"
    if isinstance(conversion, ColourMatrix):
        return (f"chart colour calibration ({conversion.n_patches} patches, residual median "
                f"{conversion.residual_median_de00:.2f} dE00)")
    if conversion is None:
        return UNCALIBRATED
    return type(conversion).__name__


@dataclass(frozen=True)
class ColourReport:
    """Colour of one BRDF at instrument geometries.

    Attributes
    ----------
    name : str
    conditions : ViewingConditions
    space : str
        ``"CIELAB"`` or ``"uncalibrated sensor RGB"``.
    conversion : str
        How channels became XYZ (:func:`conversion_label`).
    channels : tuple of str, length C
    geometries : tuple of Geometry, length G
    reflectance : (G, C) array, reflectance factors ``pi f``
    xyz : (G, 3) array or None, perfect diffuser Y = 100
    lab : (G, 3) array or None
    flop : dict
        ``"MA98@0"``-style key (instrument at azimuth) to flop index.
    provenance : dict
        Conditions, weighting, library version.
    measured : tuple of bool, length G (or empty)
        Which geometries a pair of the scan measured (:mod:`gonio.brdf.colour.direct`); the
        others are read from the table.
    """

    name: str
    conditions: ViewingConditions
    space: str
    conversion: str
    channels: tuple[str, ...]
    geometries: tuple[Geometry, ...]
    reflectance: FloatArray
    xyz: FloatArray | None
    lab: FloatArray | None
    flop: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    measured: tuple[bool, ...] = ()

    @property
    def calibrated(self) -> bool:
        return self.lab is not None

    def rows(self) -> list[dict[str, Any]]:
        """One dict per geometry: instrument, angles, then L*, a*, b*, C*, h (and X, Y, Z), or
        the channel reflectance factors for an uncalibrated report."""
        out = []
        for k, g in enumerate(self.geometries):
            row: dict[str, Any] = {
                "instrument": g.instrument, "incidence_deg": g.incidence_deg,
                "aspecular_deg": g.aspecular_deg, "azimuth_deg": g.azimuth_deg,
            }
            if self.lab is not None and self.xyz is not None:
                lab = self.lab[k]
                row.update({
                    "L": float(lab[0]), "a": float(lab[1]), "b": float(lab[2]),
                    "C": float(np.hypot(lab[1], lab[2])),
                    "h_deg": float(np.degrees(np.arctan2(lab[2], lab[1])) % 360.0),
                    "X": float(self.xyz[k, 0]), "Y": float(self.xyz[k, 1]),
                    "Z": float(self.xyz[k, 2]),
                })
            else:
                row.update({f"R_{c}": float(v)
                            for c, v in zip(self.channels, self.reflectance[k], strict=True)})
            out.append(row)
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON form for the API and the result file. ``conditions`` is null for an
        uncalibrated report: its channel values do not depend on an illuminant or observer,
        so naming one would suggest colour it does not have."""
        return {
            "name": self.name, "space": self.space, "conversion": self.conversion,
            "conditions": self.conditions.as_dict() if self.calibrated else None,
            "channels": list(self.channels),
            "rows": self.rows(), "flop_index": dict(self.flop), "provenance": self.provenance,
            "measured": [bool(m) for m in self.measured] or [False] * len(self.geometries),
        }

    def csv(self, warnings: Sequence[str] = ()) -> str:
        """The rows as CSV text (header first).

        Every line states what a reader of one line needs: the space and conditions (empty
        for an uncalibrated report, whose values depend on neither), ``conversion`` (how the
        channels became colour, :func:`conversion_label`: a chart calibration's residual
        travels with every number it produced), ``source`` (``pair``: a
        pair of the scan read that geometry, :attr:`measured`; ``table``: read from the
        reconstructed table; the same words as the page's and ``gonio colour``'s column) and
        ``warnings``, the sentences that must travel with the numbers (e.g. a calibration
        measured at another exposure, :func:`gonio.result_colour.colour_warnings`), joined
        by ``"; "``, empty when there are none.
        """
        rows = self.rows()
        buf = io.StringIO()
        fields = ["space", "illuminant", "observer", "conversion", *rows[0].keys(),
                  "flop_index", "source", "warnings"]
        w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
        w.writeheader()
        flags = self.measured or (False,) * len(self.geometries)
        said = "; ".join(warnings)
        for g, row, m in zip(self.geometries, rows, flags, strict=True):
            fi = self.flop.get(_flop_key(g.instrument, g.azimuth_deg))
            w.writerow({"space": self.space,
                        "illuminant": self.conditions.illuminant if self.calibrated else "",
                        "observer": self.conditions.observer if self.calibrated else "",
                        "conversion": self.conversion,
                        **_fmt(row),
                        "flop_index": "" if fi is None else f"{fi:.4f}",
                        "source": "pair" if m else "table", "warnings": said})
        return buf.getvalue()


_ANGLES = ("incidence_deg", "aspecular_deg", "azimuth_deg")


def _fmt(row: dict[str, Any]) -> dict[str, Any]:
    return {k: f"{v:g}" if k in _ANGLES else f"{v:.4f}" if isinstance(v, float) else v
            for k, v in row.items()}


def _flop_key(instrument: str, azimuth_deg: float) -> str:
    return f"{instrument}@{azimuth_deg:g}"


def colour_report(
    table: BRDFTable,
    conversion: ToXYZ | None,
    conditions: ViewingConditions | None = None,
    instruments: Sequence[str] = DEFAULT_INSTRUMENTS,
    azimuths_deg: Sequence[float] = (0.0,),
    scan: ScanReadings | None = None,
) -> ColourReport:
    """The colour of ``table`` at the instruments' geometries.

    A geometry one of ``scan``'s pairs measured takes the table's value corrected by that
    pair's readings (:func:`gonio.brdf.colour.direct.direct_values`); the others are read
    from the table.

    Parameters
    ----------
    table : BRDFTable, (C, 72, 18, 18, 36), 1/sr
    conversion : SpectralBands, ColourMatrix or None
        How the channels become XYZ; None reports uncalibrated channel values.
    conditions : ViewingConditions, default D65 / CIE 1964 10 degree
    instruments : names from :data:`~gonio.brdf.colour.instruments.INSTRUMENTS`
    azimuths_deg : specimen azimuths of the plane of incidence, degrees
    scan : ScanReadings, optional
        The readings the table was reconstructed from, in the table's units.

    Raises
    ------
    ColourError
        Channel count not matching the conversion, or a geometry the table has no value at.
    """
    cond = conditions or ViewingConditions()
    geos = geometries(instruments, azimuths_deg)
    wi = np.stack([g.directions()[0] for g in geos])
    wo = np.stack([g.directions()[1] for g in geos])
    f = log_lookup(table, wi, wo)
    measured = np.zeros(len(geos), dtype=bool)
    if scan is not None:
        f, measured = direct_values(lambda a, b: log_lookup(table, a, b), wi, wo, f, scan,
                                    LOG_OFFSET)
    refl = np.pi * f
    if not np.isfinite(refl).all():
        finite = np.asarray(np.isfinite(refl).all(axis=1), dtype=bool)
        ok: list[bool] = [bool(finite[k]) for k in range(len(geos))]
        bad = sorted({g.name for g, good in zip(geos, ok, strict=True) if not good})
        raise ColourError(f"table {table.name!r} has no value at geometries {bad}")
    xyz = lab = None
    space = UNCALIBRATED
    if conversion is not None:
        xyz = conversion.to_xyz(refl, cond)
        lab = xyz_to_lab(xyz, cond)
        space = CIELAB
    flop: dict[str, float] = {}
    if lab is not None:
        for az in dict.fromkeys(g.azimuth_deg for g in geos):
            for inst in dict.fromkeys(g.instrument for g in geos):
                ls = {g.aspecular_deg: lab[k, 0] for k, g in enumerate(geos)
                      if g.instrument == inst and g.azimuth_deg == az and g.incidence_deg == 45}
                if {15.0, 45.0, 110.0} <= ls.keys():
                    flop[_flop_key(inst, az)] = float(flop_index(ls[15.0], ls[45.0], ls[110.0]))
    return ColourReport(
        table.name, cond, space, conversion_label(conversion), table.channels, geos, refl,
        xyz, lab, flop,
        # An uncalibrated report's values depend on no illuminant or observer: its provenance
        # names none.
        {**(describe(cond) if lab is not None else {}),
         "conversion": conversion_label(conversion)},
        tuple(bool(m) for m in measured),
    )


@dataclass(frozen=True)
class ColourDifference:
    """CIEDE2000 between a sample's report and a standard's, geometry by geometry.

    Attributes
    ----------
    geometries : tuple of Geometry, length G
        The sample's geometries compared, in the sample report's order.
    sample, standard : (G, 3) CIELAB
    de00 : (G,) array
    standard_instruments : tuple of str, length G
        The instrument of the standard's geometry each row was compared with: the sample's
        own, or another whose geometry has the same angles (:func:`compare`). Empty: the
        sample's on every row.
    """

    sample_name: str
    standard_name: str
    conditions: ViewingConditions
    geometries: tuple[Geometry, ...]
    sample: FloatArray
    standard: FloatArray
    de00: FloatArray
    standard_instruments: tuple[str, ...] = ()

    @property
    def note(self) -> str | None:
        """What a reader must know when the two were read at other instruments' geometries
        of the same angles (None when every row compares an instrument with itself)."""
        pairs = dict.fromkeys(
            (g.instrument, s) for g, s in zip(self.geometries, self.standard_instruments,
                                              strict=True) if s != g.instrument)
        if not pairs:
            return None
        which = ", ".join(f"the sample's {a} with the standard's {b}" for a, b in pairs)
        return (f"compared at the geometries of the same incidence, aspecular angle and "
                f"azimuth: {which}; a geometry is the same light and sensor direction "
                f"whichever instrument names it")

    @property
    def mean_de00(self) -> float:
        """Mean CIEDE2000 over the distinct geometries compared: each set of angles once.

        The default report holds MA98's and BYK-mac's geometries, six of them the same light
        and sensor directions; a mean over the rows would count those twice. Where two rows
        of the same angles differ (a standard CSV whose instruments read apart), the first
        row's, in the sample report's order, counts."""
        by_key: dict[tuple[float, float, float], float] = {}
        for g, d in zip(self.geometries, self.de00, strict=True):
            by_key.setdefault(_angles(g), float(d))
        return float(np.mean(list(by_key.values())))

    @property
    def distinct_geometries(self) -> int:
        """How many distinct sets of angles the rows compare (:attr:`mean_de00`'s count)."""
        return len({_angles(g) for g in self.geometries})

    def by_instrument(self) -> dict[str, dict[str, float | int]]:
        """Per instrument of the sample's rows: ``max_dE00``, ``mean_dE00`` and the number of
        ``geometries`` (what a lab quotes for one instrument's set of angles)."""
        out: dict[str, dict[str, float | int]] = {}
        for name in dict.fromkeys(g.instrument for g in self.geometries):
            de = self.de00[[g.instrument == name for g in self.geometries]]
            out[name] = {"max_dE00": float(de.max()), "mean_dE00": float(de.mean()),
                         "geometries": int(de.size)}
        return out

    def rows(self) -> list[dict[str, Any]]:
        out = []
        theirs = self.standard_instruments or tuple(g.instrument for g in self.geometries)
        for k, g in enumerate(self.geometries):
            d = self.sample[k] - self.standard[k]
            out.append({
                "instrument": g.instrument, "standard_instrument": theirs[k],
                "incidence_deg": g.incidence_deg,
                "aspecular_deg": g.aspecular_deg, "azimuth_deg": g.azimuth_deg,
                "dL": float(d[0]), "da": float(d[1]), "db": float(d[2]),
                "dE00": float(self.de00[k]),
            })
        return out

    def as_dict(self) -> dict[str, Any]:
        out = {"sample": self.sample_name, "standard": self.standard_name,
               "conditions": self.conditions.as_dict(), "rows": self.rows(),
               "max_dE00": float(self.de00.max()), "mean_dE00": self.mean_de00,
               "instruments": self.by_instrument()}
        if self.note is not None:
            out["note"] = self.note
        return out


def _angles(g: Geometry) -> tuple[float, float, float]:
    """A geometry's light and sensor directions as a key: incidence, aspecular, azimuth
    (degrees; azimuth modulo 360, rounded so that -90 and 270 meet)."""
    return (round(g.incidence_deg, 6), round(g.aspecular_deg, 6),
            round(g.azimuth_deg % 360.0, 6) % 360.0)


def compare(sample: ColourReport, standard: ColourReport) -> ColourDifference:
    """CIEDE2000 of ``sample`` against ``standard`` at the geometries both report.

    A geometry of the sample is compared with the standard's of the same instrument and angles;
    failing that, with one of another instrument at the same incidence, aspecular angle and
    azimuth (an MA68 standard's 45as15 with an MA98 sample's: the same light and sensor
    directions), each such set of angles once. The result's ``note`` says when that happened.

    Raises
    ------
    ColourError
        When either report has no CIELAB (uncalibrated), the conditions differ, or they share
        no geometry.
    """
    for r, what in ((sample, "sample"), (standard, "standard")):
        if r.lab is None:
            raise ColourError(
                f"the {what} {r.name!r} has no CIELAB ({UNCALIBRATED}); give its sensor spectral "
                "bands or a chart colour calibration first"
            )
    if sample.conditions != standard.conditions:
        raise ColourError(
            f"sample is {sample.conditions.label}, standard {standard.conditions.label}; "
            "compare colours under the same illuminant and observer"
        )
    assert sample.lab is not None and standard.lab is not None
    exact = {g: j for j, g in enumerate(standard.geometries)}
    by_angles: dict[tuple[float, float, float], int] = {}
    for j, g in enumerate(standard.geometries):
        by_angles.setdefault(_angles(g), j)
    shared = {k: exact[g] for k, g in enumerate(sample.geometries) if g in exact}
    done = {_angles(sample.geometries[k]) for k in shared}
    # The rest by angle alone, each set of angles once: a sample reported at MA98's and
    # BYK-mac's geometries holds 45as15 twice, and one comparison of it is enough.
    for k, g in enumerate(sample.geometries):
        key = _angles(g)
        if k not in shared and key in by_angles and key not in done:
            shared[k] = by_angles[key]
            done.add(key)
    if not shared:
        raise ColourError(
            f"the two reports share no geometry: the sample holds "
            f"{_which(sample.geometries)}, the standard {_which(standard.geometries)}; "
            f"report the sample with the standard's instrument and azimuth "
            f"(gonio colour --instrument NAME --azimuth DEG)")
    ks = np.array(sorted(shared))
    js = np.array([shared[k] for k in ks])
    a, b = sample.lab[ks], standard.lab[js]
    return ColourDifference(sample.name, standard.name, sample.conditions,
                            tuple(sample.geometries[k] for k in ks), a, b, delta_e00(a, b),
                            tuple(standard.geometries[j].instrument for j in js))


def _which(geos: Sequence[Geometry]) -> str:
    """``"MA68 at azimuth 30 deg"``-style summary of a report's geometries."""
    parts = dict.fromkeys(f"{g.instrument} at azimuth {g.azimuth_deg:g} deg" for g in geos)
    return ", ".join(parts) or "no geometry"
