"""Colour of result files (gonio.result_colour): which conversion applies, the stored group,
linear sRGB for renderings and exports, stored standards."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.colour.chart import ColourMatrix
from gonio.brdf.colour.conditions import ColourError, ViewingConditions
from gonio.brdf.colour.spectral import SpectralBands
from gonio.brdf.tables.table import BRDFTable, from_function
from gonio.calibration import CalibratedScan
from gonio.figures import load_input
from gonio.result_colour import (
    colour_group,
    conversion_of,
    difference_csv,
    linear_srgb,
    read_standard_csv,
    result_report,
    srgb_view,
)
from gonio.results import read_result, write_result

WL = (450.0, 550.0, 650.0)


def _table(wl: tuple[float, ...] | None) -> BRDFTable:
    t = from_function(lambda i, o: np.tile([0.1, 0.2, 0.05], (i.shape[0], 1)),
                      ["a", "b", "c"], "t", dtype=np.float32)
    return BRDFTable.trusted(np.asarray(t.values), t.channels, "t", wl)


def _write(tmp: Path, table: BRDFTable, colour: dict | None, calibrated: bool = True) -> Path:
    cal = {"pairs": [{"light": "L1", "sensor": "S1", "factor": [1, 1, 1]}]} if calibrated \
        else {"pairs": []}
    s = CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
                       sensor_dirs=np.array([[0.0, 0.0, 1.0]]), stage_angles_deg=np.zeros(1),
                       values=np.ones((1, 1, 3)), channels=table.channels, calibration=cal)
    return write_result(tmp / f"r{np.random.randint(1e9)}.h5", job_id=1, specimen="s",
                        kind="uniform", readings=[], samples=s, table=table, colour=colour)


def test_which_conversion(tmp_path: Path) -> None:
    bands = SpectralBands(WL, (40.0, 40.0, 40.0))
    m = ColourMatrix(("a", "b", "c"), np.eye(3) * 90, ViewingConditions(), 1, 2, 24)
    assert conversion_of(read_result(_write(tmp_path, _table(None), None))) is None
    # The source's bands win over the table's bare centres (they carry the widths).
    res = read_result(_write(tmp_path, _table(WL), {"source": {"bands": bands.as_dict()}}))
    assert conversion_of(res) == bands
    res = read_result(_write(tmp_path, _table(WL), None))
    assert conversion_of(res) == SpectralBands(WL)
    res = read_result(_write(tmp_path, _table(None), {"source": {"calibration": m.as_dict()}}))
    assert isinstance(conversion_of(res), ColourMatrix)
    # Sensor units (no white reference): no colour, whatever the sensor.
    res = read_result(_write(tmp_path, _table(WL), None, calibrated=False))
    assert conversion_of(res) is None and linear_srgb(res) is None


def test_colour_group_records_why_there_is_no_colour() -> None:
    g = colour_group(_table(WL), {}, calibrated=False)
    assert g["report"]["space"] == "uncalibrated sensor RGB" and "sensor units" in g["note"]
    g = colour_group(_table(WL), {"error": "sensors differ"})
    assert g == {"source": {"error": "sensors differ"}, "error": "sensors differ"}
    g = colour_group(_table(WL), {"bands": {"centres_nm": [2000.0, 2100.0, 2200.0],
                                            "widths_nm": [10.0, 10.0, 10.0]}})
    assert "respond nowhere" in g["error"]
    assert colour_group(_table(WL), {})["report"]["space"] == "CIELAB"


def test_renderings_of_a_spectral_result_are_linear_srgb(tmp_path: Path) -> None:
    path = _write(tmp_path, _table(WL), None)
    rows = load_input(path, with_truth=False)
    table = rows[-1][1]
    assert table.channels == ("R", "G", "B")
    assert table.provenance["colour_space"]["space"].startswith("linear sRGB")
    res = read_result(path)
    srgb = linear_srgb(res)
    assert srgb is not None
    view = srgb_view(res, res.table)
    wi = np.array([[0.3, 0.0, np.sqrt(1 - 0.09)]])
    wo = np.array([[-0.3, 0.0, np.sqrt(1 - 0.09)]])
    assert view.eval(wi, wo) == pytest.approx(srgb[0].eval(wi, wo), rel=1e-3, abs=1e-5)
    plain = _write(tmp_path, _table(None), None)
    assert load_input(plain, with_truth=False)[-1][1].channels == ("a", "b", "c")


def test_stored_standard_errors(tmp_path: Path) -> None:
    p = tmp_path / "std.csv"
    p.write_text("illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "D65,10,MA98,45,15,50,1,2\nD50,10,MA98,45,25,50,1,2\n")
    with pytest.raises(ColourError, match="several conditions"):
        read_standard_csv(p)
    p.write_text("space,illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "uncalibrated sensor RGB,D65,10,MA98,45,15,50,1,2\n")
    with pytest.raises(ColourError, match="not CIELAB"):
        read_standard_csv(p)
    p.write_text("illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "D65,10,MA98,45,x,50,1,2\n")
    with pytest.raises(ColourError, match="row 2"):
        read_standard_csv(p)
    p.write_text("")
    with pytest.raises(ColourError, match="no rows"):
        read_standard_csv(p)
    # A repeated geometry (two readings of the standard): the last row silently won.
    p.write_text("illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "D65,10,MA98,45,15,50,1,2\nD65,10,MA98,45,25,40,1,2\n"
                 "D65,10,ma98,45,15,60,1,2\n")
    with pytest.raises(ColourError, match="rows 2 and 4 are both MA98 45as15 at azimuth 0"):
        read_standard_csv(p)
    # Conditions as typed in a spreadsheet read as written; unknown ones name the file.
    p.write_text("illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "d50,2°,MA98,45,15,50,1,2\n")
    assert read_standard_csv(p).conditions == ViewingConditions("D50", "2")
    p.write_text("illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "D66,10,MA98,45,15,50,1,2\n")
    with pytest.raises(ColourError, match=r"std.csv: unknown illuminant 'D66'"):
        read_standard_csv(p)
    p.write_text("illuminant,observer,instrument,incidence_deg,aspecular_deg,L,a,b\n"
                 "D65,10,MA98,45,15,50,1,2\n")
    std = read_standard_csv(p)
    assert std.lab is not None and std.lab[0] == pytest.approx([50, 1, 2])


#: Sharma, Wu and Dalal (2005), "The CIEDE2000 color-difference formula: implementation notes,
#: supplementary test data", Color Res. Appl. 30(1), Table 1, pairs 1 and 7: sample, standard,
#: their CIEDE2000.
SHARMA = (((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
          ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669))


def test_a_standard_saved_by_a_spreadsheet_reads_as_written(tmp_path: Path) -> None:
    """A stored standard edited in a spreadsheet of a decimal-comma locale comes back with a
    byte order mark, semicolons, decimal commas, CRLF, spaces, a column of its own and blank
    rows: the same CIELAB as the comma file, and CIEDE2000 against it is Sharma's."""
    from gonio.brdf.colour.instruments import Geometry
    from gonio.brdf.colour.report import CIELAB, ColourReport, compare

    head = ["space", "illuminant", "observer", "instrument", "incidence_deg", "aspecular_deg",
            "azimuth_deg", "L", "a", "b", "source", "warnings"]
    rows = [["CIELAB", "D65", "10", "MA98", "45", asp, "0", *(f"{v:.4f}" for v in std), "table",
             ""] for asp, (_, std, _) in zip(("15", "45"), SHARMA, strict=True)]
    comma = tmp_path / "std.csv"
    comma.write_text("\n".join(",".join(r) for r in [head, *rows]) + "\n", encoding="utf-8")
    sheet = tmp_path / "std-sheet.csv"
    lines = [" ; ".join([*head, "operator"])]
    lines += [";".join([*(c.replace(".", ",") for c in r), "anna"]) for r in rows]
    sheet.write_text("\ufeff" + "\r\n".join([lines[0], lines[1], ";;;", "", lines[2]]) + "\r\n",
                     encoding="utf-8")
    geos = tuple(Geometry("MA98", 45.0, a, 0.0) for a in (15.0, 45.0))
    sample = ColourReport("sample", ViewingConditions(), CIELAB, "test", (), geos,
                          np.zeros((2, 0)), None, np.array([s for s, _, _ in SHARMA]))
    for path in (comma, sheet):
        std = read_standard_csv(path)
        assert std.conditions == ViewingConditions("D65", "10")
        assert std.geometries == geos
        assert std.lab == pytest.approx(np.array([s for _, s, _ in SHARMA]))
        assert compare(sample, std).de00 == pytest.approx([d for _, _, d in SHARMA], abs=1e-4)
    # The differences' CSV says what was compared with what on every row.
    rows = list(csv.DictReader(io.StringIO(difference_csv(compare(sample, std)))))
    assert [(r["sample"], r["standard"]) for r in rows] == [("sample", "std-sheet")] * 2
    assert [float(r["dE00"]) for r in rows] == pytest.approx([d for _, _, d in SHARMA],
                                                             abs=1e-4)


def test_colour_statement_names_the_space_conditions_and_source() -> None:
    from gonio.brdf.colour.exportspace import conversion_record
    from gonio.result_colour import colour_statement

    text = colour_statement({**conversion_record(ViewingConditions("D50", "2"),
                                                 "spectral bands (31)"),
                             "clamped_at_zero": True})
    assert text.startswith("linear sRGB (Rec. 709 primaries, D65)")
    assert "(D50/2)" in text and "spectral bands (31)" in text and "clamped at 0" in text


def test_a_result_report_uses_the_readings_of_a_pair_at_an_instrument_geometry(
        tmp_path: Path) -> None:
    """A pair mounted at MA98's 45as15 (light at 45 degrees, sensor 30 degrees on the far
    side, plane turned 70 degrees in the lab) read twice the table's constant value at every
    stage angle: the report gives pi times the readings there and the table elsewhere."""
    table = _table(WL)
    az = np.deg2rad(70.0)
    light = np.array([np.sin(np.pi / 4) * np.cos(az), np.sin(np.pi / 4) * np.sin(az),
                      np.cos(np.pi / 4)])
    tv = np.deg2rad(30.0)
    sensor = np.array([-np.sin(tv) * np.cos(az), -np.sin(tv) * np.sin(az), np.cos(tv)])
    read = np.array([0.2, 0.4, 0.1])
    s = CalibratedScan(pairs=[("L1", "S1")], light_dirs=light[None], sensor_dirs=sensor[None],
                       stage_angles_deg=np.arange(8) * 22.5,
                       values=np.tile(read, (1, 8, 1)), channels=table.channels,
                       calibration={"pairs": [{"light": "L1", "sensor": "S1",
                                               "factor": [1, 1, 1]}]})
    path = write_result(tmp_path / "r.h5", job_id=1, specimen="s", kind="uniform", readings=[],
                        samples=s, table=table, colour=None)
    rep = result_report(read_result(path), instruments=["MA98"])
    names = [g.name for g in rep.geometries]
    assert [n for n, m in zip(names, rep.measured, strict=True) if m] == ["45as15"]
    k = names.index("45as15")
    np.testing.assert_allclose(rep.reflectance[k], np.pi * read, rtol=1e-5)
    others = [i for i in range(len(names)) if i != k]
    np.testing.assert_allclose(rep.reflectance[others],
                               np.tile(np.pi * np.array([0.1, 0.2, 0.05]), (len(others), 1)),
                               rtol=1e-5)


def test_near_specular_geometries_read_from_the_table_are_noted() -> None:
    """Colour at a near-specular geometry no pair read is the table's gloss flank, where the
    default design's worst was 7.4 dE00 (docs/colour.md): the report says which; a geometry
    a pair read, a far one (aspecular above 25) or a report without colour says nothing."""
    from dataclasses import replace

    from gonio.brdf.colour.report import colour_report
    from gonio.result_colour import NEAR_SPECULAR_DEG, near_specular_note

    bands = SpectralBands(WL, (40.0, 40.0, 40.0))
    report = colour_report(_table(WL), bands, instruments=["MA98"])
    near = [g.name for g in report.geometries if abs(g.aspecular_deg) <= NEAR_SPECULAR_DEG]
    # MA98's near-specular geometries, from the instrument's published aspecular angles.
    assert near == ["45as-15", "45as15", "45as25", "15as-15", "15as-5"]
    note = near_specular_note(report)
    assert note is not None and note.startswith(
        f"the geometries within 25 degrees of the specular direction ({', '.join(near)}) "
        "were read from the")
    assert "gonio design --colour" in note
    # The first two read by a pair: only the others are named.
    read = tuple(g.name in ("45as-15", "45as15") for g in report.geometries)
    note = near_specular_note(replace(report, measured=read))
    assert note is not None and "(45as25, 15as-15, 15as-5) were read" in note
    every = tuple(abs(g.aspecular_deg) <= NEAR_SPECULAR_DEG for g in report.geometries)
    assert near_specular_note(replace(report, measured=every)) is None
    assert near_specular_note(colour_report(_table(WL), None, instruments=["MA98"])) is None


def test_stored_standard_names_the_cell_that_is_not_a_number(tmp_path: Path) -> None:
    # A standard typed from an instrument's printout into a spreadsheet: a typo in one cell
    # and a gap in another. The error said "row 3: could not convert string to float: 'abc'"
    # (and for the gap, "... float: ''"): no column, nothing to do.
    p = tmp_path / "std.csv"
    head = "illuminant,observer,instrument,incidence_deg,aspecular_deg,azimuth_deg,L,a,b\n"
    p.write_text(head + "D65,10,MA98,45,15,,50,1,2\nD65,10,MA98,45,25,0,40,1,abc\n")
    with pytest.raises(ColourError) as err:
        read_standard_csv(p)
    assert "row 3, column b: 'abc' is not a number; correct or fill that cell" in str(err.value)
    p.write_text(head + "D65,10,MA98,45,15,0,,1,2\n")
    with pytest.raises(ColourError, match="row 2, column L: '' is not a number"):
        read_standard_csv(p)
    # An instrument gonio does not know names its row as well as the known ones.
    p.write_text(head + "D65,10,MA98,45,15,0,50,1,2\nD65,10,MA99,45,25,0,40,1,2\n")
    with pytest.raises(ColourError, match=r"std.csv: row 3: .*MA99"):
        read_standard_csv(p)
    # An empty azimuth cell is azimuth 0, as before.
    p.write_text(head + "D65,10,MA98,45,15,,50,1,2\n")
    report = read_standard_csv(p)
    assert report.geometries[0].azimuth_deg == 0.0


def test_stored_standard_from_a_labs_own_table(tmp_path: Path) -> None:
    # A standard copied from a lab's instrument report heads CIELAB "L*, a*, b*" and names
    # geometries as the instrument does ("45as15", "15as-45"); both were refused ("columns
    # ['L', 'a', 'b'] are missing; write the standard with 'gonio colour RESULT.h5 --csv'").
    # The numbers expected are the file's own.
    p = tmp_path / "std.csv"
    p.write_text("illuminant,observer,instrument,geometry,L*,a*,b*\n"
                 "D65,10,MA98,45as15,71.3,17.5,-65.9\nD65,10,MA98,15as-45,33.0,12.9,-45.8\n")
    report = read_standard_csv(p)
    assert [(g.instrument, g.incidence_deg, g.aspecular_deg, g.azimuth_deg)
            for g in report.geometries] == [("MA98", 45.0, 15.0, 0.0), ("MA98", 15.0, -45.0, 0.0)]
    assert report.lab.tolist() == [[71.3, 17.5, -65.9], [33.0, 12.9, -45.8]]
    # A geometry that is not one names its row; a missing column says which columns a
    # standard needs, not only how gonio writes one.
    p.write_text("illuminant,observer,instrument,geometry,L*,a*,b*\n"
                 "D65,10,MA98,45/15,71.3,17.5,-65.9\n")
    with pytest.raises(ColourError, match="row 2, column geometry: '45/15' is not an "):
        read_standard_csv(p)
    p.write_text("illuminant,observer,instrument,geometry,L*,a*\nD65,10,MA98,45as15,71.3,17.5\n")
    with pytest.raises(ColourError, match=r"\['b'\] are missing; a standard needs the columns"):
        read_standard_csv(p)


def test_a_difference_of_two_scans_says_where_both_sides_are_the_table() -> None:
    """Two scans of one layout compared: at near-specular geometries no pair read, both
    values come from reconstructed tables (the same prior), so their dE00 cannot show an
    error they share; a review saw 0.38 dE00 between two scans each about 12 from the truth.
    The note names exactly the near-specular geometries neither side read."""
    from dataclasses import replace

    from gonio.brdf.colour.report import colour_report
    from gonio.result_colour import NEAR_SPECULAR_DEG, shared_table_note

    bands = SpectralBands(WL, (40.0, 40.0, 40.0))
    report = colour_report(_table(WL), bands, instruments=["MA98"])
    near = [g.name for g in report.geometries if abs(g.aspecular_deg) <= NEAR_SPECULAR_DEG]
    assert near == ["45as-15", "45as15", "45as25", "15as-15", "15as-5"]  # MA98's, published
    note = shared_table_note(report, report)
    assert note is not None and note.startswith(f"at {', '.join(near)} both sides' colour")
    # A geometry read by a pair on either side is left out; all read on one side: nothing.
    mine = tuple(g.name == "45as-15" for g in report.geometries)
    theirs = tuple(g.name == "15as-5" for g in report.geometries)
    note = shared_table_note(replace(report, measured=mine), replace(report, measured=theirs))
    assert note is not None and note.startswith("at 45as15, 45as25, 15as-15 both sides'")
    every = tuple(abs(g.aspecular_deg) <= NEAR_SPECULAR_DEG for g in report.geometries)
    assert shared_table_note(report, replace(report, measured=every)) is None
    # Without colour (no CIELAB) there is no dE00 to qualify.
    assert shared_table_note(colour_report(_table(WL), None, instruments=["MA98"]),
                             report) is None
