"""Spectral specimens for the simulator and the colour benchmark.

A spectral specimen is an analytic BRDF (:mod:`gonio.brdf.models.analytic`) evaluated at every
wavelength of the colour grid (:data:`gonio.brdf.colour.conditions.GRID_NM`, 360-780 nm every
10 nm) and read through a spectral sensor's bands: ``f_band = sum_g A[band, g] f(lambda_g)``
(:meth:`gonio.brdf.colour.spectral.SpectralBands.read`). The spectral BRDF itself stays
available (:meth:`SpectralSpecimen.spectral_eval`), so the true colour of the material at any
geometry can be computed without the bands, the reference the colour benchmark compares with.

Materials (``SPECTRAL_MATERIALS``):

- coloured diffuse and coated materials from measured spectral reflectances: the 24 ColorChecker
  patches as colour-science ships them (Ohta's measurements), under a clear coat (a dielectric
  GGX lobe, n = 1.5) or a plastic's broader specular lobe;
- metallic paints: aluminium flakes (a broad conductor GGX lobe) tinted by a pigment's
  reflectance, a diffuse pigment base and a clear coat;
- spectral conductors from complex refractive indices ``n + ik`` per wavelength: aluminium,
  copper, gold; brushed (anisotropic roughness) and anodised (aluminium under a dye layer whose
  transmission, squared for the way in and out, tints the reflection).

The optical constants are approximate values at 50 nm steps after Johnson & Christy (1972, Cu,
Au) and Rakić (1995, Al), interpolated linearly; they make metals of the right hue, not a
reference for optics.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.conditions import GRID_NM, resample
from gonio.brdf.colour.spectral import SpectralBands
from gonio.brdf.models.analytic import (
    GGX,
    ConductorFresnel,
    DielectricFresnel,
    Lambert,
    LobeSum,
)

FloatArray = NDArray[np.float64]

#: A spectrometer's 31 bands, 400-700 nm every 10 nm, 10 nm wide.
SPECTROMETER_31 = SpectralBands(tuple(np.arange(400.0, 701.0, 10.0)),
                                tuple(np.full(31, 10.0)))
#: An 11-channel visible spectral sensor chip (centres and widths of a typical datasheet).
CHIP_11 = SpectralBands((405, 425, 450, 475, 515, 550, 555, 600, 640, 690, 745),
                        (30, 22, 55, 30, 40, 35, 100, 40, 50, 55, 60))

_WL_NK = np.array([400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0])
#: (n, k) at ``_WL_NK``: approximate optical constants (module docstring).
_CONDUCTORS: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "aluminium": ((0.49, 0.62, 0.77, 0.96, 1.20, 1.47, 1.83),
                  (4.86, 5.47, 6.08, 6.69, 7.26, 7.79, 8.31)),
    "copper": ((1.18, 1.24, 1.12, 1.02, 0.27, 0.21, 0.21),
               (2.21, 2.40, 2.56, 2.58, 3.42, 3.67, 4.05)),
    "gold": ((1.66, 1.40, 0.97, 0.43, 0.25, 0.17, 0.16),
             (1.96, 1.88, 1.87, 2.46, 2.98, 3.60, 3.95)),
}


def conductor_fresnel(metal: str) -> ConductorFresnel:
    """Fresnel of ``metal`` on the colour grid (constant beyond 400-700 nm)."""
    n, k = (np.interp(GRID_NM, _WL_NK, np.asarray(v)) for v in _CONDUCTORS[metal])
    return ConductorFresnel(tuple(n), tuple(k))


@functools.lru_cache(maxsize=1)
def _colorchecker() -> dict[str, FloatArray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour

        sds = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    return {name: resample(np.asarray(sd.wavelengths, float), np.asarray(sd.values, float))
            for name, sd in sds.items()}


def reflectance(patch: str) -> FloatArray:
    """(G,) reflectance of a ColorChecker patch on the colour grid; ``"a + b"`` is the mean of
    patches ``a`` and ``b`` (a colour no chart patch has, for the held-out specimens)."""
    return np.mean([_colorchecker()[p.strip()] for p in patch.split(" + ")], axis=0)


_CH = tuple(f"{w:g}" for w in GRID_NM)


def _lambert(r: ArrayLike) -> Lambert:
    return Lambert(tuple(np.clip(np.broadcast_to(np.asarray(r, float), GRID_NM.shape), 0.0, 1.0)),
                   channels=_CH)


def _coat(alpha: float) -> GGX:
    return GGX(alpha, alpha, DielectricFresnel(1.5), channels=_CH)


def _metal(metal: str, ax: float, ay: float) -> GGX:
    return GGX(ax, ay, conductor_fresnel(metal), channels=_CH)


def _sum(name: str, lobes: list[Any], weights: list[ArrayLike]) -> LobeSum:
    return LobeSum(tuple(lobes), [tuple(np.broadcast_to(np.asarray(w, float), GRID_NM.shape))
                                  for w in weights], channels=_CH, name=name)


def _solid_paint(patch: str, coat_alpha: float = 0.06) -> Callable[[], LobeSum]:
    # The clear coat reflects about 4 % at normal incidence; the pigment below sees the rest.
    return lambda: _sum(f"solid paint ({patch})",
                        [_lambert(reflectance(patch)), _coat(coat_alpha)], [0.96, 1.0])


def _metallic_paint(patch: str, flake_alpha: float) -> Callable[[], LobeSum]:
    def make() -> LobeSum:
        tint = reflectance(patch)
        return _sum(f"metallic paint ({patch})",
                    [_lambert(0.3 * tint), _metal("aluminium", flake_alpha, flake_alpha),
                     _coat(0.06)],
                    [1.0, 0.35 * np.clip(tint / tint.max(), 0.05, 1.0), 1.0])
    return make


def _plastic(patch: str, alpha: float) -> Callable[[], LobeSum]:
    return lambda: _sum(f"plastic ({patch})", [_lambert(reflectance(patch)), _coat(alpha)],
                        [0.95, 1.0])


def _anodised(patch: str, alpha: float = 0.18) -> Callable[[], LobeSum]:
    def make() -> LobeSum:
        dye = np.clip(reflectance(patch) / reflectance(patch).max(), 0.02, 1.0)
        return _sum(f"anodised aluminium ({patch})",
                    [_metal("aluminium", alpha, alpha), _lambert(0.08 * dye), _coat(0.08)],
                    [dye, 1.0, 0.5])
    return make


def _brushed(metal: str, ax: float = 0.08, ay: float = 0.30) -> Callable[[], LobeSum]:
    return lambda: _sum(f"brushed {metal}", [_metal(metal, ax, ay), _lambert(0.02)],
                        [1.0, 1.0])


#: name -> maker of the spectral BRDF (channels: the colour grid's wavelengths).
SPECTRAL_MATERIALS: dict[str, Callable[[], LobeSum]] = {
    "solid-red-paint": _solid_paint("red"),
    "solid-blue-paint": _solid_paint("blue"),
    "metallic-blue-paint": _metallic_paint("blue", 0.25),
    "metallic-silver-paint": _metallic_paint("neutral 8 (.23 D)", 0.20),
    "metallic-green-paint": _metallic_paint("green", 0.30),
    "anodised-red-aluminium": _anodised("red"),
    "anodised-gold-aluminium": _anodised("orange yellow"),
    "brushed-aluminium": _brushed("aluminium"),
    "brushed-copper": _brushed("copper"),
    "yellow-plastic": _plastic("yellow", 0.12),
    "green-plastic": _plastic("bluish green", 0.30),
}

#: Held-out specimens of the same five families with other colours (some no chart patch has),
#: coat and flake roughnesses, dyes and metals: the colour benchmark's validation set
#: (``bench_colour.py --set validation``), on which nothing is chosen. Not offered by the
#: simulator's ``--material``.
VALIDATION_MATERIALS: dict[str, Callable[[], LobeSum]] = {
    "solid-orange-paint": _solid_paint("orange", coat_alpha=0.05),
    "solid-purple-paint": _solid_paint("purple + magenta", coat_alpha=0.08),
    "metallic-red-paint": _metallic_paint("moderate red", 0.22),
    "metallic-cyan-paint": _metallic_paint("blue sky + cyan", 0.35),
    "metallic-bronze-paint": _metallic_paint("dark skin", 0.28),
    "anodised-blue-aluminium": _anodised("purplish blue", alpha=0.15),
    "anodised-green-aluminium": _anodised("yellow green + green", alpha=0.22),
    "brushed-gold": _brushed("gold", 0.10, 0.25),
    "brushed-copper-fine": _brushed("copper", 0.06, 0.20),
    "purple-plastic": _plastic("purple", 0.20),
    "orange-plastic": _plastic("orange + yellow", 0.40),
}

#: A third set, held out of every choice made on the other two: other hues (cyan, a dark green,
#: a near black, magenta, a gold tint, charcoal, blue flower, white; several mixtures), other
#: coat, flake and dye roughnesses (clear coats GGX alpha 0.065 and 0.07, flakes 0.18, 0.24,
#: 0.32, anodising 0.16 and 0.20, plastics 0.15, 0.18, 0.25) and metals brushed otherwise
#: (coarse aluminium, fine gold): ``bench_colour.py --set validation2``, written before the
#: benchmark first ran on it. Not offered by the simulator's ``--material``.
VALIDATION2_MATERIALS: dict[str, Callable[[], LobeSum]] = {
    "solid-cyan-paint": _solid_paint("cyan", coat_alpha=0.07),
    "solid-foliage-paint": _solid_paint("foliage", coat_alpha=0.065),
    "solid-black-paint": _solid_paint("black 2 (1.5 D) + neutral 3.5 (1.05 D)", coat_alpha=0.07),
    "metallic-magenta-paint": _metallic_paint("magenta", 0.24),
    "metallic-gold-paint": _metallic_paint("orange yellow + yellow", 0.32),
    "metallic-charcoal-paint": _metallic_paint("neutral 3.5 (1.05 D)", 0.18),
    "anodised-purple-aluminium": _anodised("purple", alpha=0.20),
    "anodised-cyan-aluminium": _anodised("cyan + blue sky", alpha=0.16),
    "brushed-aluminium-coarse": _brushed("aluminium", 0.12, 0.35),
    "brushed-gold-fine": _brushed("gold", 0.06, 0.15),
    "blue-flower-plastic": _plastic("blue flower", 0.15),
    "red-plastic": _plastic("red + orange", 0.25),
    "white-plastic": _plastic("white 9.5 (.05 D)", 0.18),
}


@dataclass(frozen=True)
class SpectralSpecimen:
    """A spectral BRDF read through a spectral sensor's bands.

    Attributes
    ----------
    model : analytic BRDF whose channels are :data:`GRID_NM` (one per wavelength)
    bands : SpectralBands of the sensor
    name : str
    """

    model: Any
    bands: SpectralBands
    name: str

    @property
    def channels(self) -> tuple[str, ...]:
        """One name per band: its centre, ``"550nm"``."""
        return tuple(f"{c:g}nm" for c in self.bands.centres_nm)

    @property
    def wavelengths_nm(self) -> tuple[float, ...]:
        return self.bands.centres_nm

    def spectral_eval(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """(..., G) BRDF at every colour-grid wavelength, 1/sr."""
        return np.asarray(self.model.eval(wi, wo), dtype=float)

    def eval(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """(..., C) BRDF as the bands read it, 1/sr."""
        return self.bands.read(self.spectral_eval(wi, wo))


def spectral_specimen(name: str, bands: SpectralBands = SPECTROMETER_31,
                      materials: dict[str, Callable[[], LobeSum]] | None = None
                      ) -> SpectralSpecimen:
    """The spectral material ``name`` read through ``bands``.

    ``materials``: where ``name`` is looked up (default :data:`SPECTRAL_MATERIALS`; the colour
    benchmark passes :data:`VALIDATION_MATERIALS` and :data:`VALIDATION2_MATERIALS` for its
    held-out sets).

    Raises
    ------
    ValueError
        For an unknown name; the message lists the known ones.
    """
    known = SPECTRAL_MATERIALS if materials is None else materials
    make = known.get(name)
    if make is None:
        raise ValueError(f"unknown spectral material {name!r}; known: {', '.join(known)}")
    return SpectralSpecimen(make(), bands, name)
