"""Colorimetry against published CIE / ASTM values and colour-science's own computations."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from gonio.brdf.colour.conditions import (
    GRID_NM,
    ColourError,
    ViewingConditions,
    delta_e00,
    resample,
    sd_to_xyz,
    spectra_to_xyz,
    xyz_to_lab,
)

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour


@pytest.mark.parametrize(("illuminant", "observer", "white"), [
    # ASTM E308-15 Table 5 (10 nm), white points of the perfect diffuser.
    ("D65", "10", (94.811, 100.0, 107.304)),
    ("D65", "2", (95.047, 100.0, 108.883)),
    ("D50", "2", (96.422, 100.0, 82.521)),
    ("A", "10", (111.144, 100.0, 35.200)),
])
def test_white_point_matches_astm_e308(illuminant: str, observer: str,
                                       white: tuple[float, float, float]) -> None:
    cond = ViewingConditions(illuminant, observer)
    assert cond.white_xyz == pytest.approx(white, abs=0.01)
    assert xyz_to_lab(cond.white_xyz, cond) == pytest.approx([100.0, 0.0, 0.0], abs=0.01)


def test_default_conditions_are_d65_10_degree() -> None:
    c = ViewingConditions()
    assert (c.illuminant, c.observer_name) == ("D65", "CIE 1964 10 Degree Standard Observer")
    # CIE 15:2004 Table T.3: D65 chromaticity for the 10 degree observer.
    assert c.white_xy == pytest.approx([0.31382, 0.33100], abs=1e-5)


def test_grid_weighting_equals_colour_science_on_a_spectrum() -> None:
    rng = np.random.default_rng(3)
    r = np.clip(0.4 + 0.3 * np.sin(GRID_NM / 37.0) + 0.05 * rng.normal(size=GRID_NM.size),
                0, 1)
    cond = ViewingConditions()
    sd = colour.SpectralDistribution(r, GRID_NM)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = colour.sd_to_XYZ(sd, colour.MSDS_CMFS[cond.observer_name],
                               colour.SDS_ILLUMINANTS["D65"], method="ASTM E308")
    assert spectra_to_xyz(r, cond) == pytest.approx(ref, abs=1e-6)
    assert sd_to_xyz(GRID_NM, r, cond) == pytest.approx(ref, abs=1e-6)


def test_spectra_to_xyz_is_linear_and_batched() -> None:
    cond = ViewingConditions("D50", "2")
    r = np.stack([np.full(GRID_NM.size, 0.5), np.full(GRID_NM.size, 0.25)])
    xyz = spectra_to_xyz(r, cond)
    assert xyz.shape == (2, 3)
    assert xyz[0] == pytest.approx(cond.white_xyz * 0.5)
    assert xyz[1] == pytest.approx(cond.white_xyz * 0.25)


def test_lab_follows_the_cie_1976_formula() -> None:
    cond = ViewingConditions()
    xyz = np.array([[20.0, 30.0, 10.0], [0.5, 0.4, 0.3]])
    wn = cond.white_xyz

    def f(t: np.ndarray) -> np.ndarray:
        d = 6 / 29
        return np.where(t > d ** 3, np.cbrt(t), t / (3 * d * d) + 4 / 29)

    fx, fy, fz = (f(xyz[:, i] / wn[i]) for i in range(3))
    ref = np.stack([116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)], axis=1)
    assert xyz_to_lab(xyz, cond) == pytest.approx(ref, abs=1e-6)


@pytest.mark.parametrize(("lab1", "lab2", "de"), [
    # Sharma, Wu & Dalal (2005), CIEDE2000 test data, pairs 1, 7, 17, 25 and 34.
    ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
    ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
    ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
])
def test_delta_e00_matches_sharma_test_data(lab1: tuple[float, ...], lab2: tuple[float, ...],
                                            de: float) -> None:
    assert float(delta_e00(lab1, lab2)) == pytest.approx(de, abs=1e-4)


def test_resample_interpolates_and_extends_flat() -> None:
    out = resample([400.0, 500.0, 700.0], [0.1, 0.5, 0.3])
    at = dict(zip(GRID_NM.tolist(), out.tolist(), strict=True))
    assert at[360.0] == pytest.approx(0.1) and at[780.0] == pytest.approx(0.3)
    assert at[450.0] == pytest.approx(0.3)


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"illuminant": "D66"}, "unknown illuminant"),
    ({"observer": "5"}, "unknown observer"),
])
def test_unknown_conditions_say_what_is_known(kwargs: dict[str, str], words: str) -> None:
    with pytest.raises(ColourError, match=words):
        ViewingConditions(**kwargs)


def test_bad_spectra_are_refused() -> None:
    with pytest.raises(ColourError, match="expected 43"):
        spectra_to_xyz(np.ones(31), ViewingConditions())
    with pytest.raises(ColourError, match="increasing"):
        resample([500.0, 400.0], [0.1, 0.2])
