"""Spectral bands: forward model, spectrum recovery, and colour of band readings."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.colour.conditions import (
    GRID_NM,
    ColourError,
    ViewingConditions,
    delta_e00,
    spectra_to_xyz,
    xyz_to_lab,
)
from gonio.brdf.colour.spectral import SpectralBands, bands_from_channels, default_widths

SPECTROMETER = SpectralBands(tuple(np.arange(400.0, 701.0, 10.0)))
# An 8-channel visible spectral sensor chip: centres and FWHM of a typical datasheet.
CHIP = SpectralBands((415, 445, 480, 515, 555, 590, 630, 680), (26, 30, 36, 39, 39, 40, 50, 52))


def smooth_spectrum(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a, b, c = rng.uniform(0.1, 0.5, 3)
    return np.clip(a + b * np.sin(GRID_NM / 60.0 + c * 10) ** 2, 0.02, 1.0)


def test_flat_reflectance_reads_and_returns_flat() -> None:
    for bands in (SPECTROMETER, CHIP):
        read = bands.read(np.full(GRID_NM.size, 0.37))
        assert read == pytest.approx(np.full(bands.n_bands, 0.37))
        assert bands.to_spectrum(read) == pytest.approx(np.full(GRID_NM.size, 0.37), abs=1e-6)


def test_gaussian_width_is_the_full_width_at_half_maximum() -> None:
    # The same band as a response table sampled from exp(-4 ln2 (x - c)^2 / w^2): the
    # definition of FWHM w.
    wl = np.arange(300.0, 850.0, 0.5)
    table = np.exp(-4 * np.log(2) * (wl - 532.0) ** 2 / 20.0 ** 2)
    a = SpectralBands((532.0,), (20.0,)).response_matrix()
    b = SpectralBands((532.0,), None, tuple(wl), (tuple(table),)).response_matrix()
    assert a == pytest.approx(b, abs=1e-6)


@pytest.mark.parametrize(("bands", "tolerance"), [(SPECTROMETER, 0.05), (CHIP, 1.0)])
def test_band_readings_give_the_spectrum_colour(bands: SpectralBands, tolerance: float) -> None:
    cond = ViewingConditions()
    for seed in range(5):
        r = smooth_spectrum(seed)
        truth = xyz_to_lab(spectra_to_xyz(r, cond), cond)
        got = xyz_to_lab(bands.to_xyz(bands.read(r), cond), cond)
        assert float(delta_e00(truth, got)) < tolerance


def test_default_widths_are_the_centre_spacing() -> None:
    assert default_widths([400.0, 410.0, 430.0]) == pytest.approx([10.0, 15.0, 20.0])
    assert SPECTROMETER.widths_nm == pytest.approx(np.full(31, 10.0))


def test_bands_from_channels() -> None:
    assert bands_from_channels(["R", "G", "B"], None) is None
    assert bands_from_channels(["R", "G"], [float("nan")] * 2) is None
    b = bands_from_channels(["a", "b", "c"], [450.0, 550.0, 650.0], [20.0, 20.0, 20.0])
    assert b is not None and b.widths_nm == (20.0, 20.0, 20.0)
    with pytest.raises(ColourError, match="no wavelength"):
        bands_from_channels(["a", "b"], [450.0, float("nan")])


def test_round_trip_through_dict() -> None:
    b = SpectralBands((450.0, 550.0), None, (400.0, 500.0, 600.0), ((1, 0.5, 0), (0, 0.5, 1)))
    assert SpectralBands.from_dict(b.as_dict()) == b


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"centres_nm": ()}, "positive wavelengths"),
    ({"centres_nm": (500.0, 600.0), "widths_nm": (10.0,)}, "one positive band width"),
    ({"centres_nm": (500.0,), "response_nm": (400.0, 500.0)}, "both"),
    ({"centres_nm": (500.0,), "response_nm": (400.0, 500.0), "responses": ((1.0,),)},
     "expected 1 channels x 2"),
    ({"centres_nm": (500.0,), "response_nm": (400.0, 500.0), "responses": ((0.0, 0.0),)},
     "positive somewhere"),
])
def test_bad_bands_are_refused(kwargs: dict[str, object], words: str) -> None:
    with pytest.raises(ColourError, match=words):
        SpectralBands(**kwargs)  # type: ignore[arg-type]


def test_bands_outside_the_visible_are_refused_for_colour() -> None:
    with pytest.raises(ColourError, match="respond nowhere"):
        SpectralBands((1500.0,), (10.0,)).response_matrix()


def test_wrong_channel_count_is_refused() -> None:
    with pytest.raises(ColourError, match="3 values for 31"):
        SPECTROMETER.to_spectrum(np.ones(3))
