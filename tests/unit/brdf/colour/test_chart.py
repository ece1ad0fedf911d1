"""Chart colour calibration: the fit, its residual, and the chart file."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.colour.chart import (
    Chart,
    ChartError,
    ColourMatrix,
    fit_matrix,
    format_chart,
    parse_chart,
    read_chart,
)
from gonio.brdf.colour.conditions import (
    GRID_NM,
    ColourError,
    ViewingConditions,
    resample,
)

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour


def colorchecker() -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """The 24 ColorChecker patches' spectra as colour-science ships them (Ohta's data)."""
    sds = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    names = tuple(sds)
    wl = np.asarray(sds[names[0]].wavelengths, float)
    refl = np.stack([np.asarray(sds[n].values, float) for n in names])
    return names, wl, refl


def test_a_luther_sensor_is_calibrated_exactly() -> None:
    names, wl, refl = colorchecker()
    cond = ViewingConditions()
    on_grid = resample(wl, refl)
    # A sensor whose channels are a mix of the CIE weighting (computed by colour-science,
    # independently of gonio's weights): the Luther condition, a 3 x 3 matrix undoes it.
    cmfs = colour.MSDS_CMFS[cond.observer_name].copy().align(
        colour.SpectralShape(360, 780, 10))
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(colour.SpectralShape(360, 780, 10))
    cie = (np.asarray(cmfs.values) * np.asarray(ill.values)[:, None]).T  # (3, G)
    mix = np.array([[0.2, 0.7, 0.1], [0.6, 0.3, 0.1], [0.0, 0.2, 0.8]])
    readings = on_grid @ (mix @ cie).T / (mix @ cie).sum(axis=1)
    m = fit_matrix(Chart(names, wl, refl, ("R", "G", "B"), readings), cond)
    assert m.residual_max_de00 < 0.05
    ref = m.to_xyz(readings, cond)
    assert ref == pytest.approx(Chart(names, wl, refl, (), readings).reference_xyz(cond),
                                rel=2e-3, abs=0.02)


def test_a_non_luther_sensor_has_a_residual() -> None:
    names, wl, refl = colorchecker()
    on_grid = resample(wl, refl)
    centres = np.array([610.0, 540.0, 460.0])
    resp = np.exp(-0.5 * ((GRID_NM[None, :] - centres[:, None]) / 15.0) ** 2)
    readings = on_grid @ (resp / resp.sum(axis=1, keepdims=True)).T
    m = fit_matrix(Chart(names, wl, refl, ("R", "G", "B"), readings))
    assert 0.2 < m.residual_median_de00 < m.residual_max_de00
    assert m.n_patches == 24


def test_chart_file_round_trip_and_channel_order(tmp_path: Path) -> None:
    names, wl, refl = colorchecker()
    readings = np.random.default_rng(0).uniform(0.05, 0.9, (24, 3))
    chart = Chart(names, wl, refl, ("R", "G", "B"), readings)
    path = tmp_path / "chart.csv"
    path.write_text(format_chart(chart), encoding="utf-8")
    back = read_chart(path)
    assert back.patches == names and back.channels == ("R", "G", "B")
    assert back.readings == pytest.approx(readings, rel=1e-5)
    assert back.reflectance == pytest.approx(refl, rel=1e-5)
    swapped = fit_matrix(back, channels=["B", "G", "R"])
    plain = fit_matrix(back)
    assert swapped.matrix[:, ::-1] == pytest.approx(plain.matrix)
    with pytest.raises(ChartError, match=r"no column for channels \['IR'\]"):
        fit_matrix(back, channels=["R", "IR"])


def _chart_text(rows: int = 6, header: str = "patch,R,G,B,400,450,500,550,600") -> str:
    lines = [header]
    for i in range(rows):
        lines.append(f"p{i},{0.1 + i / 10},{0.2},{0.3 + i / 20},0.1,0.2,0.3,0.4,0.5")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("text", "words"), [
    ("", "empty"),
    ("name,R,400\n", "first column must be 'patch'"),
    (_chart_text(header="patch,R,G,B,400,450,500,550,X"), "4 reference wavelength columns"),
    ("patch,400,450,500,550,600\np,1,1,1,1,1\n", "no sensor channel"),
    (_chart_text(header="patch,R,G,B,400,450,500,600,550"), "must increase"),
    (_chart_text(rows=5), "5 patches"),
    (_chart_text() + "p9,1,2\n", "row 8 has 3 fields"),
    (_chart_text() + "p9,a,1,1,1,1,1,1,1\n", "row 8 .'p9'."),
    (_chart_text() + "p9,nan,1,1,1,1,1,1,1\n", "not finite"),
])
def test_bad_chart_files_say_what_is_wrong(text: str, words: str) -> None:
    with pytest.raises(ChartError, match=words):
        parse_chart(text)


def test_missing_chart_file_names_it(tmp_path: Path) -> None:
    with pytest.raises(ChartError, match="cannot read chart file"):
        read_chart(tmp_path / "nope.csv")


def test_matrix_round_trip_and_checks() -> None:
    m = ColourMatrix(("R", "G", "B"), np.eye(3) * 90, ViewingConditions(), 0.5, 1.5, 24, "x")
    assert ColourMatrix.from_dict(m.as_dict()).matrix == pytest.approx(m.matrix)
    with pytest.raises(ColourError, match="fitted for D65/10, not A/10"):
        m.to_xyz(np.ones(3), ViewingConditions("A"))
    with pytest.raises(ColourError, match="expected 3 x 2"):
        ColourMatrix.from_dict({**m.as_dict(), "channels": ["R", "G"]})
    with pytest.raises(ColourError, match="malformed"):
        ColourMatrix.from_dict({"channels": ["R"]})
