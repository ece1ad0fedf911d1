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
    swapped = fit_matrix(back, channels=["B", "G", "R"], method="linear")
    plain = fit_matrix(back, method="linear")
    assert swapped.matrix[:, ::-1] == pytest.approx(plain.matrix)
    # Either form: the same colour from the same readings in the other order.
    cond = ViewingConditions()
    rp_swapped = fit_matrix(back, channels=["B", "G", "R"], method="root-polynomial")
    rp_plain = fit_matrix(back, method="root-polynomial")
    assert rp_swapped.to_xyz(readings[:, ::-1], cond) == pytest.approx(
        rp_plain.to_xyz(readings, cond), rel=1e-8, abs=1e-8)
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


def test_a_chart_saved_by_a_spreadsheet_reads_as_written(tmp_path: Path) -> None:
    """The chart as a decimal-comma spreadsheet saves it (byte order mark, semicolons,
    decimal commas, CRLF, blank rows, wavelengths headed '400 nm', a notes column): the same
    patches, spectra and readings as written, once the channels are named."""
    names, wl, refl = colorchecker()
    readings = np.random.default_rng(1).uniform(0.05, 0.9, (24, 3))
    lines = [";".join(["patch", "R", "G", "B", *(f"{x:g} nm" for x in wl), "notes"])]
    for n, read, r in zip(names, readings, refl, strict=True):
        lines.append(";".join([n, *(f"{x:.6f}".replace(".", ",") for x in (*read, *r)),
                               "checked, ok"]))
        lines.append(";" * (len(wl) + 4))
    path = tmp_path / "chart.csv"
    path.write_text("\ufeff" + "\r\n".join(lines) + "\r\n", encoding="utf-8")
    back = read_chart(path, channels=["R", "G", "B"])
    assert back.patches == names and back.channels == ("R", "G", "B")
    assert back.wavelengths_nm == pytest.approx(wl)
    assert back.readings == pytest.approx(readings, abs=1e-6)
    assert back.reflectance == pytest.approx(refl, abs=1e-6)
    # Without the channels named the notes column is one: the error says which and what to do.
    with pytest.raises(ChartError, match=r"column 'notes': 'checked, ok' is not a number.*"
                                         r"--channels R,G,B"):
        read_chart(path)


@pytest.mark.parametrize("percent", ["reference", "readings"])
def test_a_chart_in_percent_is_refused(percent: str) -> None:
    """Ohta's ColorChecker spectra (colour-science) reach 0.891 as factors, 89.1 in percent: a
    chart with either column set in percent was fitted, into a calibration 100 times off
    (every result's XYZ 100 times too high or too low)."""
    names, wl, refl = colorchecker()
    assert refl.max() == pytest.approx(0.891)
    readings = np.random.default_rng(3).uniform(0.05, 0.9, (24, 3))
    if percent == "reference":
        refl = refl * 100
    else:
        readings = readings * 100
    text = format_chart(Chart(names, wl, refl, ("R", "G", "B"), readings))
    with pytest.raises(ChartError, match=r"reach \d+.*divide by 100"):
        parse_chart(text)


def test_fewer_than_three_channels_are_refused() -> None:
    """Two channels map every patch into a plane of XYZ: the fit was accepted, at a residual
    of 13.7 dE00 median (the simulated RGB chart's R, G), and made CIELAB of it."""
    names, wl, refl = colorchecker()
    readings = np.random.default_rng(2).uniform(0.05, 0.9, (24, 3))
    chart = Chart(names, wl, refl, ("R", "G", "B"), readings)
    for channels in (["R", "G"], ["B"]):
        with pytest.raises(ChartError, match=f"{len(channels)} channels .*at least 3"):
            fit_matrix(chart, channels=channels)
    assert fit_matrix(chart, channels=["B", "G", "R"]).channels == ("B", "G", "R")


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


def _gaussian_sensor(width_nm: float = 60.0) -> tuple[Chart, np.ndarray]:
    """A non-Luther RGB sensor (Gaussian bands at 610/540/460 nm) reading the ColorChecker,
    and the patches' XYZ under D65/10 computed by colour-science's own ASTM E308 path."""
    names, wl, refl = colorchecker()
    on_grid = resample(wl, refl)
    centres = np.array([610.0, 540.0, 460.0])
    sigma = width_nm / (2 * np.sqrt(2 * np.log(2)))
    resp = np.exp(-0.5 * ((GRID_NM[None, :] - centres[:, None]) / sigma) ** 2)
    readings = on_grid @ (resp / resp.sum(axis=1, keepdims=True)).T
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
    ill = colour.SDS_ILLUMINANTS["D65"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xyz = np.stack([colour.sd_to_XYZ(colour.SpectralDistribution(r, wl), cmfs, ill,
                                         method="ASTM E308") for r in refl])
    return Chart(names, wl, refl, ("R", "G", "B"), readings), xyz


def test_root_polynomial_calibration_is_colour_sciences_finlayson_2015() -> None:
    chart, xyz = _gaussian_sensor()
    cond = ViewingConditions()
    m = fit_matrix(chart, cond, method="root-polynomial")
    assert m.method == "root-polynomial" and m.matrix.shape == (3, 6)
    ccm = colour.matrix_colour_correction(chart.readings, xyz, method="Finlayson 2015",
                                          degree=2, root_polynomial_expansion=True)
    want = colour.apply_matrix_colour_correction(chart.readings, ccm, method="Finlayson 2015",
                                                 degree=2, root_polynomial_expansion=True)
    # gonio's reference XYZ come from its 10 nm weights (E308 with colour-science's
    # alignment); colour-science's own path differs by interpolation only.
    assert m.to_xyz(chart.readings, cond) == pytest.approx(want, rel=5e-3, abs=0.05)
    # Finlayson et al.'s point: the terms scale with the reading, so the colour of a
    # brighter or darker surface of the same chromaticity scales with it.
    for k in (0.05, 3.0):
        assert m.to_xyz(k * chart.readings, cond) == pytest.approx(
            k * m.to_xyz(chart.readings, cond), rel=1e-9)


def test_the_form_is_chosen_by_left_out_patches() -> None:
    """Default: the form whose patches are better predicted by fits without them, each
    left-out prediction recomputed here with colour-science alone."""
    chart, xyz = _gaussian_sensor()
    cond = ViewingConditions()
    white = colour.XYZ_to_xy(cond.white_xyz / 100.0)
    lab = colour.XYZ_to_Lab(xyz / 100.0, white)

    def loo(method: str) -> float:
        out = []
        for p in range(24):
            keep = np.arange(24) != p
            if method == "linear":
                sol = np.linalg.lstsq(chart.readings[keep], xyz[keep], rcond=None)[0]
                pred = chart.readings[p] @ sol
            else:
                ccm = colour.matrix_colour_correction(
                    chart.readings[keep], xyz[keep], method="Finlayson 2015", degree=2)
                pred = colour.apply_matrix_colour_correction(
                    chart.readings[p], ccm, method="Finlayson 2015", degree=2)
            out.append(colour.delta_E(colour.XYZ_to_Lab(pred / 100.0, white), lab[p],
                                      method="CIE 2000"))
        return float(np.median(out))

    want = {"linear": loo("linear"), "root-polynomial": loo("root-polynomial")}
    m = fit_matrix(chart, cond)
    assert m.method == min(want, key=lambda k: want[k])
    assert m.loo_median_de00 == pytest.approx(want[m.method], rel=0.05, abs=0.02)
    assert m.loo_median_de00 > m.residual_median_de00  # left-out patches are harder
    back = ColourMatrix.from_dict(m.as_dict())
    assert back.method == m.method and back.to_xyz(chart.readings, cond) == pytest.approx(
        m.to_xyz(chart.readings, cond))


def test_bad_calibration_forms_say_what_to_do() -> None:
    chart, _ = _gaussian_sensor()
    with pytest.raises(ChartError, match="method 'cubic' is unknown"):
        fit_matrix(chart, method="cubic")
    four = Chart(chart.patches, chart.wavelengths_nm, chart.reflectance, ("R", "G", "B", "W"),
                 np.column_stack([chart.readings, chart.readings.mean(axis=1)]))
    with pytest.raises(ChartError, match="needs 3 channels"):
        fit_matrix(four, method="root-polynomial")
    assert fit_matrix(four).method == "linear"  # the only form for 4 channels
    d = fit_matrix(chart, method="root-polynomial").as_dict()
    with pytest.raises(ColourError, match="3 x 6"):
        ColourMatrix.from_dict({**d, "matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]})
    with pytest.raises(ColourError, match="unknown"):
        ColourMatrix.from_dict({**d, "method": "spline"})
