"""Is the reconstruction's highlight read by any pair? (issue 23 item 4: the result says why).

A scan reads a few dozen directions. Where the reconstructed table peaks, its highlight, there
may be no reading at all: then the highlight's height, width and (over a coloured body) colour
are the prior's extrapolation from the lobe's tail, not the specimen's
(docs/notes/2026-11-27-red-highlight.md: a red paint's white highlight reconstructed cyan at a
fifth to a half of its height, the nearest pair 7 degrees of ``th`` from it).

:func:`highlight_read` says, from the scan alone (no truth), where the table's brightest cell
is, in half-vector terms, and how near the nearest reading comes to it:

* the **peak**: the valid cell with the largest projected value ``f cos ti cos to`` (mean over
  channels), as the physical bounds locate it (:mod:`gonio.brdf.tables.bounds`: the projection
  keeps a lobe's grazing rows from outranking its mirror direction);
* its **half vector** ``(th, ph)`` (specimen frame), and each reading's half vector: the pair's
  ``th`` and ``ph_lab - alpha`` at each stage angle ``alpha``;
* **nearest**: the angle between the peak's half vector and the nearest reading's, degrees;
* **excess**: the projected peak over the largest projected reading (mean over channels).

One sentence for a lab: *the reconstruction's highlight is M times brighter than anything the
scan read, so its height, width and colour are the prior's guess.*

The warning (:meth:`HighlightRead.message`) is ``excess`` above :data:`EXCESS_LIMIT`, with
the peak looked for at ``td`` up to :data:`TD_MAX_DEG`. The half-vector distances are kept
for the message and the metrics but do not decide: on the benches every layout reads a half
vector within 2.5-7 degrees of the normal, where nearly every peak lies, but at another
``td``, and the distance did not tell right highlights from wrong ones
(docs/notes/2026-11-28-highlight-read.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.bounds import projection_weight
from gonio.brdf.tables.table import BRDFTable

TD_MAX_DEG = 45.0
"""The highlight is looked for at difference angles ``td`` up to this, degrees: where the
standard renderings (``td`` 10-35) and a lab's usual geometries look. Over every cell the
projected peak of a measured material lies in its grazing rows (``td`` 75-85), which no
rendering shows and a 5 degree table holds poorly."""
EXCESS_LIMIT = 3.4
"""Projected peak over the largest projected reading above which the highlight is said not to
be read. Chosen on bench_peakread's choice set (33 scans: 7 of 11 with a peak more than 2x off
in some channel flagged, 1 of 22 others) and checked once on its test and fresh sets (63
scans: 9 of 14 and 2 of 49; docs/notes/2026-11-28-highlight-read.md); the rule's threshold
was 3.407, no scan lies between."""


@dataclass(frozen=True)
class HighlightRead:
    """Where a reconstruction peaks and how near the readings come (:func:`highlight_read`).

    Attributes
    ----------
    peak_th_deg, peak_ph_deg, peak_td_deg, peak_pd_deg : float
        The grid cell of the table's largest projected value (mean over channels), degrees.
    nearest_deg : float
        Angle between that cell's half vector and the nearest reading's half vector, degrees.
    excess : float
        The projected peak over the largest projected reading (mean over channels); NaN when
        no reading is positive.
    nearest_td_deg : float
        The nearest reading in half vector and ``td`` together: the smallest
        ``sqrt(angle(h)^2 + (td_peak - td_reading)^2)``, degrees.
    """

    peak_th_deg: float
    peak_ph_deg: float
    peak_td_deg: float
    peak_pd_deg: float
    nearest_deg: float
    excess: float
    nearest_td_deg: float = float("nan")

    @property
    def flagged(self) -> bool:
        """Whether the table peaks more than :data:`EXCESS_LIMIT` times above every reading."""
        return bool(self.excess > EXCESS_LIMIT)

    def message(self) -> str | None:
        """The warning a result carries when :attr:`flagged`; None otherwise."""
        if not self.flagged:
            return None
        return (f"the highlight is not read: the reconstruction peaks {self.excess:.3g} times "
                "above the brightest reading (both times cos(theta_i) cos(theta_o); half "
                f"vector th {self.peak_th_deg:.0f}, ph {self.peak_ph_deg:.0f}, td "
                f"{self.peak_td_deg:.0f} degrees, the nearest reading's half vector "
                f"{self.nearest_deg:.1f} degrees away), so the highlight's height, width and "
                "colour are the prior's extrapolation, not the specimen's; read a pair near "
                "its mirror direction to measure it")

    def as_metrics(self) -> dict[str, float | None]:
        """The numbers every result stores (NaN as None)."""
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"highlight_excess": num(self.excess),
                "highlight_nearest_deg": num(self.nearest_deg),
                "highlight_peak_th_deg": num(self.peak_th_deg),
                "highlight_peak_ph_deg": num(self.peak_ph_deg),
                "highlight_peak_td_deg": num(self.peak_td_deg)}


def _half_vector(th: Any, ph: Any) -> np.ndarray:
    th, ph = np.asarray(th, dtype=float), np.asarray(ph, dtype=float)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)


def highlight_read(table: BRDFTable, cells: Any, ph_lab: Any, stage_angles: Any,
                   values: Any, td_max_deg: float | None = TD_MAX_DEG) -> HighlightRead:
    """Where ``table`` peaks and how near the scan's readings come to it.

    Parameters
    ----------
    table : BRDFTable
        The reconstruction, ``(C, 72, 18, 18, 36)``.
    cells : array_like
        ``(n, 3)`` pair cells ``(th, td, pd)``, radians (specimen frame).
    ph_lab : array_like
        ``(n,)`` each pair's lab ``ph``, radians.
    stage_angles : array_like
        ``(r,)`` stage angles, radians.
    values : array_like
        ``(n, r, C)`` readings, same units as ``table`` (NaN ignored).
    td_max_deg : float or None
        Look for the peak only at ``td`` up to this (degrees; :data:`TD_MAX_DEG`); None:
        every valid cell.

    Returns
    -------
    HighlightRead
    """
    c = np.asarray(cells, dtype=float).reshape(-1, 3)
    ph_l = np.asarray(ph_lab, dtype=float).reshape(-1)
    alpha = np.asarray(stage_angles, dtype=float).reshape(-1)
    v = np.asarray(values, dtype=float)
    v = v.reshape(c.shape[0], alpha.size, -1)
    w = projection_weight()
    mean = np.mean(np.asarray(table.values, dtype=float), axis=0)  # (72, 18, 18, 36)
    keep = w > 0
    if td_max_deg is not None:
        keep = keep & (np.rad2deg(geo.TD_GRID)[None, :, None] <= td_max_deg + 1e-9)
    with np.errstate(invalid="ignore"):
        proj = np.where(keep[None] & np.isfinite(mean), mean * w[None], -np.inf)
    i_ph, i_th, i_td, i_pd = np.unravel_index(int(np.argmax(proj)), proj.shape)
    peak = float(proj[i_ph, i_th, i_td, i_pd])
    h_peak = _half_vector(geo.TH_GRID[i_th], geo.PH_GRID[i_ph])
    ph_read = geo.stage_shifted_ph(ph_l[:, None], alpha[None, :])  # (n, r)
    h_read = _half_vector(np.broadcast_to(c[:, :1], ph_read.shape), ph_read)
    read_ok = np.isfinite(v).any(axis=-1)
    cosang = np.clip(h_read[read_ok] @ h_peak, -1.0, 1.0)
    nearest = math.degrees(math.acos(float(cosang.max()))) if cosang.size else float("nan")
    ang = np.degrees(np.arccos(cosang))
    dtd = np.rad2deg(geo.TD_GRID[i_td]) - np.rad2deg(np.broadcast_to(c[:, 1:2], ph_read.shape)
                                                    [read_ok])
    nearest_td = float(np.sqrt(ang ** 2 + dtd ** 2).min()) if ang.size else float("nan")
    ci, co = geo.cell_cosines(c[:, 0], c[:, 1], c[:, 2])
    pv = np.mean(v, axis=-1) * (np.maximum(ci, 0.0) * np.maximum(co, 0.0))[:, None]
    top = float(np.nanmax(pv)) if np.isfinite(pv).any() else float("nan")
    excess = peak / top if top > 0 else float("nan")
    return HighlightRead(
        peak_th_deg=float(np.rad2deg(geo.TH_GRID[i_th])),
        peak_ph_deg=float(np.rad2deg(geo.PH_GRID[i_ph])),
        peak_td_deg=float(np.rad2deg(geo.TD_GRID[i_td])),
        peak_pd_deg=float(np.rad2deg(geo.PD_GRID[i_pd])),
        nearest_deg=nearest, excess=excess, nearest_td_deg=nearest_td)
