"""Colour reports of tables: CIELAB at instrument geometries, flop index, CIEDE2000."""

from __future__ import annotations

import csv
import io
import warnings

import numpy as np
import pytest

from gonio.brdf.colour.conditions import ColourError, ViewingConditions
from gonio.brdf.colour.report import CIELAB, UNCALIBRATED, colour_report, compare, flop_index
from gonio.brdf.colour.spectral import SpectralBands
from gonio.brdf.tables.table import BRDFTable, from_function

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

WL = np.arange(400.0, 701.0, 10.0)
RED = 0.08 + 0.55 / (1 + np.exp(-(WL - 590.0) / 15.0))
BANDS = SpectralBands(tuple(WL), tuple(np.full(WL.size, 1.0)))


def spectral_table(diffuse: np.ndarray, gloss: float = 0.0, aniso: bool = False) -> BRDFTable:
    """Lambertian ``diffuse / pi`` plus an optional white Phong-like lobe about the specular."""
    def fn(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        if aniso:  # a lobe sharper along x than along y (brushed along y)
            lobe = np.exp(-(h[:, 0] ** 2 / 0.02 + h[:, 1] ** 2 / 0.2))
        else:
            lobe = np.exp(-(1 - h[:, 2] ** 2) / 0.05)
        return diffuse[None, :] / np.pi + gloss * lobe[:, None]
    return from_function(fn, [f"{w:g}nm" for w in WL], "spec")


def reference_lab(spectrum: np.ndarray, cond: ViewingConditions) -> np.ndarray:
    """colour-science's own path from a spectrum to CIELAB (white from the same weighting)."""
    cmfs = colour.MSDS_CMFS[cond.observer_name]
    ill = colour.SDS_ILLUMINANTS[cond.illuminant]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xyz = colour.sd_to_XYZ(colour.SpectralDistribution(spectrum, WL), cmfs, ill,
                               method="ASTM E308")
        white = colour.sd_to_XYZ(colour.SpectralDistribution(np.ones_like(WL), WL), cmfs, ill,
                                 method="ASTM E308")
    return np.asarray(colour.XYZ_to_Lab(xyz / 100, colour.XYZ_to_xy(white / 100)))


@pytest.mark.parametrize("cond", [ViewingConditions(), ViewingConditions("A", "2")])
def test_lambertian_spectral_table_reads_its_spectrum_colour(cond: ViewingConditions) -> None:
    report = colour_report(spectral_table(RED), BANDS, cond)
    assert report.space == CIELAB and report.lab is not None
    ref = reference_lab(RED, cond)
    # Every geometry sees the same colour (the table's interpolation is exact for a
    # constant); the band path's smoothing and colour-science's own extrapolation differ by a
    # few hundredths of a unit.
    de = colour.delta_E(report.lab, np.broadcast_to(ref, report.lab.shape), method="CIE 2000")
    assert np.max(de) < 0.05
    assert report.flop == {"MA98@0": pytest.approx(0.0), "BYK-mac@0": pytest.approx(0.0)}
    assert report.reflectance[0] == pytest.approx(RED, rel=1e-4)


def test_gloss_gives_flop_by_the_x_rite_formula() -> None:
    report = colour_report(spectral_table(RED * 0.5, gloss=0.8), BANDS, instruments=["MA68"])
    assert report.lab is not None
    L = {g.aspecular_deg: report.lab[k, 0] for k, g in enumerate(report.geometries)}
    assert L[15] > L[25] > L[45] > L[110]
    expected = 2.69 * (L[15] - L[110]) ** 1.11 / L[45] ** 0.86
    assert report.flop["MA68@0"] == pytest.approx(expected, rel=1e-9)
    assert float(flop_index(40.0, 50.0, 60.0)) == 0.0


def test_azimuth_reveals_anisotropy() -> None:
    t = spectral_table(RED * 0.5, gloss=0.5, aniso=True)
    report = colour_report(t, BANDS, instruments=["BYK-mac"], azimuths_deg=[0, 90])
    assert report.lab is not None
    at0, at90 = report.lab[:6], report.lab[6:]
    assert np.abs(at0[:, 0] - at90[:, 0]).max() > 5.0
    iso = colour_report(spectral_table(RED * 0.5, gloss=0.5), BANDS, instruments=["BYK-mac"],
                        azimuths_deg=[0, 90])
    assert iso.lab is not None
    assert np.abs(iso.lab[:6] - iso.lab[6:]).max() < 0.5


def test_uncalibrated_report_states_it_and_keeps_channel_values() -> None:
    def fn(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.tile([0.3, 0.2, 0.1], (wi.shape[0], 1))
    t = from_function(fn, ["R", "G", "B"], "plain")
    report = colour_report(t, None)
    assert report.space == UNCALIBRATED and report.lab is None and not report.flop
    row = report.rows()[0]
    assert row["R_R"] == pytest.approx(0.3 * np.pi, rel=1e-6) and "L" not in row
    text = report.csv()
    parsed = list(csv.DictReader(io.StringIO(text)))
    # Channel values depend on no illuminant or observer, so the CSV names none.
    assert parsed[0]["space"] == UNCALIBRATED and parsed[0]["illuminant"] == ""
    assert parsed[0]["observer"] == "" and parsed[0]["warnings"] == ""
    assert report.as_dict()["conditions"] is None
    with pytest.raises(ColourError, match="uncalibrated sensor RGB"):
        compare(report, report)


def test_compare_gives_ciede2000_per_geometry() -> None:
    a = colour_report(spectral_table(RED), BANDS)
    b = colour_report(spectral_table(RED * 0.9), BANDS)
    d = compare(a, b)
    assert a.lab is not None and b.lab is not None
    assert d.de00 == pytest.approx(colour.delta_E(a.lab, b.lab, method="CIE 2000"))
    assert (d.de00 > 0.5).all()
    assert d.as_dict()["rows"][0]["dL"] == pytest.approx(a.lab[0, 0] - b.lab[0, 0])
    assert compare(a, a).de00 == pytest.approx(0.0)
    other = colour_report(spectral_table(RED), BANDS, ViewingConditions("A"))
    with pytest.raises(ColourError, match="same illuminant"):
        compare(a, other)
    ma68 = colour_report(spectral_table(RED), BANDS, instruments=["MA68"], azimuths_deg=[30])
    with pytest.raises(ColourError, match="share no geometry"):
        compare(a, ma68)


def test_csv_rows_carry_space_conditions_and_numbers() -> None:
    report = colour_report(spectral_table(RED), BANDS, instruments=["MA68"])
    rows = list(csv.DictReader(io.StringIO(report.csv())))
    assert len(rows) == 5 and rows[0]["space"] == "CIELAB" and rows[0]["observer"] == "10"
    assert rows[0]["aspecular_deg"] == "15"
    assert report.lab is not None
    assert float(rows[2]["L"]) == pytest.approx(report.lab[2, 0], abs=1e-4)


def test_csv_rows_say_how_the_channels_became_colour() -> None:
    """A chart-calibrated sensor's numbers carry the calibration's residual on every CSV row,
    as the printed table's header and the JSON's ``conversion`` do: the residual median is
    colour-science's own, computed here from the chart without gonio."""
    from gonio.brdf.colour.chart import Chart, fit_matrix

    sds = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    names = tuple(sds)
    # Every 10 nm (Ohta's 5 nm data): the ASTM E308 table both paths weigh with.
    wl = np.asarray(sds[names[0]].wavelengths, float)[::2]
    refl = np.stack([np.asarray(sds[n].values, float)[::2] for n in names])
    resp = np.exp(-0.5 * ((wl[None, :] - np.array([[610.0], [540.0], [460.0]])) / 25.0) ** 2)
    readings = refl @ (resp / resp.sum(axis=1, keepdims=True)).T
    cond = ViewingConditions()
    cal = fit_matrix(Chart(names, wl, refl, ("R", "G", "B"), readings), cond, method="linear")
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
    ill = colour.SDS_ILLUMINANTS["D65"]
    with warnings.catch_warnings():
        # colour-science says it trims the CMFs to the spectra's 380-780 nm.
        warnings.simplefilter("ignore")
        xyz = np.stack([colour.sd_to_XYZ(colour.SpectralDistribution(r, wl), cmfs, ill,
                                         method="ASTM E308") for r in refl])
        white = colour.XYZ_to_xy(colour.sd_to_XYZ(
            colour.SpectralDistribution(np.ones_like(wl), wl), cmfs, ill,
            method="ASTM E308") / 100)
    m = np.linalg.lstsq(readings, xyz, rcond=None)[0]
    residual = np.median(colour.delta_E(colour.XYZ_to_Lab(readings @ m / 100, white),
                                        colour.XYZ_to_Lab(xyz / 100, white), method="CIE 2000"))
    grey = from_function(lambda i, o: np.full((i.shape[0], 3), 0.5 / np.pi), ["R", "G", "B"],
                         "grey")
    said = {r["conversion"] for r in csv.DictReader(io.StringIO(
        colour_report(grey, cal, cond, ["MA68"]).csv()))}
    assert said == {f"chart colour calibration (24 patches, residual median {residual:.2f} "
                    "dE00)"}
    spectral = colour_report(spectral_table(RED), BANDS, instruments=["MA68"]).csv()
    assert {r["conversion"] for r in csv.DictReader(io.StringIO(spectral))} == {
        "spectral bands (31)"}
    plain = colour_report(grey, None, instruments=["MA68"]).csv()
    assert {r["conversion"] for r in csv.DictReader(io.StringIO(plain))} == {UNCALIBRATED}


def test_channel_mismatch_is_refused() -> None:
    rgb = from_function(lambda i, o: np.ones((i.shape[0], 3)), ["R", "G", "B"], "x")
    with pytest.raises(ColourError, match="3 values for 31 spectral bands"):
        colour_report(rgb, BANDS)


def test_log_lookup_follows_exponential_lobes_and_flat_tables() -> None:
    from gonio.brdf.colour.report import LOG_OFFSET, log_lookup, log_lookup_linear
    from gonio.brdf.tables import geometry as geo

    # f = exp(-12 theta_h) - f0 is exactly log-linear in theta_h: the multilinear log blend
    # between two 5 degree cells reproduces it wherever theta_h falls (away from the pole,
    # where this lobe has a cusp), where a linear blend of f overshoots.
    def fn(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        th = geo.directions_to_half_diff(wi, wo)[0]
        return (np.exp(-12.0 * th) - LOG_OFFSET)[:, None]
    t = from_function(fn, ["x"], "lobe")
    th_h = np.deg2rad([7.0, 13.0, 17.5])
    wi, wo = geo.half_diff_to_directions(th_h, 0.3, np.deg2rad(20.0), np.deg2rad(40.0))
    exact = np.exp(-12.0 * th_h) - LOG_OFFSET
    assert log_lookup_linear(t, wi, wo)[:, 0] == pytest.approx(exact, rel=1e-6)
    # The cubic along theta_h reproduces what is linear in it too.
    assert log_lookup(t, wi, wo)[:, 0] == pytest.approx(exact, rel=1e-6)
    assert (t.eval(wi, wo)[:, 0] > exact * 1.005).all()
    flat = spectral_table(RED)
    wi, wo = geo.half_diff_to_directions(th_h, 1.0, np.deg2rad(33.0), np.deg2rad(12.0))
    assert log_lookup(flat, wi, wo) == pytest.approx(flat.eval(wi, wo), rel=1e-6)


def test_log_lookup_is_exact_for_a_gaussian_lobe_through_the_pole() -> None:
    """log(f + f0) = -theta_h^2 / (2 s^2) (a Gaussian lobe, s = 6 degrees, about a grid step):
    Catmull-Rom reproduces a quadratic exactly (Keys 1981), and the cell past the pole is the
    same lobe at the opposite azimuth, so the lookup is exact at the instrument geometries'
    half-way cells (aspecular -5, 15 and 25 degrees put theta_h at 2.5, 7.5, 12.5), where the
    multilinear log blend is not."""
    from gonio.brdf.colour.report import LOG_OFFSET, log_lookup, log_lookup_linear
    from gonio.brdf.tables import geometry as geo

    s = np.deg2rad(6.0)

    def fn(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        th = geo.directions_to_half_diff(wi, wo)[0]
        return (np.exp(-0.5 * (th / s) ** 2) - LOG_OFFSET)[:, None]
    t = from_function(fn, ["x"], "gauss")
    th_h = np.deg2rad([1.0, 2.5, 7.5, 12.5, 17.5])
    wi, wo = geo.half_diff_to_directions(th_h, 2.0, np.deg2rad(37.5), np.deg2rad(0.0))
    exact = np.exp(-0.5 * (th_h / s) ** 2) - LOG_OFFSET
    got = log_lookup(t, wi, wo)[:, 0]
    assert got == pytest.approx(exact, rel=1e-6, abs=1e-9)
    linear = log_lookup_linear(t, wi, wo)[:, 0]
    assert abs(linear[1] / exact[1] - 1) > 0.05  # the straight line in log misses the curvature


def test_compare_across_instruments_meets_at_the_same_angles() -> None:
    # An MA68 standard against an MA98 report: MA68's five geometries are MA98's 45as15 to
    # 45as110 (the instruments' published angles, gonio.brdf.colour.instruments), so those
    # five are compared, in the sample's order, and the note names both instruments.
    sample = colour_report(spectral_table(RED, gloss=0.3), BANDS, instruments=["MA98"])
    standard = colour_report(spectral_table(RED * 0.9, gloss=0.3), BANDS, instruments=["MA68"])
    d = compare(sample, standard)
    assert [g.name for g in d.geometries] == ["45as15", "45as25", "45as45", "45as75", "45as110"]
    assert sample.lab is not None and standard.lab is not None
    assert d.de00 == pytest.approx(colour.delta_E(sample.lab[1:6], standard.lab, method="CIE 2000"))
    rows = d.as_dict()["rows"]
    assert {(r["instrument"], r["standard_instrument"]) for r in rows} == {("MA98", "MA68")}
    assert d.note is not None and "MA98" in d.note and "MA68" in d.note
    assert d.as_dict()["note"] == d.note
    # The default report (MA98 and BYK-mac) holds 45as15 twice: each angle is compared once.
    both = colour_report(spectral_table(RED, gloss=0.3), BANDS)
    assert [g.name for g in compare(both, standard).geometries] == [g.name for g in d.geometries]
    # Same instrument: as before, no note, and each row is compared with its own instrument.
    same = compare(sample, sample)
    assert same.note is None and "note" not in same.as_dict()
    assert all(r["standard_instrument"] == "MA98" for r in same.as_dict()["rows"])


def test_the_mean_difference_counts_a_geometry_two_instruments_share_once() -> None:
    """The default report holds MA98's 11 in-plane geometries and BYK-mac's 6, all six of
    them MA98's too: the mean over the rows counted those twice. The mean is over the 11
    distinct geometries, and each instrument gets its own maximum and mean (CIEDE2000 from
    colour-science on the CIELAB of the MA98-only and BYK-mac-only reports)."""
    def reports(instruments: list[str]) -> tuple[np.ndarray, np.ndarray]:
        a = colour_report(spectral_table(RED, gloss=0.3), BANDS, instruments=instruments)
        b = colour_report(spectral_table(RED * 0.8, gloss=0.1), BANDS, instruments=instruments)
        assert a.lab is not None and b.lab is not None
        return a.lab, b.lab
    ma98 = colour.delta_E(*reports(["MA98"]), method="CIE 2000")
    byk = colour.delta_E(*reports(["BYK-mac"]), method="CIE 2000")
    d = compare(colour_report(spectral_table(RED, gloss=0.3), BANDS),
                colour_report(spectral_table(RED * 0.8, gloss=0.1), BANDS))
    assert d.de00.size == ma98.size + byk.size == 17  # every instrument's rows, as before
    assert d.distinct_geometries == ma98.size == 11
    assert d.mean_de00 == pytest.approx(float(np.mean(ma98)))
    assert d.mean_de00 != pytest.approx(float(np.mean(np.concatenate([ma98, byk]))))
    summary = d.as_dict()
    assert summary["mean_dE00"] == pytest.approx(float(np.mean(ma98)))
    assert summary["instruments"] == {
        "MA98": {"max_dE00": pytest.approx(float(ma98.max())),
                 "mean_dE00": pytest.approx(float(ma98.mean())), "geometries": 11},
        "BYK-mac": {"max_dE00": pytest.approx(float(byk.max())),
                    "mean_dE00": pytest.approx(float(byk.mean())), "geometries": 6}}


def test_compare_with_no_shared_geometry_says_what_each_holds() -> None:
    sample = colour_report(spectral_table(RED), BANDS, instruments=["MA98"])
    turned = colour_report(spectral_table(RED), BANDS, instruments=["MA68"], azimuths_deg=[30])
    with pytest.raises(ColourError, match=r"MA98 at azimuth 0 deg.*MA68 at azimuth 30 deg"
                                          r".*--instrument NAME --azimuth DEG"):
        compare(sample, turned)
