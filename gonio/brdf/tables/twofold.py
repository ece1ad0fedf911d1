"""How far a BRDF table is from twofold symmetry (a specimen that reads the same turned by half a
turn).

Turning a specimen by half a turn about its normal adds 180 deg to the azimuth of every
direction, so it adds 180 deg to the half vector's azimuth ``ph`` and leaves the difference
angles ``(th, td, pd)`` as they are (math.md 2). A twofold-symmetric table therefore has
``f(ph) = f(ph + 180 deg)`` cell by cell: on gonio's grid (72 slices of 5 deg) slice ``k`` equals
slice ``k + 36``. Its half-turn average ``(f(ph) + f(ph + 180 deg)) / 2`` is what any twofold
symmetric model (the principled GGX lobe of the glTF and MaterialX exports, a basis without odd
harmonics) can hold at best; :func:`twofold_asymmetry` says how much that loses, in the same
cosine-weighted log RMSE (:func:`gonio.brdf.tables.metrics.log_rmse`) the rest of gonio reports.

The test on the readings themselves, before any table exists, is
:func:`gonio.brdf.reconstruction.symmetry.twofold_test`.
"""

from __future__ import annotations

import numpy as np

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable

#: Slices between ``ph`` and ``ph + 180 deg`` on the table's grid.
HALF_TURN_SLICES = geo.N_PH // 2


def half_turn_average(table: BRDFTable) -> BRDFTable:
    """The table averaged with itself turned by half a turn: ``(f(ph) + f(ph + 180 deg)) / 2``.

    Parameters
    ----------
    table : BRDFTable
        Values of shape ``(C, 72, 18, 18, 36)``, 1/sr.

    Returns
    -------
    BRDFTable
        Same shape, channels and name; NaN where either slice is NaN (invalid cells are invalid
        in every slice, so this only matters for damaged tables).
    """
    v = np.asarray(table.values, dtype=float)
    turned = np.roll(v, -HALF_TURN_SLICES, axis=1)  # slice k holds slice k + 36
    return BRDFTable.trusted(0.5 * (v + turned), table.channels, table.name,
                             table.wavelengths_nm)


def twofold_asymmetry(table: BRDFTable) -> float:
    """Cosine-weighted log RMSE (dimensionless) between ``table`` and its half-turn average.

    0 for a twofold-symmetric table (every reconstruction made with a basis that holds only even
    harmonics along ``ph``, as the default one does); for comparison, a reconstruction's own
    error is typically 0.01 to 0.06 (docs/science.md).

    The same number as ``log_rmse(half_turn_average(table), table)``, summed one channel at a
    time: a 31-band table's whole-table temporaries took 1.6 GB and 1.8 s of every export of
    a spectral result; one channel's take a thirty-first of the memory.
    """
    v = np.asarray(table.values)
    mask = geo.valid_mask()
    cos_ti = metrics.cell_cos_ti()[mask]  # (valid cells,)
    weight = geo.volume_weight()[mask]
    total = weight_sum = 0.0
    for channel in v:
        f = np.asarray(channel[:, mask], dtype=np.float64)  # (72, valid cells)
        avg = 0.5 * (f + np.roll(f, -HALF_TURN_SLICES, axis=0))
        # Cells where either is not finite are left out, as by every metric here.
        ok = np.isfinite(f) & np.isfinite(avg)
        d = (np.log1p(np.maximum(np.where(ok, avg, 0.0), 0.0) * cos_ti)
             - np.log1p(np.maximum(np.where(ok, f, 0.0), 0.0) * cos_ti))
        w = np.where(ok, weight, 0.0)
        total += float(np.sum(w * d * d))
        weight_sum += float(np.sum(w))
    if weight_sum == 0.0:
        raise metrics.MetricError("the two tables share no finite valid cell")
    return float(np.sqrt(total / weight_sum))
