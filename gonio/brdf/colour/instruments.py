"""The measuring geometries of multi-angle spectrophotometers, as aspecular angles.

Multi-angle instruments light the specimen at a fixed incidence and read at aspecular angles:
the angle in the plane of incidence from the specular direction, positive toward the light
(ASTM E2194, DIN 6175-2). An aspecular angle ``a`` at incidence ``theta_i`` puts the sensor at
signed elevation ``theta_i - a`` on the specular side (negative: on the light's side). The sets
below are the in-plane geometries of :mod:`gonio.brdf.design.presets` (V&F Table 1) in that
form; a test checks the two agree. MA98's eight out-of-plane pairs have no aspecular angle and
are not part of the colour report.

The plane of incidence lies along the specimen's reference mark (specimen azimuth 0) unless an
azimuth is given: at other azimuths the same instrument reads an anisotropic specimen turned on
its holder, which is what the instrument itself cannot show.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.colour.conditions import ColourError

FloatArray = NDArray[np.float64]

#: (incidence deg, aspecular deg) of each instrument family's in-plane geometries.
INSTRUMENTS: dict[str, tuple[tuple[float, float], ...]] = {
    "MA68": ((45, 15), (45, 25), (45, 45), (45, 75), (45, 110)),
    "MA98": (
        (45, -15), (45, 15), (45, 25), (45, 45), (45, 75), (45, 110),
        (15, -45), (15, -15), (15, -5), (15, 45), (15, 80),
    ),
    "BYK-mac": ((45, -15), (45, 15), (45, 25), (45, 45), (45, 75), (45, 110)),
    "MultiFX10": (
        (45, -15), (45, 15), (45, 25), (45, 45), (45, 75), (45, 110),
        (15, -15), (15, 15), (65, -15), (65, 15),
    ),
}
#: The report's instruments when none are named.
DEFAULT_INSTRUMENTS: tuple[str, ...] = ("MA98", "BYK-mac")


@dataclass(frozen=True)
class Geometry:
    """One reading geometry of an instrument.

    Attributes
    ----------
    instrument : str
    incidence_deg : float
        Light's angle from the normal.
    aspecular_deg : float
        Sensor's angle from the specular direction, positive toward the light.
    azimuth_deg : float
        Specimen azimuth of the plane of incidence (0 = along the reference mark).
    """

    instrument: str
    incidence_deg: float
    aspecular_deg: float
    azimuth_deg: float = 0.0

    @property
    def name(self) -> str:
        """``"45as15"``-style label (incidence, aspecular) as instruments print them."""
        return f"{self.incidence_deg:g}as{self.aspecular_deg:g}"

    def directions(self) -> tuple[FloatArray, FloatArray]:
        """Light and sensor unit vectors (3,) each, in the specimen frame."""
        phi = np.deg2rad(self.azimuth_deg)
        ti = np.deg2rad(self.incidence_deg)
        light = np.array([np.sin(ti) * np.cos(phi), np.sin(ti) * np.sin(phi), np.cos(ti)])
        # Signed elevation on the specular side (azimuth phi + pi).
        tv = np.deg2rad(self.incidence_deg - self.aspecular_deg)
        view = np.array([-np.sin(tv) * np.cos(phi), -np.sin(tv) * np.sin(phi), np.cos(tv)])
        return light, view


def instrument_names() -> tuple[str, ...]:
    return tuple(INSTRUMENTS)


def _key(name: str) -> str:
    return "".join(ch for ch in name.lower() if ch.isalnum())


def canonical_instrument(name: str) -> str:
    """The known name for ``name`` (case, spaces and dashes ignored).

    Raises
    ------
    ColourError
        For an unknown instrument; the message lists the known ones.
    """
    for known in INSTRUMENTS:
        if _key(known) == _key(name):
            return known
    raise ColourError(
        f"unknown instrument {name!r}; known instruments are {', '.join(INSTRUMENTS)}"
    )


def geometries(instruments: Sequence[str] = DEFAULT_INSTRUMENTS,
               azimuths_deg: Sequence[float] = (0.0,)) -> tuple[Geometry, ...]:
    """Every geometry of the named instruments at each specimen azimuth, in that order; an
    instrument or azimuth named twice counts once."""
    if not instruments:
        raise ColourError(f"name at least one instrument ({', '.join(INSTRUMENTS)})")
    out: list[Geometry] = []
    for az in dict.fromkeys(float(a) for a in azimuths_deg):
        if not np.isfinite(az):
            raise ColourError(f"azimuth {az} is not a number of degrees")
        for name in dict.fromkeys(canonical_instrument(n) for n in instruments):
            out.extend(Geometry(name, float(i), float(a), float(az))
                       for i, a in INSTRUMENTS[name])
    return tuple(out)
