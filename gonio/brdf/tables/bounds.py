"""Physical bounds of a BRDF table (issue 23 item 4): is a reconstruction a possible material?

A linear basis fitted to a few dozen readings can extrapolate wildly where no reading looks:
a tilted brushed aluminium read by eight rotations of a simulated rig reconstructed to
2.3e13 1/sr from readings that never exceeded 0.75. Two numbers say so without knowing the
truth:

* the **directional albedo** ``a(wi) = integral f(wi, wo) cos(theta_o) dwo`` over the outgoing
  hemisphere, the fraction of light from ``wi`` that is reflected. Energy conservation puts it
  at or below 1 for every passive material; :func:`directional_albedo` integrates the table by
  the midpoint rule on a (theta_o, phi_o) grid at several incidences, leaving out the cone
  around the mirror direction where a 5 degree table cannot hold a narrow lobe's energy
  (:data:`SPECULAR_EXCLUDE_DEG`).
* the **peak ratio**: the table's largest projected value ``f cos(theta_i) cos(theta_o)`` over
  the largest projected reading the reconstruction was fitted to. A reconstruction may
  legitimately peak above every reading (a narrow highlight falls between the pairs), but not
  by orders of magnitude. The projection is what keeps the bound physical at grazing angles: a
  microfacet lobe's value at its mirror direction is ``D F G / (4 cos ti cos to)``, so a clear
  coat of GGX alpha 0.06 (a plain solid paint) peaks at 1.5e3 1/sr where the light and the view
  are both 85 degrees from the normal, 4e3 times the largest reading of the default simulated
  rig, while its projected peak ``D F G / 4`` stays at 11 (49 times the largest projected
  reading; docs/science.md 7.5).

Where a table exceeds the peak bound, :func:`peak_excess_log_rmse` says how much error that
part alone carries: the ``log_rmse`` between the table and itself capped at the bound (in each
cell, the bound's projected value over that cell's ``cos ti cos to``: :func:`peak_cap`). For
any truth within the bound it is a lower bound of the table's true ``log_rmse`` (in every cell
above the cap the truth is at or below it, and ``ln(1 + f cos ti)`` grows with ``f``), so a
reconstruction's self-estimate is never reported below it (``predicted_log_rmse``). That the
truth stays within the bound is an assumption: a polished specimen no pair reads near its
mirror direction can peak higher (docs/science.md 7.5).

:func:`bounds_check` returns both with a verdict against :data:`ALBEDO_LIMIT` and
:data:`PEAK_RATIO_LIMIT` (their docstrings say why those values).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]

ALBEDO_LIMIT = 1.5
"""Directional albedo above which a table is out of bounds. Physics says 1; the margin covers
what is not the material's fault: the midpoint quadrature of a narrow lobe on the 5 degree
grid (a few per cent), a white reference whose stated albedo is off by 10-20 %, and the 1-3 %
noise of the readings. A reconstruction at 1.5 reflects half as much light again as falls on
it: no calibration or quadrature error explains that."""
PEAK_RATIO_LIMIT = 1.0e3
"""Largest projected table value ``f cos ti cos to`` over the largest projected reading above
which a table is out of bounds. A narrow highlight between the pairs legitimately peaks above
every reading: a GGX lobe of roughness alpha = 0.06 (polished brushed metal) has a projected
peak near 1/(4 pi alpha^2) ~ 22 1/sr while a pair 10 degrees off its mirror direction reads ~0.1
1/sr, a ratio of about 200. Three orders of magnitude is beyond what the readings can support;
the issue's blow-up was thirteen. The value itself, unprojected, is not bounded so: the same
lobe at grazing incidence peaks ``1 / (cos ti cos to)`` higher, 131 times at 85 degrees, where
the 5 degree grid's last row lies (docs/science.md 7.5: a plain solid paint's exact table is
4e3 times its largest reading there). A polished specimen whose mirror direction no pair comes
near can exceed the bound itself: such a result is flagged although its peak may be real,
since the readings cannot tell."""
INCIDENCE_DEG: tuple[float, ...] = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0)
"""Polar angles of incidence at which the directional albedo is integrated."""
INCIDENCE_AZIMUTH_DEG: tuple[float, ...] = (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0)
"""Azimuths of incidence (specimen frame): a brushed lobe's albedo depends on them."""
N_THETA_O, N_PHI_O = 30, 60
"""Midpoint-rule cells of the outgoing hemisphere (3 x 6 degrees)."""
SPECULAR_EXCLUDE_DEG = 7.5
"""Outgoing directions whose half vector is within this angle of the normal are left out of the
albedo. A 5 degree table samples a lobe narrower than its step at the nodes, and its
multilinear lookup spreads the node's peak over a whole step: a GGX mirror lobe of
alpha = 0.03 tabulated exactly integrates to an "albedo" of 6.4, alpha = 0.01 to 56. One and a
half steps around the mirror direction hold that part of any lobe; the rest of the hemisphere
is integrated faithfully (off the mirror cone the alpha = 0.03 lobe with a white Fresnel
term gives 0.10, alpha = 0.1 gives 0.47, a white Lambertian 0.93 at normal incidence to 0.99 at
75 degrees), so what is left is a lower bound of the true albedo that no physical table
exceeds, and the peak itself is bounded by :data:`PEAK_RATIO_LIMIT` instead."""


def projection_weight() -> FloatArray:
    """(18, 18, 36) ``cos theta_i cos theta_o`` of each slice cell of the grid, 0 where the
    light or the view is at or below the horizon (the cells no metric compares)."""
    ci, co = geo.cell_cosines(*geo.grid_angles())
    return np.where(geo.valid_mask(), ci * co, 0.0)


def projected_table_max(table: BRDFTable) -> float:
    """Largest finite ``f cos theta_i cos theta_o`` of ``table`` over its valid cells, channels
    and ``ph`` (its units); NaN when it has no finite valid value."""
    v = np.asarray(table.values)
    mask = geo.valid_mask()
    # Largest value of each slice cell over channels and ph first (fmax skips NaN): no copy.
    per_cell = np.fmax.reduce(v, axis=(0, 1))[mask].astype(float)
    if not np.isfinite(per_cell).any():
        return float("nan")
    return float(np.nanmax(per_cell * projection_weight()[mask]))


def projected_readings(readings: Any, cells: Any = None) -> FloatArray:
    """Readings times ``cos theta_i cos theta_o`` of their pair, finite ones only, flattened.

    Parameters
    ----------
    readings : array_like
        The readings, first axis one per pair (any shape after it; NaN ignored).
    cells : array_like or None
        (n_pairs, 3) pair cells ``(th, td, pd)`` in radians
        (:func:`gonio.brdf.reconstruction.reconstruct.pair_cells`). None: the geometry is not
        known and each reading counts as it is (``cos = 1``, its largest possible projection).

    Returns
    -------
    (N,) float array
    """
    r = np.asarray(readings, dtype=float)
    if cells is not None:
        c = np.asarray(cells, dtype=float).reshape(-1, 3)
        if r.ndim == 0 or r.shape[0] != c.shape[0]:
            raise ValueError(f"{c.shape[0]} pair cells for readings of shape {r.shape}: the "
                             "readings' first axis must be one per pair")
        ci, co = geo.cell_cosines(c[:, 0], c[:, 1], c[:, 2])
        r = r * (np.maximum(ci, 0.0) * np.maximum(co, 0.0)).reshape((-1,) + (1,) * (r.ndim - 1))
    r = r.reshape(-1)
    return r[np.isfinite(r)]


def peak_cap(readings: Any, cells: Any = None) -> FloatArray | None:
    """(18, 18, 36) cap of the peak bound per slice cell: :data:`PEAK_RATIO_LIMIT` times the
    largest projected reading (:func:`projected_readings`) over the cell's ``cos ti cos to``
    (infinite at the invalid cells). None when no reading is positive."""
    p = projected_readings(readings, cells)
    if not p.size or not p.max() > 0:
        return None
    w = projection_weight()
    with np.errstate(divide="ignore"):
        return np.where(w > 0, PEAK_RATIO_LIMIT * float(p.max()) / np.where(w > 0, w, 1.0),
                        np.inf)


def directional_albedo(table: BRDFTable,
                       theta_i_deg: tuple[float, ...] = INCIDENCE_DEG,
                       phi_i_deg: tuple[float, ...] = INCIDENCE_AZIMUTH_DEG,
                       exclude_deg: float = SPECULAR_EXCLUDE_DEG) -> FloatArray:
    """Directional-hemispherical reflectance of ``table`` at the given incidences.

    Parameters
    ----------
    table : BRDFTable, 1/sr (a table in sensor units gives sensor units x sr)
    theta_i_deg, phi_i_deg : incidence polar angles and azimuths, degrees (specimen frame)
    exclude_deg : float
        Half vectors within this angle of the normal are left out (:data:`SPECULAR_EXCLUDE_DEG`).

    Returns
    -------
    (len(theta_i_deg), len(phi_i_deg), C) array: ``sum f(wi, wo) cos(theta_o) dw`` over the
    midpoint cells of the outgoing hemisphere (:data:`N_THETA_O` x :data:`N_PHI_O`) whose half
    vector is at least :data:`SPECULAR_EXCLUDE_DEG` from the normal (the off-specular albedo,
    a lower bound of the directional albedo; ``exclude_deg=0`` integrates all of it): a
    Lambertian of albedo ``a`` gives ``a`` with ``exclude_deg=0`` (to the quadrature's 1e-3),
    and ``0.93 a`` at normal incidence to ``0.99 a`` at 75 degrees by default.
    NaN table cells count as 0.
    """
    dth, dph = 0.5 * math.pi / N_THETA_O, 2 * math.pi / N_PHI_O
    th = (np.arange(N_THETA_O) + 0.5) * dth
    ph = (np.arange(N_PHI_O) + 0.5) * dph
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    wo = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)],
                  axis=-1).reshape(-1, 3)
    # cos(theta_o) dw = cos sin dth dph for each midpoint cell.
    weight = (np.cos(tt) * np.sin(tt) * dth * dph).reshape(-1)
    ti = np.deg2rad(np.asarray(theta_i_deg, dtype=float))
    pi = np.deg2rad(np.asarray(phi_i_deg, dtype=float))
    wi = np.stack([np.sin(ti)[:, None] * np.cos(pi)[None, :],
                   np.sin(ti)[:, None] * np.sin(pi)[None, :],
                   np.broadcast_to(np.cos(ti)[:, None], (ti.size, pi.size))], axis=-1)
    wi = wi.reshape(-1, 3)
    n_o = wo.shape[0]
    big_i, big_o = np.repeat(wi, n_o, axis=0), np.tile(wo, (wi.shape[0], 1))
    f = table.eval(big_i, big_o)
    f = np.nan_to_num(np.asarray(f, dtype=float), nan=0.0).reshape(wi.shape[0], n_o, -1)
    h = big_i + big_o
    cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
    limit = math.cos(math.radians(exclude_deg)) if exclude_deg > 0 else 2.0  # 2: keep all
    off = (cos_h < limit).reshape(wi.shape[0], n_o)
    alb = np.einsum("ioc,io,o->ic", f, off.astype(float), weight)
    return alb.reshape(ti.size, pi.size, -1)


def peak_excess_log_rmse(table: BRDFTable, readings: Any, cells: Any = None) -> float:
    """``log_rmse`` of ``table`` against itself capped at the peak bound (:func:`peak_cap`:
    :data:`PEAK_RATIO_LIMIT` times the largest projected reading, over each cell's
    ``cos ti cos to``): 0 when no cell is above the cap.

    For a truth whose values stay within that cap this is a lower bound of the table's true
    ``log_rmse``: in every cell above the cap the truth is at or below it, so the cell's log
    difference is at least the one to the cap, and the other cells add nothing negative. The
    premise is an assumption (module docstring); cells the truth leaves unmeasured are not
    compared and void it there. Not unit-free: ``ln(1 + f cos ti)``.

    Parameters
    ----------
    table : BRDFTable
        The reconstruction (its units, 1/sr or sensor units).
    readings : array_like
        The readings it was fitted to, same units (first axis one per pair when ``cells`` is
        given; NaN ignored).
    cells : array_like or None
        (n_pairs, 3) pair cells of the readings (:func:`projected_readings`).

    Returns
    -------
    float
        ``log_rmse`` units (dimensionless), >= 0; NaN when no reading is positive.
    """
    from gonio.brdf.tables import metrics

    cap = peak_cap(readings, cells)
    if cap is None:
        return float("nan")
    return metrics.log_rmse_to_cap(table, cap)


@dataclass(frozen=True)
class BoundsCheck:
    """Whether a reconstruction is a possible material (module docstring).

    Attributes
    ----------
    worst_albedo : float
        Largest directional albedo over the incidences and channels (NaN when not computed:
        a table in sensor units has no albedo to compare with 1).
    worst_incidence_deg : (float, float)
        (theta_i, phi_i) of ``worst_albedo``, degrees.
    table_max : float
        Largest finite value of the table (its units).
    reading_max : float
        Largest reading the reconstruction was fitted to (same units); NaN when unknown.
    peak_ratio : float
        ``projected_max / projected_reading_max``, the ratio :data:`PEAK_RATIO_LIMIT` bounds;
        NaN when ``projected_reading_max`` is not positive.
    peak_excess_log_rmse : float
        :func:`peak_excess_log_rmse` of the table (``log_rmse`` units; 0 within the bound, NaN
        when not computed).
    """

    worst_albedo: float
    worst_incidence_deg: tuple[float, float]
    table_max: float
    reading_max: float
    peak_ratio: float
    peak_excess_log_rmse: float = float("nan")
    projected_max: float = float("nan")
    """Largest ``f cos ti cos to`` of the table (:func:`projected_table_max`)."""
    projected_reading_max: float = float("nan")
    """Largest reading times its pair's ``cos ti cos to`` (:func:`projected_readings`)."""

    @property
    def albedo_exceeded(self) -> bool:
        return bool(self.worst_albedo > ALBEDO_LIMIT)

    @property
    def peak_exceeded(self) -> bool:
        return bool(self.peak_ratio > PEAK_RATIO_LIMIT)

    @property
    def ok(self) -> bool:
        """Within both bounds (a NaN bound counts as not exceeded)."""
        return not (self.albedo_exceeded or self.peak_exceeded)

    def message(self) -> str | None:
        """What is out of bounds and what to do, or None when the table is within them."""
        if self.ok:
            return None
        why = []
        if self.albedo_exceeded:
            th, ph = self.worst_incidence_deg
            why.append("its directional albedo (off the mirror direction) reaches "
                       f"{self.worst_albedo:.3g} at incidence {th:g} deg (azimuth {ph:g} deg), "
                       f"above {ALBEDO_LIMIT:g} (a surface cannot reflect more light than falls "
                       "on it)")
        if self.peak_exceeded:
            excess = ""
            if np.isfinite(self.peak_excess_log_rmse) and self.peak_excess_log_rmse > 0:
                excess = (f"; what lies above that bound alone is {self.peak_excess_log_rmse:.3g} "
                          "in log_rmse, so predicted_log_rmse is at least that")
            why.append(f"its largest f cos(theta_i) cos(theta_o), {self.projected_max:.3g}, is "
                       f"{self.peak_ratio:.3g} times the largest reading's "
                       f"({self.projected_reading_max:.3g}), above {PEAK_RATIO_LIMIT:g}" + excess)
        return ("the reconstruction is outside physical bounds: " + "; ".join(why)
                + ". The readings do not determine the BRDF where it blows up: add stage "
                "angles or pairs, check the specimen's alignment and the calibration, and "
                "do not use this table without checking it")

    def as_dict(self) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None

        return {
            "ok": self.ok, "worst_albedo": num(self.worst_albedo),
            "worst_incidence_deg": list(self.worst_incidence_deg),
            "table_max": num(self.table_max), "reading_max": num(self.reading_max),
            "peak_ratio": num(self.peak_ratio), "projected_max": num(self.projected_max),
            "projected_reading_max": num(self.projected_reading_max),
            "peak_excess_log_rmse": num(self.peak_excess_log_rmse), "albedo_limit": ALBEDO_LIMIT,
            "peak_ratio_limit": PEAK_RATIO_LIMIT, "message": self.message(),
        }


def bounds_check(table: BRDFTable, readings: Any = None, *, cells: Any = None,
                 calibrated: bool = True, peak_excess: float | None = None) -> BoundsCheck:
    """Directional albedo and peak ratio of ``table`` against the readings it was fitted to.

    Parameters
    ----------
    table : BRDFTable
    readings : array_like or None
        The readings (NaN ignored), in the table's units; None: no peak ratio.
    cells : array_like or None
        (n_pairs, 3) pair cells ``(th, td, pd)`` of the readings, whose first axis is then one
        per pair: the peak ratio compares projected values (:func:`projected_readings`). None:
        each reading counts as it is.
    calibrated : bool
        The table is in 1/sr. False (sensor units): the albedo is not compared with 1 (it is
        left NaN); the peak ratio still applies, being unit-free.
    peak_excess : float, optional
        :func:`peak_excess_log_rmse` of this table and these readings when the caller has it
        already (a reconstruction's ``peak_excess_log_rmse``); computed when omitted.

    Returns
    -------
    BoundsCheck
    """
    vals = np.asarray(table.values, dtype=float)
    finite = vals[np.isfinite(vals)]
    table_max = float(finite.max()) if finite.size else float("nan")
    projected_max = projected_table_max(table)
    reading_max = projected_reading_max = float("nan")
    if readings is not None:
        r = np.asarray(readings, dtype=float)
        r = r[np.isfinite(r)]
        reading_max = float(r.max()) if r.size else float("nan")
        p = projected_readings(readings, cells)
        projected_reading_max = float(p.max()) if p.size else float("nan")
    ratio = (projected_max / projected_reading_max if projected_reading_max > 0
             else float("nan"))
    worst, where = float("nan"), (float("nan"), float("nan"))
    if calibrated:
        alb = directional_albedo(table)
        k = np.unravel_index(int(np.argmax(alb)), alb.shape)
        worst = float(alb[k])
        where = (INCIDENCE_DEG[k[0]], INCIDENCE_AZIMUTH_DEG[k[1]])
    excess = (float(peak_excess) if peak_excess is not None
              else peak_excess_log_rmse(table, readings, cells) if readings is not None
              else float("nan"))
    return BoundsCheck(worst, where, table_max, reading_max, ratio, excess, projected_max,
                       projected_reading_max)
