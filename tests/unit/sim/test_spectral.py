"""Spectral simulated specimens: bands read the spectral BRDF, metals follow Fresnel."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.colour.conditions import GRID_NM
from gonio.brdf.colour.spectral import SpectralBands
from gonio.sim.rig import resolve_material
from gonio.sim.spectral import (
    CHIP_11,
    SPECTRAL_MATERIALS,
    SPECTROMETER_31,
    VALIDATION2_MATERIALS,
    VALIDATION_MATERIALS,
    conductor_fresnel,
    reflectance,
    spectral_specimen,
)


def _dirs() -> tuple[np.ndarray, np.ndarray]:
    t = np.deg2rad([20.0, 45.0, 60.0])
    wi = np.stack([np.sin(t), np.zeros(3), np.cos(t)], axis=1)
    wo = np.stack([-np.sin(t[::-1]), np.zeros(3), np.cos(t[::-1])], axis=1)
    return wi, wo


@pytest.mark.parametrize("name", [*SPECTRAL_MATERIALS, *VALIDATION_MATERIALS,
                                  *VALIDATION2_MATERIALS])
def test_every_material_is_finite_and_read_through_its_bands(name: str) -> None:
    spec = spectral_specimen(name, materials=next(
        m for m in (SPECTRAL_MATERIALS, VALIDATION_MATERIALS, VALIDATION2_MATERIALS) if name in m))
    wi, wo = _dirs()
    full = spec.spectral_eval(wi, wo)
    assert full.shape == (3, GRID_NM.size) and np.isfinite(full).all() and (full >= 0).all()
    assert spec.eval(wi, wo) == pytest.approx(full @ SPECTROMETER_31.response_matrix().T)
    assert spec.channels[0] == "400nm" and spec.wavelengths_nm == SPECTROMETER_31.centres_nm


def test_conductor_fresnel_at_normal_incidence_follows_the_formula() -> None:
    # R(0) = ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2) for a metal of index n + ik.
    f = conductor_fresnel("gold")
    got = f.reflectance(np.ones(1), GRID_NM.size)[0]
    i = int(np.flatnonzero(GRID_NM == 550.0)[0])
    n, k = f.eta[i], f.k[i]  # type: ignore[index]
    assert got[i] == pytest.approx(((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2))
    # Gold reflects red more than blue: the source of its colour.
    assert got[GRID_NM == 650.0][0] > got[GRID_NM == 450.0][0] + 0.3


def test_solid_paint_diffuse_colour_is_its_pigment() -> None:
    spec = spectral_specimen("solid-red-paint")
    # Far from the specular direction the clear coat's lobe is negligible: pi f is the
    # pigment's reflectance times the light the coat lets through.
    wi = np.array([[np.sin(0.7), 0.0, np.cos(0.7)]])
    wo = np.array([[np.sin(0.5), 0.0, np.cos(0.5)]])  # same side as the light
    assert np.pi * spec.spectral_eval(wi, wo)[0] == pytest.approx(0.96 * reflectance("red"),
                                                                    rel=0.02, abs=2e-3)


def test_other_bands_and_names() -> None:
    spec = spectral_specimen("brushed-copper", CHIP_11)
    assert len(spec.channels) == 11
    assert resolve_material("yellow-plastic").name == "yellow-plastic"  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="known: solid-red-paint"):
        spectral_specimen("purple-paint")
    narrow = spectral_specimen("green-plastic", SpectralBands((500.0, 600.0)))
    assert narrow.eval(*_dirs()).shape == (3, 2)
    # A misspelt spectral material (--material of gonio scan --sim, sim, serve --sim) names
    # the spectral materials and the close one, not only the library's families.
    with pytest.raises(ValueError, match=r"did you mean metallic-blue-paint\? spectral "
                                         r"materials .*: solid-red-paint, "):
        resolve_material("metalic-blue-paint")


def test_the_held_out_set_is_apart_from_the_simulators_set() -> None:
    """bench_colour's validation specimens share no name with the set choices are made on, and
    the simulator does not offer them."""
    assert not set(VALIDATION_MATERIALS) & set(SPECTRAL_MATERIALS)
    assert len(VALIDATION_MATERIALS) == len(SPECTRAL_MATERIALS)
    # The third set shares no name with either, and has at least as many specimens.
    assert not set(VALIDATION2_MATERIALS) & (set(SPECTRAL_MATERIALS) | set(VALIDATION_MATERIALS))
    assert len(VALIDATION2_MATERIALS) >= len(SPECTRAL_MATERIALS)
    with pytest.raises(ValueError, match="unknown spectral material 'brushed-gold'"):
        spectral_specimen("brushed-gold")
    # A mixture colour is the mean of its two patches' reflectances, wavelength by wavelength.
    mix = reflectance("purple + magenta")
    assert mix == pytest.approx((reflectance("purple") + reflectance("magenta")) / 2)
    assert not np.allclose(mix, reflectance("purple"), atol=0.02)
