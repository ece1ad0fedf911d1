"""The colour numbers of result files: which conversion a result's channels take, its colour
report under asked conditions, the ``/colour`` group written when a job finishes, and a stored
standard read back from a colour CSV (docs/colour.md).

How a result's channels become XYZ, first match wins:

1. ``/colour`` ``source`` ``{"bands": ...}``: the spectral sensor's bands as the rig config gave
   them (centres and widths or response tables);
2. the reconstruction's ``wavelengths_nm``: bands at those centres, widths from their spacing;
3. ``/colour`` ``source`` ``{"calibration": ...}``: a chart colour calibration of the sensor;
4. none: "uncalibrated sensor RGB".

A result whose samples are in sensor units (its calibration lists no pair: no white reference
was measured) has no colour whatever its sensor: its values are not reflectance factors.
"""

from __future__ import annotations

import csv
import io
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.colour.chart import ColourMatrix
from gonio.brdf.colour.conditions import ColourError, ViewingConditions
from gonio.brdf.colour.direct import ScanReadings
from gonio.brdf.colour.instruments import DEFAULT_INSTRUMENTS, Geometry, canonical_instrument
from gonio.brdf.colour.report import (
    CIELAB,
    ColourDifference,
    ColourReport,
    ToXYZ,
    colour_report,
)
from gonio.brdf.colour.report import (
    UNCALIBRATED as UNCALIBRATED_SPACE,
)
from gonio.brdf.colour.spectral import SpectralBands, bands_from_channels
from gonio.brdf.colour.spreadsheet import csv_rows
from gonio.brdf.tables.table import BRDFTable
from gonio.results import ResultFile


def conversion_of(res: ResultFile) -> ToXYZ | None:
    """How ``res``'s channels become XYZ (module docstring), or None (uncalibrated)."""
    if not in_reflectance(res.samples.calibration):
        return None
    source = (res.colour or {}).get("source") or {}
    if "bands" in source:
        return SpectralBands.from_dict(source["bands"])
    if res.table is not None:
        bands = bands_from_channels(res.table.channels, res.table.wavelengths_nm)
        if bands is not None:
            return bands
    if "calibration" in source:
        return ColourMatrix.from_dict(source["calibration"])
    return None


def result_report(
    res: ResultFile,
    conditions: ViewingConditions | None = None,
    instruments: Sequence[str] = DEFAULT_INSTRUMENTS,
    azimuths_deg: Sequence[float] = (0.0,),
) -> ColourReport:
    """The colour report of a result's reconstruction.

    Raises
    ------
    ColourError
        The result has no reconstruction (a calibration job), or its colour cannot be computed
        as asked.
    """
    if res.table is None:
        raise ColourError(
            f"result of job {res.attrs.get('job_id')} has no reconstructed BRDF (a "
            f"{res.attrs.get('kind')} job); colour needs a specimen scan"
        )
    table = res.table
    name = str(res.attrs.get("specimen") or table.name)
    if name != table.name:
        table = BRDFTable.trusted(np.asarray(table.values), table.channels, name,
                                  table.wavelengths_nm, table.provenance)
    return colour_report(table, conversion_of(res), conditions, instruments, azimuths_deg,
                         scan=scan_readings(res.samples))


#: The result provenance's warnings about the reconstruction, in the order exports list them
#: (``gonio.export.metadata.RECONSTRUCTION_WARNINGS``, a layer above this one; a test keeps
#: the two equal): the calibration measured at another exposure, the arc, a table outside
#: physical bounds, a predicted error far from the design's, a basis that does not fit, a
#: prior that is the specimen's own earlier result (gonio.finishing.own_result_prior), a
#: highlight no reading comes near (gonio.brdf.highlightread).
RECONSTRUCTION_WARNINGS = ("calibration_warning", "arc_warning", "physical_bounds",
                           "design_gap", "basis_misfit", "local_prior_own",
                           "highlight_not_read")


def colour_warnings(res: ResultFile, role: str = "") -> list[str]:
    """What a colour report of ``res`` must say beside its numbers: the reconstruction's own
    warnings (:data:`RECONSTRUCTION_WARNINGS`), which every export of the result carries too:
    e.g. the calibration was measured at another exposure than the scan's, so every value
    (and L*) is off by about the ratio (:func:`gonio.finishing.exposure_mismatch`), or the
    table is outside physical bounds where the readings do not determine it; [] when none.
    ``gonio colour`` and the API's colour route both say these, and write them into the
    CSV's ``warnings`` column. ``role`` (e.g. ``"standard"``) prefixes each sentence, for a
    comparison that reports the standard's warnings beside the sample's."""
    said = [str(res.provenance[k]) for k in RECONSTRUCTION_WARNINGS if res.provenance.get(k)]
    return [f"{role}: {w}" if role else w for w in said]


#: Geometries within this many degrees of the specular direction (aspecular angle) are the
#: ones a reconstruction is least sure of (docs/colour.md, "Measured").
NEAR_SPECULAR_DEG = 25.0


def near_specular_note(report: ColourReport) -> str | None:
    """A sentence when a report's colour at near-specular geometries (aspecular within
    :data:`NEAR_SPECULAR_DEG`) was read from the table rather than by a pair of the scan;
    None when every such geometry was read directly, or the report has no colour.

    Near the specular direction the table holds the gloss lobe's flank, which a design not
    made for the instrument does not read: on bench_colour's held-out specimens the default
    design's worst there was 7.4 dE00 (15as-5), a colour design's 2.1 at any geometry
    (docs/colour.md). ``gonio colour`` prints it as a note, the API and ``--json`` give it
    under ``notes``, the lab page adds it to the colour's caption.
    """
    if not report.calibrated:
        return None
    flags = report.measured or (False,) * len(report.geometries)
    labels = list(dict.fromkeys(
        g.name for g, m in zip(report.geometries, flags, strict=True)
        if not m and abs(g.aspecular_deg) <= NEAR_SPECULAR_DEG))
    if not labels:
        return None
    # Named as the near-specular ones: the other geometries marked "table" in the source
    # column were read from the table too, and a bare list read as if they were not.
    return (f"the geometries within {NEAR_SPECULAR_DEG:g} degrees of the specular direction "
            f"({', '.join(labels)}) were read from the reconstructed table, not by a pair of "
            "the scan: there the table is least certain (on held-out simulated specimens "
            "gonio's default designed layout's worst there was 7.4 dE00 and a colour design's "
            "2.1 at any geometry, docs/colour.md; a layout gonio did not design, such as a "
            "rig's own fixed pairs, was not benched and can be worse); for an instrument's "
            "numbers, scan with pairs designed for it (gonio design --colour INSTRUMENT)")


def shared_table_note(sample: ColourReport, standard: ColourReport) -> str | None:
    """A sentence when a difference compares, at near-specular geometries, two values both
    read from reconstructed tables (:func:`near_specular_note`); ``standard`` is another
    scan's report (the caller gives only those: an instrument's CSV or a stored standard
    was measured). Both come from the same prior where no pair read, so an error they share
    does not show in their dE00, and a small dE00 there says the scans agree, not that either
    is right. None when a pair read each such geometry on either side.

    A review compared two scans of a metallic paint on the simulated rig: 0.38 dE00 apart,
    each about 12 from the true material at 15as-5, and nothing said why the difference
    could not show it.
    """
    if not (sample.calibrated and standard.calibrated):
        return None
    theirs = standard.measured or (False,) * len(standard.geometries)
    read = {g.name for g, m in zip(standard.geometries, theirs, strict=True) if m}
    table = {g.name for g, m in zip(standard.geometries, theirs, strict=True) if not m}
    flags = sample.measured or (False,) * len(sample.geometries)
    both = list(dict.fromkeys(
        g.name for g, m in zip(sample.geometries, flags, strict=True)
        if not m and abs(g.aspecular_deg) <= NEAR_SPECULAR_DEG and g.name in table
        and g.name not in read))
    if not both:
        return None
    return (f"at {', '.join(both)} both sides' colour was read from their reconstructed "
            "tables, where no pair read: there both are the reconstruction's guess, so an "
            "error they share does not show in their dE00, and a small difference says the "
            "two scans agree, not that either is right (an instrument's reading of the "
            "standard would)")


def scan_readings(samples: Any) -> ScanReadings | None:
    """A result's ``/samples`` (or the samples a job is finishing with) as the colour report's
    scan readings, so that instrument geometries a pair measured use its readings
    (:mod:`gonio.brdf.colour.direct`); None when there are none."""
    values = np.asarray(samples.values, dtype=float)
    if values.ndim != 3 or values.shape[0] == 0:
        return None
    return ScanReadings(np.asarray(samples.light_dirs, dtype=float).reshape(-1, 3),
                        np.asarray(samples.sensor_dirs, dtype=float).reshape(-1, 3),
                        np.asarray(samples.stage_angles_deg, dtype=float), values)


def no_colour_reason(res: ResultFile, who: str | None = None) -> str | None:
    """Why ``res`` has no CIELAB, hence no CIEDE2000 against anything, and what to do; None
    when it has colour (or no reconstruction, which :func:`result_report` refuses itself).

    Two causes ask for different remedies: values in sensor units (no white reference was in
    effect: calibrate, then scan again) and reflectance factors from sensors with neither
    spectral bands nor a chart colour calibration (give them one, then scan again). A rebuild
    (``gonio jobs rebuild``) keeps the calibration and colour source the job was finished
    with, so it does not help either. The API answers it as the colour's ``no_colour`` (and
    as a refused comparison's reason), the lab page shows it in the caption instead of a
    silently missing ΔE00 column, and ``gonio colour`` prints it.

    Parameters
    ----------
    res
        The result file.
    who
        How the sentence names the result; default ``"job N"`` from the file.
    """
    if res.table is None or conversion_of(res) is not None:
        return None
    who = who or f"job {res.attrs.get('job_id', '?')}"
    if not in_reflectance(res.samples.calibration):
        return (f"{who} is uncalibrated: its values are sensor units, not 1/sr (no white "
                "reference calibration was in effect when it was scanned), so it has no "
                "CIELAB and no colour difference (CIEDE2000); calibrate the rig on the white "
                "reference (a calibration job), then scan the specimen again")
    return (f"{who}'s sensors have neither spectral bands nor a chart colour calibration: its "
            f"values are reflectance factors per channel ({UNCALIBRATED_SPACE}), with no "
            "CIELAB and no colour difference (CIEDE2000); give the sensors spectral bands or "
            "a chart colour calibration in the rig config (gonio colour-chart, "
            "docs/colour.md), then scan the specimen again")


def in_reflectance(calibration: Mapping[str, Any]) -> bool:
    """False when a result's calibration (``/samples`` attribute) says its values are in sensor
    units: a calibration that lists no pair. Files without the record are taken as calibrated."""
    return "pairs" not in calibration or bool(calibration["pairs"])


def report_instruments(rig_config_json: Any) -> tuple[str, ...]:
    """The instruments a finished scan's colour report covers: the defaults, then the one the
    rig's geometry was designed for (its ``[design]`` table's ``colour_instrument``, written
    by ``gonio design --colour``) when that is another.

    Parameters
    ----------
    rig_config_json : the rig config as a job's provenance records it (JSON text), or None
    """
    from gonio.designgap import design_expectation

    design = design_expectation(rig_config_json)
    extra = None if design is None else design.colour_instrument
    if extra is None or extra in DEFAULT_INSTRUMENTS:
        return DEFAULT_INSTRUMENTS
    return (*DEFAULT_INSTRUMENTS, extra)


def colour_group(table: BRDFTable, source: Mapping[str, Any],
                 calibrated: bool = True, scan: ScanReadings | None = None,
                 instruments: Sequence[str] = DEFAULT_INSTRUMENTS) -> dict[str, Any]:
    """The ``/colour`` attributes of a new result: the source and the report at
    ``instruments``' geometries (:func:`report_instruments`).

    ``scan``: the readings the table was reconstructed from; instrument geometries one of its
    pairs measured take their value from it (:mod:`gonio.brdf.colour.direct`).

    ``calibrated`` False (values in sensor units) gives a report in uncalibrated sensor units
    with a note saying why.

    A report that cannot be computed (bands outside the visible, a calibration for other
    channels) is stored as its reason, so the measurement is kept and the reason is visible.
    """
    out: dict[str, Any] = {"source": dict(source)}
    if "error" in source:
        out["error"] = source["error"]
        return out
    if not calibrated:
        out["note"] = ("values in sensor units (no white reference calibration): no "
                       "colour until the rig is calibrated")
    try:
        out["report"] = colour_report(table, _conversion(table, source, calibrated),
                                      instruments=instruments, scan=scan).as_dict()
    except ColourError as exc:
        out["error"] = str(exc)
    return out


def _conversion(table: BRDFTable, source: Mapping[str, Any],
                calibrated: bool) -> ToXYZ | None:
    """:func:`conversion_of` for a table and source not yet in a result file."""
    if not calibrated or "error" in source:
        return None
    if "bands" in source:
        return SpectralBands.from_dict(source["bands"])
    if (b := bands_from_channels(table.channels, table.wavelengths_nm)) is not None:
        return b
    if "calibration" in source:
        return ColourMatrix.from_dict(source["calibration"])
    return None


def table_for_fits(table: BRDFTable, source: Mapping[str, Any],
                   calibrated: bool) -> BRDFTable:
    """The table the export fits (factored, principled: what glTF and MaterialX are written
    from) are made of: linear sRGB from XYZ when the channels have colour, else the table.

    A spectral table's fits on its bands would give renderers the first three bands as R, G,
    B (and cost ten times the time); a chart-calibrated sensor's raw channels are not sRGB.
    """
    from gonio.brdf.colour.exportspace import linear_srgb_table
    from gonio.brdf.colour.report import conversion_label

    try:
        conv = _conversion(table, source, calibrated)
        if conv is None:
            return table
        return linear_srgb_table(table, conv, ViewingConditions(), conversion_label(conv))
    except ColourError:
        return table


# ---------------------------------------------------------------------------- stored standards
STANDARDS_DIR = "standards"
"""The folder of a daemon's data directory that holds its stored colour standards: colour CSVs
(``gonio colour RESULT.h5 --csv NAME.csv``, or edited in a spreadsheet) that
``GET /api/v1/jobs/{id}/colour?against=NAME`` compares with (:func:`stored_standard`)."""

_STANDARD_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._ -]{0,99}$")


class UnknownStandard(LookupError):
    """No stored standard of that name (:func:`stored_standard`); the message names the
    folder and the standards it holds."""


def standard_names(folder: str | os.PathLike[str]) -> list[str]:
    """The stored standards of ``folder`` (a data directory's :data:`STANDARDS_DIR`): the
    stems of its ``.csv`` files, sorted; empty when it does not exist."""
    try:
        return sorted(p.stem for p in Path(folder).iterdir()
                      if p.suffix.lower() == ".csv" and p.is_file())
    except OSError:
        return []


def stored_standard(folder: str | os.PathLike[str],
                    name: str) -> tuple[ColourReport, list[str]]:
    """A stored standard by name: ``folder/NAME.csv`` read by :func:`read_standard` (its
    colour report and warnings). ``name`` may end in ``.csv``; it names a file of ``folder``
    only (letters, digits, ``. _ -`` and spaces, no path), so a request cannot name any
    other file.

    Raises
    ------
    UnknownStandard
        No such file (or a name that cannot be one), naming ``folder`` and what it holds.
    ColourError
        The file cannot be read as a standard (:func:`read_standard`'s reasons).
    """
    path = _standard_path(folder, name, "a stored standard is a colour CSV there (gonio "
                          "colour RESULT.h5 --csv FILE.csv), named without .csv; a job's "
                          "result is named by its id")
    report, said = read_standard(path)
    return report, said


def _standard_path(folder: str | os.PathLike[str], name: str, advice: str) -> Path:
    """The file of the stored standard ``name`` (a trailing ``.csv`` dropped), which exists;
    :class:`UnknownStandard` naming ``folder``, what it holds and ``advice`` otherwise."""
    folder = Path(folder)
    stem = name[:-4] if name.lower().endswith(".csv") else name
    path = folder / f"{stem}.csv"
    if not _STANDARD_NAME.match(stem) or not path.is_file():
        held = standard_names(folder)
        have = (f"it holds {', '.join(held)}" if held else "it holds none")
        raise UnknownStandard(f"no stored colour standard {name!r} in {folder} ({have}); "
                              f"{advice}")
    return path


def delete_standard(folder: str | os.PathLike[str], name: str) -> str:
    """Remove the stored standard ``name`` of ``folder`` (its CSV file; ``name`` may end in
    ``.csv``, and names a file of ``folder`` only, as in :func:`stored_standard`).

    Returns
    -------
    str
        The name it was stored under (without ``.csv``).

    Raises
    ------
    UnknownStandard
        No such standard (or a name that cannot be one), naming ``folder`` and the standards
        it holds.
    """
    path = _standard_path(folder, name, "nothing was removed; the names are the stored "
                          "standards' as listed (GET /api/v1/colour-standards), without .csv")
    path.unlink()
    return path.stem


def store_standard(folder: str | os.PathLike[str], name: str,
                   text: str) -> tuple[ColourReport, list[str], bool]:
    """Keep a colour CSV as the stored standard ``name`` of ``folder`` (created if needed),
    once it reads as one (:func:`parse_standard`); a standard already stored under that name
    is replaced, atomically, and nothing is written when the text is refused.

    Returns
    -------
    The standard's colour report and warnings, and whether it replaced one.

    Raises
    ------
    ColourError
        A name that cannot be a stored standard's (letters, digits, ``. _ -`` and spaces, no
        path), or a text that is not a colour CSV (what is wrong in it).
    """
    from gonio.atomicfile import write_atomically

    stem = name[:-4] if name.lower().endswith(".csv") else name
    if not _STANDARD_NAME.match(stem):
        raise ColourError(
            f"{name!r} cannot name a stored standard: use letters, digits, '.', '_', '-' and "
            "spaces (up to 100, starting with a letter or digit), no folders")
    report, said = parse_standard(text.removeprefix("\ufeff"), f"standard {stem!r}", stem)
    path = Path(folder) / f"{stem}.csv"
    replaced = path.is_file()
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, text)
    return report, said, replaced


def read_standard_csv(path: str | os.PathLike[str]) -> ColourReport:
    """A standard's colour from a colour CSV (:func:`read_standard`, without its warnings)."""
    return read_standard(path)[0]


def read_standard(path: str | os.PathLike[str]) -> tuple[ColourReport, list[str]]:
    """A standard's colour from a CSV written by ``gonio colour --csv`` (or by hand, same
    columns: space, illuminant, observer, instrument, incidence_deg, aspecular_deg,
    azimuth_deg, L, a, b; other columns are ignored).

    The file may have been saved by a spreadsheet: a byte order mark, cells separated by
    semicolons or tabs with decimal commas, spaces around the cells, blank rows
    (:func:`gonio.brdf.colour.spreadsheet.csv_rows`).

    Returns
    -------
    ColourReport, and the standard's warnings: the distinct non-empty values of its
    ``warnings`` column (what its result said beside its numbers when the CSV was written,
    :func:`colour_warnings`), to travel with a comparison as a result file standard's do.

    Raises
    ------
    ColourError
        Naming the file and what is missing or wrong.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ColourError(f"cannot read standard {p}: {exc}") from None
    return parse_standard(text, str(p), p.stem)


#: Header cells a lab's own table uses for the colour CSV's columns (compared lower-case,
#: without spaces): CIELAB as instruments and papers print it.
_STANDARD_ALIASES = {"l*": "L", "a*": "a", "b*": "b"}

#: An instrument geometry's name, as instruments and gonio print it: "45as15", "15as-45".
_GEOMETRY_NAME = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*as\s*([+-]?\d+(?:\.\d+)?)\s*$",
                            re.IGNORECASE)


def _standard_columns(header: list[str], rows: list[dict[str, str]], source: str) -> None:
    """Read a lab's own standard's columns as the colour CSV's, in place: ``L*``, ``a*``,
    ``b*`` as ``L``, ``a``, ``b``, and a ``geometry`` column of names such as ``45as15`` as
    ``incidence_deg`` and ``aspecular_deg`` (when those are absent).

    A standard copied from an instrument's report said "columns ['L', 'a', 'b'] are
    missing; write the standard with 'gonio colour RESULT.h5 --csv FILE'": a lab comparing
    with its own instrument has no gonio result to write it from.
    """
    for cell in header:
        alias = _STANDARD_ALIASES.get(cell.replace(" ", "").lower())
        if alias is not None and alias not in header:
            for r in rows:
                r[alias] = r.get(cell, "")
    if "geometry" in header and not {"incidence_deg", "aspecular_deg"} & set(header):
        for n, r in enumerate(rows, start=2):
            m = _GEOMETRY_NAME.match(r.get("geometry", ""))
            if m is None:
                raise ColourError(
                    f"{source}: row {n}, column geometry: {r.get('geometry', '')!r} is not an "
                    "instrument geometry such as 45as15 or 15as-45 (incidence, 'as', "
                    "aspecular angle in degrees)")
            r["incidence_deg"], r["aspecular_deg"] = m.group(1), m.group(2)


def parse_standard(text: str, source: str, name: str) -> tuple[ColourReport, list[str]]:
    """A standard's colour from a colour CSV's text (:func:`read_standard`'s rules).

    Parameters
    ----------
    text : the CSV, decoded
    source : how the errors name it (a file's path, "standard 'NAME'")
    name : the standard's name in the report and its comparisons

    Raises
    ------
    ColourError
        Naming ``source`` and what is missing or wrong.
    """
    p = source
    cells = csv_rows(text)
    header = cells[0] if cells else []
    rows = [dict(zip(header, row + [""] * (len(header) - len(row)), strict=False))
            for row in cells[1:]]
    need = ("illuminant", "observer", "instrument", "incidence_deg", "aspecular_deg", "L", "a",
            "b")
    if not rows:
        raise ColourError(f"{p}: no rows; a standard is a colour CSV (gonio colour --csv)")
    _standard_columns(header, rows, p)
    # An uncalibrated result's CSV has no L, a, b: say why, not which columns are missing.
    if any((r.get("space") or CIELAB) != CIELAB for r in rows):
        raise ColourError(f"{p}: holds {rows[0].get('space')}, not CIELAB; a standard must be "
                          "colour from a spectral or chart-calibrated sensor")
    missing = [c for c in need if c not in rows[0]]
    if missing:
        raise ColourError(
            f"{p}: columns {missing} are missing; a standard needs the columns illuminant, "
            "observer, instrument, incidence_deg and aspecular_deg (or geometry, e.g. 45as15), "
            "L, a and b (or L*, a*, b*), one row per geometry, e.g. 'D65,10,MA98,45,15,71.3,"
            "17.5,-65.9'; 'gonio colour RESULT.h5 --csv FILE' writes one from a result")
    # As a person types them in a spreadsheet: "d65", "10°".
    conds = {(r["illuminant"].upper(), r["observer"].rstrip("°º")) for r in rows}
    if len(conds) != 1:
        raise ColourError(f"{p}: rows under several conditions {sorted(conds)}; keep one")
    try:
        cond = ViewingConditions(*next(iter(conds)))
    except ColourError as exc:
        raise ColourError(f"{p}: {exc}") from None
    geos, lab = [], []
    for n, r in enumerate(rows, start=2):

        def number(column: str, row: dict[str, str] = r, line: int = n) -> float:
            # "could not convert string to float: 'abc'" named neither the column nor what
            # to do; a standard typed into a spreadsheet has its gaps and typos in one cell.
            cell = row.get(column) or ""
            try:
                return float(cell)
            except ValueError:
                raise ColourError(
                    f"{p}: row {line}, column {column}: {cell!r} is not a number; correct or "
                    "fill that cell (a number, e.g. 45 or 12.5) and read the standard "
                    "again") from None

        try:
            instrument = canonical_instrument(r["instrument"])
        except (ColourError, ValueError, TypeError) as exc:
            raise ColourError(f"{p}: row {n}: {exc}") from None
        geos.append(Geometry(instrument, number("incidence_deg"), number("aspecular_deg"),
                             number("azimuth_deg") if r.get("azimuth_deg") else 0.0))
        lab.append([number("L"), number("a"), number("b")])
    lab_arr = np.asarray(lab, dtype=float)
    if not np.isfinite(lab_arr).all():
        raise ColourError(f"{p}: a CIELAB value is not a finite number")
    first: dict[Geometry, int] = {}
    for n, g in enumerate(geos, start=2):
        if g in first:
            # A comparison takes one standard per geometry: a second row would silently win.
            raise ColourError(
                f"{p}: rows {first[g]} and {n} are both {g.instrument} {g.name} at azimuth "
                f"{g.azimuth_deg:g}; keep one row per geometry (average repeated readings)")
        first[g] = n
    said = list(dict.fromkeys(w for r in rows if (w := r.get("warnings") or "")))
    return ColourReport(name, cond, CIELAB, "stored standard", (), tuple(geos),
                        np.zeros((len(geos), 0)), None, lab_arr), said


def difference_csv(diff: ColourDifference, warnings: Sequence[str] = ()) -> str:
    """CIEDE2000 rows as CSV text (header first), each stating the conditions, what was
    compared (``sample`` and ``standard``: the names the JSON's ``difference`` gives) and, in
    a last ``warnings`` column, the sentences that must travel with the numbers (joined by
    ``"; "``; empty when there are none)."""
    buf = io.StringIO()
    rows = diff.rows()
    w = csv.DictWriter(buf, fieldnames=["illuminant", "observer", "sample", "standard",
                                        *rows[0].keys(), "warnings"], lineterminator="\n")
    w.writeheader()
    said = "; ".join(warnings)
    for r in rows:
        w.writerow({"illuminant": diff.conditions.illuminant,
                    "observer": diff.conditions.observer,
                    "sample": diff.sample_name, "standard": diff.standard_name,
                    **{k: (f"{v:g}" if k.endswith("_deg") else f"{v:.4f}")
                       if isinstance(v, float) else v for k, v in r.items()},
                    "warnings": said})
    return buf.getvalue()


def colour_source(rig_config_json: str | None, sensors: Sequence[str]) -> dict[str, Any]:
    """How the measuring sensors' channels become XYZ, from the rig config a job ran with.

    Parameters
    ----------
    rig_config_json : the rig config as JSON (the result's ``rig_config`` provenance), or None
    sensors : names of the sensors the job's pairs used

    Returns
    -------
    dict
        ``{"bands": SpectralBands dict}``, ``{"calibration": ColourMatrix dict}``, ``{}`` for
        uncalibrated sensor RGB, or ``{"error": why}`` when the sensors disagree (one
        reconstruction mixes their channels, so their colour must be one).
    """
    if not rig_config_json:
        return {}
    import json

    cfg = json.loads(rig_config_json)
    by_name = {s.get("name"): s for s in cfg.get("sensors", [])}
    found = []
    for name in dict.fromkeys(sensors):
        s = by_name.get(name) or {}
        if s.get("wavelengths_nm") is not None:
            found.append({"bands": SpectralBands(
                tuple(s["wavelengths_nm"]),
                None if s.get("bandwidths_nm") is None else tuple(s["bandwidths_nm"]),
                None if s.get("response_nm") is None else tuple(s["response_nm"]),
                None if s.get("responses") is None
                else tuple(tuple(r) for r in s["responses"])).as_dict()})
        elif s.get("colour_calibration") is not None:
            cal = s["colour_calibration"]
            found.append({"calibration": ColourMatrix.from_dict(
                {**cal, "channels": s.get("channels", [])}).as_dict()})
        else:
            found.append({})
    if not found:
        return {}
    if any(f != found[0] for f in found[1:]):
        return {"error": "the scan's sensors have different colour descriptions (bands or "
                         "calibrations); one reconstruction mixes their channels, so measure "
                         "with sensors of one colour description"}
    return found[0]


# ---------------------------------------------------------------------------- linear sRGB
def linear_srgb(res: ResultFile) -> tuple[BRDFTable, dict[str, Any]] | None:
    """A result's reconstruction in linear sRGB, and the record of the conversion; None when
    its channels have no colour (uncalibrated sensor RGB) or it has no reconstruction.

    The one function exports and renderings call to state their colour space (docs/colour.md):
    a spectral or chart-calibrated result becomes ``R, G, B`` linear sRGB computed from XYZ
    (D65/10 by default, Bradford-adapted to sRGB's D65); an uncalibrated result's values are
    not a colour space and get None (write them labelled "uncalibrated sensor RGB").
    """
    from gonio.brdf.colour.exportspace import linear_srgb_table
    from gonio.brdf.colour.report import conversion_label

    if res.table is None:
        return None
    conv = conversion_of(res)
    if conv is None:
        return None
    table = linear_srgb_table(res.table, conv, ViewingConditions(), conversion_label(conv))
    return table, dict(table.provenance["colour_space"])


def colour_statement(record: Mapping[str, Any]) -> str:
    """One sentence for a result's ``colour_space`` provenance from a conversion record
    (:func:`gonio.brdf.colour.exportspace.conversion_record`): what export readers see in
    every exported file's ``colour_space`` (gonio.export.metadata)."""
    return (f"{record['space']}, computed from CIE XYZ ({record['xyz_conditions']}) of "
            f"{record['channels_to_xyz']} by {record['library']}, "
            f"{record['chromatic_adaptation']} adaptation to D65"
            + (", negative components clamped at 0" if record.get("clamped_at_zero") else ""))


def uncalibrated_record() -> dict[str, Any]:
    """What an export states for a result without colour: its values' space."""
    return {"space": UNCALIBRATED_SPACE,
            "note": "the sensor's channels as measured, in 1/sr; no colour space "
                    "(docs/colour.md: spectral bands or a chart calibration give one)"}


def srgb_view(res: ResultFile, brdf: Any) -> Any:
    """``brdf`` (the result's table or its simulated truth, channels as the result's) seen in
    linear sRGB, for renderings; ``brdf`` itself when the result has no colour."""
    from gonio.brdf.colour.exportspace import srgb_matrix

    conv = conversion_of(res)
    if conv is None or res.table is None:
        return brdf
    return _SrgbView(brdf, srgb_matrix(conv, res.table.n_channels, ViewingConditions()))


class _SrgbView:
    """A BRDF whose channels are mapped to linear sRGB by a (3, C) matrix, clamped at 0."""

    channels = ("R", "G", "B")

    def __init__(self, brdf: Any, matrix: np.ndarray) -> None:
        self.brdf = brdf
        self.matrix = matrix
        self.name = getattr(brdf, "name", "brdf")

    def eval(self, wi: Any, wo: Any) -> np.ndarray:
        v = np.asarray(self.brdf.eval(wi, wo), dtype=float)
        return np.maximum(np.nan_to_num(v) @ self.matrix.T, 0.0)
