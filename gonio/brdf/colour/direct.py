"""Instrument geometries a scan measured directly (issue 28).

When one of a scan's pairs sits at an instrument geometry (a colour design puts pairs at the
near-specular ones, :mod:`gonio.brdf.design.colourtargets`; a preset rig has them all), the
rig has read the specimen at that geometry at every stage angle, which is the instrument's own
measurement. The table cannot reproduce it there as well: its 5 degree cells are wider than a
clear coat's gloss lobe, and the joint fit pulls a few readings of a peak toward the prior.

:func:`direct_values` therefore corrects the table's value at such a geometry by the readings
of its pair: at each stage angle ``alpha_j`` the pair read ``v_j`` where the table (read the
same way as the report reads it) gives ``t_j``; the log ratio ``log((v_j + f0) / (t_j + f0))``
is fitted over the stage angles by a constant plus the second harmonic ``cos 2 alpha``,
``sin 2 alpha`` (the slowest azimuthal change of a twofold-symmetric specimen; the constant
alone below 5 stage angles) and the fit, taken at the stage angle that turns the pair onto the
wanted specimen azimuth, multiplies the table's value. For an isotropic specimen that is the
readings' own mean at that geometry; for an anisotropic one the table's azimuthal shape,
scaled to the readings. The fit averages the readings' noise over the stage angles.

A pair matches a geometry when their half/difference angles ``th``, ``td``, ``pd`` agree within
:data:`MATCH_DEG` (the lab azimuth is free: the stage turns it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.conditions import ColourError
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

#: Largest difference of ``th``, ``td`` and ``pd`` (degrees) between a pair and a geometry it
#: is taken to measure (well below the table's 5 degree cells, above a rig's mounting slack).
MATCH_DEG = 0.25


@dataclass(frozen=True)
class ScanReadings:
    """What a scan read: its pairs' lab directions, stage angles and calibrated values.

    Attributes
    ----------
    light_dirs, sensor_dirs : (n, 3) arrays
        Lab-frame unit vectors of each pair at stage angle 0.
    stage_angles_deg : (r,) array, degrees
    values : (n, r, C) array, 1/sr
        BRDF read by each pair at each stage angle (NaN where a reading is missing).
    """

    light_dirs: FloatArray
    sensor_dirs: FloatArray
    stage_angles_deg: FloatArray
    values: FloatArray

    def __post_init__(self) -> None:
        li = np.asarray(self.light_dirs, dtype=float).reshape(-1, 3)
        so = np.asarray(self.sensor_dirs, dtype=float).reshape(-1, 3)
        al = np.asarray(self.stage_angles_deg, dtype=float).ravel()
        v = np.asarray(self.values, dtype=float)
        if li.shape != so.shape or v.ndim != 3 or v.shape[:2] != (li.shape[0], al.size):
            raise ColourError(
                f"scan readings need (n, 3) light and sensor directions and (n, r, C) values "
                f"for r stage angles; got {li.shape}, {so.shape}, {v.shape} and {al.size} "
                "angles")
        for name, arr in (("light_dirs", li), ("sensor_dirs", so), ("stage_angles_deg", al),
                          ("values", v)):
            object.__setattr__(self, name, arr)


LogLookup = Callable[[FloatArray, FloatArray], FloatArray]


def direct_values(lookup: LogLookup, light: ArrayLike, view: ArrayLike, table_values: ArrayLike,
                  scan: ScanReadings, offset: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The table's values at geometries, corrected by the readings of pairs measuring them.

    Parameters
    ----------
    lookup : callable
        ``lookup(wi, wo) -> (N, C)`` the table's BRDF at specimen-frame directions, as the
        report reads it.
    light, view : (G, 3) array_like
        The geometries, specimen frame.
    table_values : (G, C) array_like, 1/sr
        ``lookup(light, view)``.
    scan : ScanReadings
    offset : float, 1/sr
        The logarithm's offset ``f0`` (the report's lookup offset).

    Returns
    -------
    values : (G, C) array, 1/sr
    measured : (G,) bool
        Which geometries a pair measured (their values corrected).
    """
    li = np.asarray(light, dtype=float).reshape(-1, 3)
    vi = np.asarray(view, dtype=float).reshape(-1, 3)
    out = np.array(table_values, dtype=float)
    measured = np.zeros(li.shape[0], dtype=bool)
    if scan.light_dirs.shape[0] == 0:
        return out, measured
    g_th, g_ph, g_td, g_pd = geo.directions_to_half_diff(li, vi)
    p_th, p_ph, p_td, p_pd = geo.directions_to_half_diff(scan.light_dirs, scan.sensor_dirs)
    tol = math.radians(MATCH_DEG)
    alpha = np.deg2rad(scan.stage_angles_deg)
    for g in range(li.shape[0]):
        # pd is folded by half a turn in the table (reciprocity), so compare it modulo pi.
        dpd = np.abs((p_pd - g_pd[g] + np.pi / 2) % np.pi - np.pi / 2)
        hit = np.flatnonzero((np.abs(p_th - g_th[g]) <= tol) & (np.abs(p_td - g_td[g]) <= tol)
                             & (dpd <= tol))
        for p in hit:
            ratio = _log_ratio_at(lookup, scan, int(p), alpha, float(p_ph[p] - g_ph[g]), offset)
            if ratio is None:
                continue
            out[g] = np.maximum((out[g] + offset) * np.exp(ratio) - offset, 0.0)
            measured[g] = True
            break
    return out, measured


def _log_ratio_at(lookup: LogLookup, scan: ScanReadings, p: int, alpha: FloatArray,
                  at: float, offset: float) -> FloatArray | None:
    """(C,) the fitted log ratio of pair ``p``'s readings to the table at stage angle ``at``
    (radians); None when the pair has fewer than one complete reading."""
    wi = geo.lab_to_specimen(scan.light_dirs[p][None, :], alpha[:, None])
    wo = geo.lab_to_specimen(scan.sensor_dirs[p][None, :], alpha[:, None])
    table = lookup(wi.reshape(-1, 3), wo.reshape(-1, 3))
    v = scan.values[p]
    ok = np.isfinite(v).all(axis=1) & np.isfinite(table).all(axis=1)
    if not ok.any():
        return None
    rho = np.log(np.maximum(v[ok], 0.0) + offset) - np.log(np.maximum(table[ok], 0.0) + offset)
    a = alpha[ok]
    if a.size >= 5:
        # Stage angle alpha turns the specimen so the pair reads specimen azimuth ph - alpha;
        # the wanted azimuth is reached at alpha = ph_pair - ph_geometry.
        X = np.stack([np.ones_like(a), np.cos(2 * a), np.sin(2 * a)], axis=1)
        coef, *_ = np.linalg.lstsq(X, rho, rcond=None)
        return np.asarray(np.array([1.0, math.cos(2 * at), math.sin(2 * at)]) @ coef)
    return np.asarray(rho.mean(axis=0))
