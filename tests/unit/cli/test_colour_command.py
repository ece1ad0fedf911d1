"""'gonio colour' on result files: CIELAB tables, CSV, CIEDE2000 against a standard, errors."""

from __future__ import annotations

import csv
import io
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.colour import conditions as colour_conditions
from gonio.brdf.colour import instruments as colour_instruments
from gonio.brdf.colour.chart import ColourMatrix
from gonio.brdf.colour.conditions import ViewingConditions
from gonio.brdf.tables.table import BRDFTable, from_function
from gonio.calibration import CalibratedScan
from gonio.cli import colour_command, main
from gonio.results import write_result

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

RGB = np.array([0.25, 0.15, 0.05])
MATRIX = np.array([[41.2, 35.8, 18.0], [21.3, 71.5, 7.2], [1.9, 11.9, 95.0]])


def _samples(channels: tuple[str, ...]) -> CalibratedScan:
    return CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
                          sensor_dirs=np.array([[0.0, 0.0, 1.0]]),
                          stage_angles_deg=np.array([0.0]),
                          values=np.ones((1, 1, len(channels))), channels=channels)


def _lambert(scale: float = 1.0) -> BRDFTable:
    return from_function(lambda i, o: np.tile(RGB * scale, (i.shape[0], 1)), ["R", "G", "B"],
                         "x", dtype=np.float32)


def _write(path: Path, table: BRDFTable, source: dict[str, object] | None,
           specimen: str = "panel") -> Path:
    return write_result(path, job_id=7, specimen=specimen, kind="uniform", readings=[],
                        samples=_samples(table.channels), table=table,
                        colour=None if source is None else {"source": source})


def _matrix() -> dict[str, object]:
    return ColourMatrix(("R", "G", "B"), MATRIX, ViewingConditions(), 0.4, 1.1, 24,
                        "chart.csv").as_dict()


def _expected_lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB of a matrix-calibrated reflectance, by colour-science directly."""
    refl = np.pi * rgb
    xyz = MATRIX @ refl
    white = ViewingConditions().white_xyz
    return np.asarray(colour.XYZ_to_Lab(xyz / 100, colour.XYZ_to_xy(white / 100)))


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("colour")
    return {
        "cal": _write(d / "cal.h5", _lambert(), {"calibration": _matrix()}),
        "cal2": _write(d / "cal2.h5", _lambert(0.9), {"calibration": _matrix()}, "batch 2"),
        "raw": _write(d / "raw.h5", _lambert(), None),
        # Scanned with no white reference in effect: sensor units (its calibration lists no
        # pair), whatever the sensor's colour source.
        "units": write_result(d / "units.h5", job_id=9, specimen="panel", kind="uniform",
                              readings=[], samples=CalibratedScan(
                                  pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
                                  sensor_dirs=np.array([[0.0, 0.0, 1.0]]),
                                  stage_angles_deg=np.array([0.0]), values=np.ones((1, 1, 3)),
                                  channels=("R", "G", "B"), calibration={"pairs": []}),
                              table=_lambert(), colour={"source": {"calibration": _matrix()}}),
    }


def test_calibrated_result_prints_cielab(files: dict[str, Path],
                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["colour", str(files["cal"]), "--csv", "-"]) == 0
    out = capsys.readouterr()
    # The result's one pair (normal incidence and view) reads no instrument geometry: the
    # near-specular ones are noted as read from the table.
    assert ("note: the geometries within 25 degrees of the specular direction (45as-15, "
            "45as15, 45as25, 15as-15, 15as-5) were read from the reconstructed table") in out.err
    rows = list(csv.DictReader(io.StringIO(out.out)))
    assert len(rows) == 11 + 6 and rows[0]["space"] == "CIELAB"
    assert rows[0]["illuminant"] == "D65" and rows[0]["observer"] == "10"
    lab = _expected_lab(RGB)
    for r in rows:
        assert [float(r["L"]), float(r["a"]), float(r["b"])] == pytest.approx(lab, abs=2e-3)
        assert float(r["flop_index"]) == pytest.approx(0.0)


def test_table_json_and_csv_file(files: dict[str, Path], tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "c.csv"
    assert main(["colour", str(files["cal"]), "--instrument", "MA68", "--azimuth", "0,90",
                 "--csv", str(out)]) == 0
    text = capsys.readouterr().out
    assert "panel: CIELAB, D65/10 (chart colour calibration (24 patches" in text
    assert "flop index MA68 at azimuth 90: 0.00" in text and f"wrote {out}" in text
    assert len(list(csv.DictReader(out.open()))) == 10
    # The result's one pair (normal incidence and view) sits at no MA68 geometry: every row
    # says it was read from the table, in the printout and in the CSV.
    lines = text.splitlines()
    assert lines[1].split()[-1] == "source"
    assert [ln.split()[-1] for ln in lines[2:12]] == ["table"] * 10
    assert {r["source"] for r in csv.DictReader(out.open())} == {"table"}
    assert main(["colour", str(files["cal"]), "--json", "--observer", "2"]) == 2
    err = capsys.readouterr()
    # A matrix fitted for D65/10 refuses other conditions with what to do.
    assert "fit it again from the chart for D65/2" in err.err


def test_uncalibrated_result_says_so(files: dict[str, Path],
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["colour", str(files["raw"]), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)["colour"]
    assert rep["space"] == "uncalibrated sensor RGB"
    assert rep["rows"][0]["R_R"] == pytest.approx(np.pi * RGB[0], rel=1e-5)
    # Channel values depend on no illuminant or observer: none is named anywhere.
    assert rep["conditions"] is None and "illuminant" not in rep["provenance"]
    assert main(["colour", str(files["raw"])]) == 0
    text = capsys.readouterr().out
    assert "raw.h5's sensors have neither spectral bands nor a chart colour calibration" in text
    assert text.splitlines()[0] == "panel: uncalibrated sensor RGB"
    assert main(["colour", str(files["raw"]), "--csv", "-"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert {(r["illuminant"], r["observer"]) for r in rows} == {("", "")}
    assert main(["colour", str(files["raw"]), "--against", str(files["cal"])]) == 2
    err = capsys.readouterr().err
    assert f"no dE00 against {files['cal']}: raw.h5's sensors have neither" in err, err


def test_a_result_in_sensor_units_says_why_it_has_no_colour_difference(
        files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """Its sensors have a chart calibration, but its values are not in 1/sr: the advice is
    the white reference, not a colour calibration it already has. It said "give its sensor
    spectral bands or a chart colour calibration first"."""
    for args in ([str(files["units"]), "--against", str(files["cal"])],
                 [str(files["cal"]), "--against", str(files["units"])]):
        assert main(["colour", *args]) == 2
        err = capsys.readouterr().err
        assert "no dE00 against" in err and "units.h5 is uncalibrated: its values are sensor " \
            "units, not 1/sr" in err, err
        assert "calibrate the rig on the white reference" in err, err
    assert main(["colour", str(files["units"]), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["colour"]["space"] == "uncalibrated sensor RGB"
    assert out["no_colour"].startswith("units.h5 is uncalibrated"), out
    assert main(["colour", str(files["units"])]) == 0
    text = capsys.readouterr().out
    assert "units.h5 is uncalibrated" in text
    # Its values are pi times sensor units: the table must not call them reflectance factors
    # (docs/colour.md), as it did.
    assert "pi times the sensor units per channel (uncalibrated: not reflectance factors)" \
        in text and "reflectance factors per channel (pi f)" not in text, text
    # A result in 1/sr without colour keeps the name (its values are reflectance factors).
    assert main(["colour", str(files["raw"])]) == 0
    assert "reflectance factors per channel (pi f)" in capsys.readouterr().out


def test_against_a_result_and_a_stored_csv(files: dict[str, Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["colour", str(files["cal2"]), "--against", str(files["cal"]), "--json"]) == 0
    diff = json.loads(capsys.readouterr().out)["difference"]
    expected = colour.delta_E(_expected_lab(RGB * 0.9), _expected_lab(RGB), method="CIE 2000")
    assert diff["max_dE00"] == pytest.approx(expected, abs=1e-3)
    assert diff["sample"] == "batch 2" and diff["standard"] == "panel"
    # The table's summary: the mean over MA98's 11 geometries (BYK-mac's 6 are among them,
    # counted once), then each instrument's own.
    assert main(["colour", str(files["cal2"]), "--against", str(files["cal"])]) == 0
    said = capsys.readouterr()
    text = said.out
    # Two results without scan readings: every near-specular value is each one's table, so
    # the difference says a shared error would not show there (MA98's five near-specular
    # geometries, from its published aspecular angles).
    assert ("note: at 45as-15, 45as15, 45as25, 15as-15, 15as-5 both sides' colour was read "
            "from their reconstructed tables") in said.err, said.err
    assert f"max dE00 {expected.max():.2f}, mean {expected.mean():.2f} over the 11 distinct " \
        "geometries" in text, text
    assert "  MA98: max" in text and "over its 11 geometries" in text, text
    assert "  BYK-mac: max" in text and "over its 6 geometries" in text, text
    std = tmp_path / "std.csv"
    assert main(["colour", str(files["cal"]), "--csv", str(std)]) == 0
    capsys.readouterr()
    assert main(["colour", str(files["cal2"]), "--against", str(std), "--csv", "-"]) == 0
    said = capsys.readouterr()
    rows = list(csv.DictReader(io.StringIO(said.out)))
    assert float(rows[0]["dE00"]) == pytest.approx(expected, abs=1e-3)
    assert "both sides' colour" not in said.err  # a CSV standard was measured
    assert main(["colour", str(files["cal"]), "--against", str(std), "--csv", "-"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert max(float(r["dE00"]) for r in rows) < 1e-3
    # A standard written at MA68's geometries against the default report (MA98, BYK-mac): met
    # at MA68's five angles, each once, and the note says the instruments differ.
    ma68 = tmp_path / "ma68.csv"
    assert main(["colour", str(files["cal"]), "--instrument", "MA68", "--csv", str(ma68)]) == 0
    capsys.readouterr()
    assert main(["colour", str(files["cal2"]), "--against", str(ma68), "--csv", "-"]) == 0
    out = capsys.readouterr()
    rows = list(csv.DictReader(io.StringIO(out.out)))
    assert [(r["incidence_deg"], r["aspecular_deg"]) for r in rows] == [
        ("45", "15"), ("45", "25"), ("45", "45"), ("45", "75"), ("45", "110")]
    assert {r["standard_instrument"] for r in rows} == {"MA68"}
    assert float(rows[0]["dE00"]) == pytest.approx(expected, abs=1e-3)
    assert "note: compared at the geometries of the same incidence" in out.err


def test_against_takes_a_stored_standard_by_name_as_the_page_does(
        files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--against NAME``: a stored standard of the data directory (its standards/ folder, as
    the lab page and the API name them), from --data-dir or the result's own data directory;
    it took files only. A name that is neither a file nor a stored standard is refused,
    listing the stored ones."""
    import shutil

    data = tmp_path / "data"
    (data / "standards").mkdir(parents=True)
    assert main(["colour", str(files["cal"]), "--csv", str(data / "standards" /
                                                           "blue master.csv")]) == 0
    capsys.readouterr()
    assert main(["colour", str(files["cal2"]), "--against", str(files["cal"]), "--json"]) == 0
    by_file = json.loads(capsys.readouterr().out)["difference"]["max_dE00"]
    assert main(["colour", str(files["cal2"]), "--against", "blue master", "--data-dir",
                 str(data), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["difference"]["standard"] == "blue master"
    assert out["difference"]["max_dE00"] == pytest.approx(by_file, abs=0.01)
    # A result in a data directory's results/ folder looks in that directory by itself.
    (data / "results").mkdir()
    shutil.copy(files["cal2"], data / "results" / "job-7.h5")
    assert main(["colour", str(data / "results" / "job-7.h5"), "--against", "blue master.csv",
                 "--csv", "-"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert rows and {r["standard"] for r in rows} == {"blue master"}
    # Neither a file nor a stored name: the stored ones are listed.
    assert main(["colour", str(files["cal2"]), "--against", "green master", "--data-dir",
                 str(data)]) == 2
    err = capsys.readouterr().err
    assert "--against green master: no such file, and no stored standard of that name in " \
        f"{data / 'standards'} (it holds blue master)" in err, err
    # No data directory to look in: said, with what to give.
    assert main(["colour", str(files["cal2"]), "--against", "blue master"]) == 2
    err = capsys.readouterr().err
    assert "no data directory to look for a stored standard" in err and "--data-dir" in err, err
    assert main(["colour", str(files["cal2"]), "--against", "blue master", "--data-dir",
                 str(tmp_path / "none")]) == 2
    assert "is not a folder" in capsys.readouterr().err


def test_bad_input(files: dict[str, Path], tmp_path: Path,
                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["colour", str(tmp_path / "none.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["colour", str(files["cal"]), "--azimuth", "north"]) == 2
    assert "degrees separated by commas" in capsys.readouterr().err
    assert main(["colour", str(files["cal"]), "--instrument", "MA99"]) == 2
    assert "known instruments are MA68" in capsys.readouterr().err
    assert main(["colour", str(files["cal"]), "--against", str(tmp_path / "x.h5")]) == 2
    assert "standard" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("instrument,L\nMA98,50\n")
    assert main(["colour", str(files["cal"]), "--against", str(bad)]) == 2
    assert "are missing" in capsys.readouterr().err
    calib = write_result(tmp_path / "white.h5", job_id=8, specimen="white",
                         kind="calibration", readings=[], samples=_samples(("R", "G", "B")))
    assert main(["colour", str(calib)]) == 2
    assert "no reconstructed BRDF" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["colour", str(files["cal"]), "--illuminant", "D66"])


def test_cli_names_match_the_core() -> None:
    assert colour_command.ILLUMINANTS == colour_conditions.ILLUMINANTS
    assert tuple(colour_instruments.INSTRUMENTS) == colour_command.INSTRUMENTS
    assert colour_command.DEFAULT_INSTRUMENTS == colour_instruments.DEFAULT_INSTRUMENTS


def test_colour_chart_writes_a_rig_config_table(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    import tomllib

    from gonio.brdf.colour.chart import Chart, format_chart
    from gonio.brdf.colour.conditions import GRID_NM, resample
    from gonio.config import parse_rig_config
    from tests.unit.test_config import EXAMPLE

    sds = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    names = tuple(sds)
    wl = np.asarray(sds[names[0]].wavelengths, float)
    refl = np.stack([np.asarray(sds[n].values, float) for n in names])
    centres = np.array([[610.0], [540.0], [460.0]])
    resp = np.exp(-0.5 * ((GRID_NM[None, :] - centres) / 25.0) ** 2)
    read = resample(wl, refl) @ (resp / resp.sum(axis=1, keepdims=True)).T
    chart = tmp_path / "chart.csv"
    chart.write_text(format_chart(Chart(names, wl, refl, ("R", "G", "B"), read)))
    out = tmp_path / "cal.toml"
    assert main(["colour-chart", str(chart), "--channels", "R,G,B", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "from 24 patches (D65/10): residual median" in said
    fragment = tomllib.loads(out.read_text())["sensors"]["colour_calibration"]
    assert len(fragment["matrix"]) == 3 and fragment["n_patches"] == 24
    with EXAMPLE.open("rb") as f:
        rig = tomllib.load(f)
    rig["sensors"][0]["colour_calibration"] = fragment
    cfg = parse_rig_config(rig)
    cal = cfg.sensors[0].colour_calibration
    assert cal is not None and cal.source == "chart.csv"
    # The table names the channels its matrix's columns are for; under a sensor whose
    # channels are in another order it is refused, not applied to the wrong channels.
    assert fragment["channels"] == ["R", "G", "B"] == cfg.sensors[0].channels
    assert main(["colour-chart", str(chart), "--channels", "B,G,R", "-o",
                 str(tmp_path / "bgr.toml")]) == 0
    capsys.readouterr()
    rig["sensors"][0]["colour_calibration"] = tomllib.loads(
        (tmp_path / "bgr.toml").read_text())["sensors"]["colour_calibration"]
    from gonio.config import ConfigError

    with pytest.raises(ConfigError, match=r"fitted for channels \['B', 'G', 'R'\]"):
        parse_rig_config(rig)
    # The matrix maps the chart's own readings near its reference XYZ (what fitting means).
    ref = Chart(names, wl, refl, ("R", "G", "B"), read).reference_xyz(ViewingConditions())
    # Root-polynomial terms (Finlayson et al. 2015) when that form was chosen.
    r, g, b = read.T
    terms = read if cal.method == "linear" else np.column_stack(
        [r, g, b, np.sqrt(r * g), np.sqrt(g * b), np.sqrt(r * b)])
    fitted = terms @ np.asarray(cal.matrix).T
    assert np.median(np.abs(fitted - ref)) < 3.0
    assert f"colour calibration ({cal.method})" in said
    assert main(["colour-chart", str(chart), "--method", "linear", "-o", str(out)]) == 0
    capsys.readouterr()
    linear = tomllib.loads(out.read_text())["sensors"]["colour_calibration"]
    assert linear["method"] == "linear" and len(linear["matrix"][0]) == 3
    assert main(["colour-chart", str(tmp_path / "none.csv")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["colour-chart", str(chart), "--channels", "R,IR"]) == 2
    assert "no column for channels ['IR']" in capsys.readouterr().err


def test_a_calibration_at_another_exposure_is_said_with_the_colour(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Every L* of such a scan is off (its values by the exposure ratio): gonio colour printed
    # the table as if nothing were wrong.
    off = ("the calibration was measured at exposure 0.01 s, this scan at 0.5 s; its values "
           "are off by about the ratio. Calibrate at the scan's exposure")
    path = write_result(tmp_path / "off.h5", job_id=8, specimen="panel", kind="uniform",
                        readings=[], samples=_samples(("R", "G", "B")), table=_lambert(),
                        colour={"source": {"calibration": _matrix()}},
                        provenance={"calibration_warning": off})
    assert main(["colour", str(path)]) == 0
    assert f"warning: {off}" in capsys.readouterr().err
    # The CSV a lab keeps carries it on every row, and so does the JSON.
    assert main(["colour", str(path), "--csv", "-"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert rows and {r["warnings"] for r in rows} == {off}
    assert main(["colour", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == [off]

    plain = _write(tmp_path / "plain.h5", _lambert(), {"calibration": _matrix()})
    assert main(["colour", str(plain)]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["colour", str(plain), "--csv", "-"]) == 0
    assert {r["warnings"] for r in csv.DictReader(io.StringIO(capsys.readouterr().out))} == {""}
    # Compared with the off scan as the standard: the standard's warning travels too.
    assert main(["colour", str(plain), "--against", str(path), "--csv", "-"]) == 0
    out = capsys.readouterr()
    assert f"warning: standard: {off}" in out.err
    assert {r["warnings"] for r in csv.DictReader(io.StringIO(out.out))} == {f"standard: {off}"}
    # The off scan's CSV kept as a stored standard carries its warning into the comparison.
    std = tmp_path / "std.csv"
    assert main(["colour", str(path), "--csv", str(std)]) == 0
    capsys.readouterr()
    assert main(["colour", str(plain), "--against", str(std), "--csv", "-"]) == 0
    assert f"warning: standard: {off}" in capsys.readouterr().err


def test_the_reconstruction_s_warnings_travel_with_the_colour(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A table outside physical bounds (the simulated solid red paint's clear coat: 1.3e3 1/sr,
    3.9e3 times its largest reading) was said by its exports and its headline, and not by its
    colour: gonio colour printed 15as-5 at L* 91.9 (the material's is 114.6, 25.6 dE00 off)
    as if nothing were wrong. Every reconstruction warning an export carries travels with the
    colour, in the exports' order."""
    from gonio.export.metadata import RECONSTRUCTION_WARNINGS
    from gonio.result_colour import RECONSTRUCTION_WARNINGS as COLOUR_WARNINGS

    assert COLOUR_WARNINGS == RECONSTRUCTION_WARNINGS
    bounds = ("the reconstruction is outside physical bounds: its maximum 1.33e+03 is 3.86e+03 "
              "times the largest reading (0.345), above 1000")
    gap = "the predicted error is 3.1 times the design's expectation"
    path = write_result(tmp_path / "red.h5", job_id=9, specimen="red", kind="uniform",
                        readings=[], samples=_samples(("R", "G", "B")), table=_lambert(),
                        colour={"source": {"calibration": _matrix()}},
                        provenance={"design_gap": gap, "physical_bounds": bounds})
    assert main(["colour", str(path), "--csv", "-"]) == 0
    out = capsys.readouterr()
    assert f"warning: {bounds}" in out.err and f"warning: {gap}" in out.err
    assert {r["warnings"] for r in csv.DictReader(io.StringIO(out.out))} == {
        f"{bounds}; {gap}"}
    assert main(["colour", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == [bounds, gap]


def test_a_stored_standard_keeps_its_warnings_and_its_space(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A standard kept as a colour CSV carries its result's warnings in its warnings column:
    a comparison with it says them, prefixed 'standard:', as with the result file itself
    (they were dropped). An uncalibrated result's CSV as a standard is refused for its space
    (it was refused for 'columns ['L', 'a', 'b'] are missing')."""
    bounds = "the reconstruction is outside physical bounds: its maximum 1.33e+03 is above 1000"
    path = write_result(tmp_path / "red.h5", job_id=9, specimen="red", kind="uniform",
                        readings=[], samples=_samples(("R", "G", "B")), table=_lambert(),
                        colour={"source": {"calibration": _matrix()}},
                        provenance={"physical_bounds": bounds})
    std = tmp_path / "std.csv"
    assert main(["colour", str(path), "--csv", str(std)]) == 0
    capsys.readouterr()
    plain = _write(tmp_path / "plain.h5", _lambert(), {"calibration": _matrix()})
    for against in (path, std):
        assert main(["colour", str(plain), "--against", str(against), "--csv", "-"]) == 0
        out = capsys.readouterr()
        assert f"warning: standard: {bounds}" in out.err
        rows = list(csv.DictReader(io.StringIO(out.out)))
        assert rows and {r["warnings"] for r in rows} == {f"standard: {bounds}"}
    unc = _write(tmp_path / "unc.h5", _lambert(), {})
    unc_csv = tmp_path / "unc.csv"
    assert main(["colour", str(unc), "--csv", str(unc_csv)]) == 0
    capsys.readouterr()
    assert main(["colour", str(plain), "--against", str(unc_csv)]) == 2
    assert "holds uncalibrated sensor RGB, not CIELAB" in capsys.readouterr().err


def test_an_existing_csv_is_kept_unless_overwrite_says_to_replace_it(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`gonio colour --csv` replaced an existing CSV (a lab's master) without a word."""
    master = tmp_path / "master.csv"
    master.write_text("the lab's master\n")
    assert main(["colour", str(files["cal"]), "--csv", str(master)]) == 2
    err = capsys.readouterr().err
    assert f"--csv {master} already exists" in err and "--overwrite" in err, err
    assert master.read_text() == "the lab's master\n"
    assert main(["colour", str(files["cal"]), "--csv", str(master), "--overwrite"]) == 0
    assert len(list(csv.DictReader(master.open()))) > 0
