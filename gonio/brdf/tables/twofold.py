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
    """
    return metrics.log_rmse(half_turn_average(table), table)
