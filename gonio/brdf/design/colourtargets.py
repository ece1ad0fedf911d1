"""Geometries a colour lab reads, as a design asks for them (issue 28).

A lab that asks for colour numbers reads them at a multi-angle instrument's geometries
(aspecular angles at fixed incidences, :mod:`gonio.brdf.colour.instruments`). The expected-error
design (:mod:`gonio.brdf.design.posterior`) knows nothing of them: it spreads the pairs over
the whole table, and the gloss peak near the specular direction, where the colour of metallic
and clear-coated specimens changes fastest, is then the prior's. :class:`ColourTargets` is what
the design needs to do better, given as direction pairs (the design does not know instruments;
the caller turns an instrument name into directions):

* **direct pairs**: every target geometry whose half vector lies within
  :attr:`ColourTargets.direct_within_deg` of the normal becomes one of the designed pairs, at
  exactly that geometry. Near the specular direction a clear coat's lobe is narrower than the
  table's 5 degree cells, so even the true material tabulated on the grid is read there up to
  2.6 ΔE00 off (docs/colour.md); a pair at the geometry reads it directly, and the colour
  report uses that reading (:mod:`gonio.brdf.colour.direct`).
* **weighted error**: the rest of the pairs minimise the expected error of the table plus
  :attr:`ColourTargets.weight` times the expected error at the target geometries (the basis
  rows there, :meth:`~gonio.brdf.reconstruction.basis.Basis.rows_at`), scaled so that under the
  prior the two terms are equal for ``weight = 1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.errors import DesignError
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

#: How much the target geometries' expected error counts against the whole table's
#: (``bench/bench_colour.py --colour-design --colour-weight W`` on its choice set: 0, 1, 3, 10,
#: 30 and 100 measured; 100 chosen by the lowest worst MA98 ΔE00 at 10 pairs, then tested once
#: on a third set; docs/colour.md gives the tables and which set saw which choice).
DEFAULT_COLOUR_WEIGHT = 100.0
#: The largest colour weight a request, a rig config or ``gonio design`` accepts (config.py
#: repeats it: the config layer may not import the design room).
MAX_COLOUR_WEIGHT = 1000.0
#: Targets with the half vector within this angle of the normal get a pair of their own:
#: aspecular angles up to 25 degrees (the half vector sits at half the aspecular angle).
DEFAULT_DIRECT_WITHIN_DEG = 12.5


@dataclass(frozen=True)
class ColourTargets:
    """Geometries whose colour the lab will read, and how the design treats them.

    Attributes
    ----------
    light, view : (G, 3) arrays
        Unit vectors toward the light and the sensor, specimen frame.
    weight : float, >= 0
        Weight of the target geometries' expected error (module notes).
    direct_within_deg : float, >= 0
        Targets whose half vector is within this angle (degrees) of the normal are measured by
        a pair of their own.
    """

    light: FloatArray
    view: FloatArray
    weight: float = DEFAULT_COLOUR_WEIGHT
    direct_within_deg: float = DEFAULT_DIRECT_WITHIN_DEG

    def __post_init__(self) -> None:
        li = np.asarray(self.light, dtype=float)
        vi = np.asarray(self.view, dtype=float)
        if li.ndim != 2 or li.shape[1] != 3 or li.shape != vi.shape or li.shape[0] == 0:
            raise DesignError(
                f"colour targets need (G, 3) light and view directions of the same shape, "
                f"G >= 1; got {li.shape} and {vi.shape}")
        norms = np.concatenate([np.linalg.norm(li, axis=1), np.linalg.norm(vi, axis=1)])
        if not np.isfinite(norms).all() or np.abs(norms - 1.0).max() > 1e-6:
            raise DesignError("colour target directions must be finite unit vectors")
        if (li[:, 2] <= 0).any() or (vi[:, 2] <= 0).any():
            raise DesignError("colour target directions must lie above the specimen (z > 0)")
        if not (math.isfinite(self.weight) and self.weight >= 0):
            raise DesignError(
                f"the colour weight must be a number >= 0 (0: only the direct pairs), got "
                f"{self.weight}")
        if not (math.isfinite(self.direct_within_deg) and 0 <= self.direct_within_deg <= 90):
            raise DesignError(
                f"direct_within_deg must be in 0..90 degrees, got {self.direct_within_deg}")
        object.__setattr__(self, "light", li)
        object.__setattr__(self, "view", vi)

    def cells(self) -> tuple[FloatArray, FloatArray]:
        """``(th, td, pd)`` (G, 3) radians and half-vector azimuths ``ph`` (G,) of the targets."""
        th, ph, td, pd = geo.directions_to_half_diff(self.light, self.view)
        return np.stack([th, td, pd], axis=1), np.asarray(ph, dtype=float)

    def direct(self) -> NDArray[np.bool_]:
        """(G,) which targets get a pair of their own (half vector within the limit)."""
        th = self.cells()[0][:, 0]
        return np.asarray(th <= math.radians(self.direct_within_deg) + 1e-9)


def colour_gram(rows: ArrayLike) -> FloatArray:
    """(K, K) ``sum_g q_g q_g^T`` over the target geometries' basis rows ``q_g`` ((G, K)).

    The expected squared error of the remapped values at the targets is ``tr(Wc Sigma)``; the
    remapped value is the logarithm of the BRDF wherever it is well above the basis' ``eps``
    (near the specular direction, where colour is most sensitive), and a colour's ΔE grows with
    that logarithm's error.
    """
    Q = np.atleast_2d(np.asarray(rows, dtype=float))
    return np.asarray(Q.T @ Q)
