"""Industrial multi-angle geometries as pair designs (V&F Sec. 7, Table 1).

Four commercial multi-angle reflectometers, given in the standard BRDF parametrization
``(theta_i, phi_i, theta_v, phi_v)`` in degrees (V&F Table 1, after [PCVMV13]): light and
sensor directions, both pointing away from the surface, with azimuths in the same lab frame
(so ``phi_v = phi_i`` puts the sensor on the light's side). The in-plane rows are the ASTM /
DIN aspecular geometries; MA98 adds eight out-of-plane pairs.

Each preset converts to half/difference cells ``(th, td, pd)`` and lab half-vector azimuths
``ph`` with the same map as every other pair (math.md 2), so it can be evaluated and reconstructed
exactly like an optimized design. The cells are off the 5 degree grid; basis rows there are
trilinear blends (math.md 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]


class UnknownPresetError(ValueError):
    """A preset name that is not one of :func:`preset_names`."""


# ASTM E2194 / DIN 6175-2 in-plane geometries shared by all four devices: light at 45 deg,
# sensor at aspecular angles 45, 75, 110, 25 and 15 deg.
_CORE = ((45, 0, 0, 0), (45, 0, 30, 0), (45, 0, 65, 0), (45, 0, 20, 180), (45, 0, 30, 180))

_TABLE: dict[str, tuple[str, tuple[tuple[float, float, float, float], ...]]] = {
    "MA68": ("X-Rite MA68 (5 in-plane pairs)", _CORE),
    "MA98": (
        "X-Rite MA98 (11 in-plane and 8 out-of-plane pairs)",
        (
            *_CORE,
            (45, 0, 60, 180),
            (15, 0, 30, 0),
            (15, 0, 65, 0),
            (15, 0, 20, 180),
            (15, 0, 30, 180),
            (15, 0, 60, 180),
            (15, 0, 50, 33),
            (15, 0, 50, 327),
            (15, 0, 45, 90),
            (15, 0, 45, 270),
            (45, 0, 50, 33),
            (45, 0, 50, 327),
            (45, 0, 45, 90),
            (45, 0, 45, 270),
        ),
    ),
    "BYK-mac": ("BYK-Gardner BYK-mac (6 in-plane pairs)", (*_CORE, (45, 0, 60, 180))),
    "MultiFX10": (
        "Datacolor MultiFX10 (10 in-plane pairs)",
        (
            *_CORE,
            (45, 0, 60, 180),
            (15, 0, 0, 180),
            (15, 0, 30, 180),
            (65, 0, 50, 180),
            (65, 0, 80, 180),
        ),
    ),
}


@dataclass(frozen=True)
class Preset:
    """One industrial geometry.

    Attributes
    ----------
    name : str
        Short name (``MA68``, ``MA98``, ``BYK-mac``, ``MultiFX10``).
    description : str
        Maker and model with the pair counts.
    lab_deg : (n, 4) array, degrees
        ``(theta_i, phi_i, theta_v, phi_v)`` of each pair.
    """

    name: str
    description: str
    lab_deg: FloatArray

    @property
    def n_pairs(self) -> int:
        return int(self.lab_deg.shape[0])

    def directions(self) -> tuple[FloatArray, FloatArray]:
        """Light and sensor unit vectors, each (n, 3), in the lab frame."""
        r = np.deg2rad(self.lab_deg)
        return (
            geo.spherical_to_direction(r[:, 0], r[:, 1]),
            geo.spherical_to_direction(r[:, 2], r[:, 3]),
        )

    def cells(self) -> tuple[FloatArray, FloatArray]:
        """Half/difference cells of the pairs.

        Returns
        -------
        cells : (n, 3) array, radians
            ``(th, td, pd)`` of each pair (off-grid in general).
        ph_lab : (n,) array, radians
            Lab half-vector azimuth of each pair (0 where ``th = 0``).
        """
        wi, wo = self.directions()
        th, ph, td, pd = geo.directions_to_half_diff(wi, wo)
        return np.stack([th, td, pd], axis=1), ph


def _key(name: str) -> str:
    return "".join(ch for ch in name.lower() if ch.isalnum())


def preset_names() -> tuple[str, ...]:
    """Names of the known presets, in Table 1 order."""
    return tuple(_TABLE)


def get_preset(name: str) -> Preset:
    """The preset called ``name`` (case, spaces and dashes ignored: ``byk mac`` works).

    Raises
    ------
    UnknownPresetError
        For an unknown name; the message lists the known presets.
    """
    wanted = _key(name)
    for key, (description, rows) in _TABLE.items():
        if _key(key) == wanted:
            return Preset(key, description, np.array(rows, dtype=float))
    raise UnknownPresetError(
        f"unknown preset {name!r}; known presets are {', '.join(preset_names())}"
    )
