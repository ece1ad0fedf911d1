"""``gonio colour RESULT.h5 [--against STD]``: the colour numbers a colour lab reads; and
``gonio colour-chart CHART.csv``: an RGB sensor's colour calibration from a chart.

CIELAB at the aspecular geometries of multi-angle spectrophotometers, the flop index, and
CIEDE2000 against a standard (another result file, a colour CSV written by this command, or a
stored standard of the data directory named as the lab page and the API name it),
under a stated illuminant and observer (docs/colour.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from gonio.cli import UsageError

#: The core's names (gonio.brdf.colour: conditions.ILLUMINANTS, instruments.INSTRUMENTS and
#: DEFAULT_INSTRUMENTS), repeated so building the parser does not import colour-science; a
#: test keeps them equal.
ILLUMINANTS = ("D65", "D50", "A", "C", "D55", "D75", "FL2", "FL11")
INSTRUMENTS = ("MA68", "MA98", "BYK-mac", "MultiFX10")
DEFAULT_INSTRUMENTS = ("MA98", "BYK-mac")


def register(sub: Any) -> None:
    p = sub.add_parser(
        "colour", aliases=["color"],
        help="CIELAB, flop index and CIEDE2000 of a result at instrument geometries",
        description="The colour of a result's reconstructed BRDF at the aspecular geometries "
        "of multi-angle spectrophotometers (MA68, MA98, BYK-mac, MultiFX10): CIELAB (and XYZ) "
        "under a stated illuminant and observer, the X-Rite flop index, and with --against the "
        "CIEDE2000 difference from a standard. Spectral sensors give colour through their "
        "bands, RGB sensors through a chart colour calibration; other sensors' values are "
        "printed as 'uncalibrated sensor RGB'. See docs/colour.md.",
    )
    p.add_argument("result", type=Path, help="a gonio result file (HDF5)")
    p.add_argument("--against", default=None, metavar="STD",
                   help="the standard: another result file (.h5), a colour CSV written by "
                   "'gonio colour --csv', or the name of a stored standard (a colour CSV in "
                   "the data directory's standards/ folder, as the lab page and the API name "
                   "them); prints CIEDE2000 per geometry")
    p.add_argument("--data-dir", type=Path, default=None, metavar="DIR",
                   help="the data directory whose stored standards --against may name (the "
                   "daemon's; default: the result's own, when the result file is in its "
                   "results/ folder)")
    p.add_argument("--csv", type=Path, default=None, metavar="FILE",
                   help="also write the numbers as CSV (the colour table, or with --against "
                   "the differences); '-' writes CSV to standard output instead of the table")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the --csv file if it exists (without it an existing file is "
                   "refused, e.g. a stored standard's CSV)")
    p.add_argument("--json", action="store_true", help="print everything as JSON")
    p.add_argument("--illuminant", default="D65", choices=list(ILLUMINANTS),
                   help="CIE illuminant (default D65)")
    p.add_argument("--observer", default="10", choices=["10", "2"],
                   help="CIE 1964 10 degree (default) or CIE 1931 2 degree observer")
    p.add_argument("--instrument", action="append", default=None, metavar="NAME",
                   help=f"instrument geometries to report ({', '.join(INSTRUMENTS)}; repeat; "
                   f"default {' and '.join(DEFAULT_INSTRUMENTS)})")
    p.add_argument("--azimuth", default="0", metavar="DEG[,DEG...]",
                   help="specimen azimuths of the plane of incidence, degrees, comma separated "
                   "(default 0: along the holder mark); more than one shows anisotropy")
    p.set_defaults(func=run)

    c = sub.add_parser(
        "colour-chart", aliases=["color-chart"],
        help="fit an RGB sensor's colour calibration from a chart of known reflectances",
        description="Fit the calibration taking a sensor's reflectance factors to CIE XYZ from "
        "a chart file (CSV: patch, the sensor's channel readings, the patches' reference "
        "reflectance per wavelength; docs/colour.md): a 3 x C matrix or, for 3 channels, a "
        "root-polynomial correction, whichever predicts left-out patches better; print its "
        "residual CIEDE2000 on the patches, and write the [sensors.colour_calibration] table "
        "for the rig config.",
    )
    c.add_argument("chart", type=Path, help="the chart file (CSV)")
    c.add_argument("--channels", default=None, metavar="A,B,C",
                   help="the sensor's channels in its order; other columns of the chart "
                   "are left out (default: every column not headed by a wavelength)")
    c.add_argument("--illuminant", default="D65", choices=list(ILLUMINANTS))
    c.add_argument("--observer", default="10", choices=["10", "2"])
    c.add_argument("--method", default=None, choices=["linear", "root-polynomial"],
                   help="the calibration's form (default: chosen on the chart, by leave-one-"
                   "patch-out CIEDE2000)")
    c.add_argument("-o", "--output", type=Path, default=None,
                   help="write the TOML table to this file (default: print it)")
    c.set_defaults(func=run_chart)


def run_chart(args: argparse.Namespace) -> int:
    import tomli_w

    from gonio.brdf.colour.chart import fit_matrix, read_chart
    from gonio.brdf.colour.conditions import ViewingConditions

    if not args.chart.is_file():
        raise UsageError(f"chart file {args.chart} does not exist")
    if args.output is not None and not args.output.parent.is_dir():
        raise UsageError(f"-o {args.output}: folder {args.output.parent} does not exist")
    channels = None
    if args.channels is not None:
        channels = [x.strip() for x in args.channels.split(",") if x.strip()]
        if not channels:
            raise UsageError("--channels: give the channel names separated by commas")
    m = fit_matrix(read_chart(args.chart, channels),
                   ViewingConditions(args.illuminant, args.observer), channels,
                   source=args.chart.name, method=args.method)
    table = {"matrix": [[round(float(x), 6) for x in row] for row in m.matrix],
             "method": m.method,
             "illuminant": m.conditions.illuminant, "observer": m.conditions.observer,
             "residual_median_de00": round(m.residual_median_de00, 4),
             "residual_max_de00": round(m.residual_max_de00, 4),
             "loo_median_de00": round(m.loo_median_de00, 4),
             "n_patches": m.n_patches, "source": m.source, "channels": list(m.channels)}
    text = ("# paste under the sensor's [[sensors]] entry (channels "
            f"{', '.join(m.channels)}), docs/colour.md\n"
            + tomli_w.dumps({"sensors": {"colour_calibration": table}}))
    print(f"colour calibration ({m.method}) of channels {', '.join(m.channels)} from "
          f"{m.n_patches} patches ({m.conditions.label}): residual median "
          f"{m.residual_median_de00:.2f}, max {m.residual_max_de00:.2f} dE00; each patch "
          f"predicted without it: median {m.loo_median_de00:.2f} dE00")
    if args.output is not None:
        args.output.write_text(text, encoding="utf-8")
        print(f"wrote {args.output}")
    else:
        print(text, end="")
    return 0


def _azimuths(text: str) -> list[float]:
    try:
        out = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UsageError(f"--azimuth {text!r}: give degrees separated by commas, e.g. "
                         "0,45,90") from None
    if not out or len(out) > 36 or not all(-360 <= a <= 360 for a in out):
        raise UsageError(f"--azimuth {text!r}: give 1 to 36 angles within -360..360 degrees")
    return out


def _standards_folder(result: Path, data_dir: Path | None) -> Path | None:
    """The stored standards' folder ``--against`` names are looked up in: ``--data-dir``'s,
    else the result's data directory's when the result is one of its ``results/`` files."""
    from gonio.result_colour import STANDARDS_DIR

    if data_dir is not None:
        return data_dir / STANDARDS_DIR
    parent = result.resolve().parent
    return parent.parent / STANDARDS_DIR if parent.name == "results" else None


def _standard(against: str, folder: Path | None, conditions: Any, instruments: list[str],
              azimuths: list[float]) -> tuple[Any, list[str]]:
    """The standard's colour report and its warnings (a stored CSV carries its own):
    ``against`` is a result file, a colour CSV, or a stored standard's name in ``folder``."""
    from gonio.result_colour import (
        UnknownStandard,
        colour_warnings,
        no_colour_reason,
        read_standard,
        result_report,
        standard_names,
        stored_standard,
    )
    from gonio.results import read_result

    path = Path(against)
    if not path.is_file():
        if folder is None:
            raise UsageError(
                f"--against {against}: no such file, and no data directory to look for a "
                "stored standard of that name in (the result is not in a data directory's "
                "results/ folder); give --data-dir DIR (the daemon's data directory), or a "
                "result file (.h5) or colour CSV")
        try:
            report, said = stored_standard(folder, against)
        except UnknownStandard:
            held = standard_names(folder)
            raise UsageError(
                f"--against {against}: no such file, and no stored standard of that name in "
                f"{folder} ({'it holds ' + ', '.join(held) if held else 'it holds none'}); "
                "give a result file (.h5), a colour CSV, or a stored standard's name") from None
        return report, [f"standard ({report.name}): {w}" for w in said]
    if path.suffix.lower() == ".csv":
        std_csv, said = read_standard(path)
        return std_csv, [f"standard: {w}" for w in said]
    std = read_result(path)
    no_colour = no_colour_reason(std, path.name)
    if no_colour is not None:
        raise UsageError(f"no dE00 against {path}: {no_colour}")
    return (result_report(std, conditions, instruments, azimuths),
            colour_warnings(std, "standard"))


def _table(report: Any, no_colour: str | None = None, in_reflectance: bool = True) -> str:
    """The colour table as a person reads it; ``no_colour`` says why it has no CIELAB;
    ``in_reflectance`` False: the values are pi times sensor units (no white reference was in
    effect), not reflectance factors, and the table says so."""
    # An uncalibrated report names no illuminant or observer: its values depend on neither.
    lines = [f"{report.name}: {report.space}, {report.conditions.label} ({report.conversion})"
             if report.calibrated else f"{report.name}: {report.space}"]
    if report.lab is None:
        head = "instrument  geometry  azimuth  " + "  ".join(f"{c:>8}" for c in report.channels)
        lines.append(head)
        for g, r in zip(report.geometries, report.reflectance, strict=True):
            lines.append(f"{g.instrument:<10}  {g.name:<8}  {g.azimuth_deg:>7g}  "
                         + "  ".join(f"{v:8.4f}" for v in r))
        units = ("reflectance factors per channel (pi f)" if in_reflectance else
                 "pi times the sensor units per channel (uncalibrated: not reflectance factors)")
        lines.append(f"{units}; " + (
            no_colour or "no CIELAB without spectral bands or a chart colour calibration "
            "(docs/colour.md)"))
        return "\n".join(lines)
    lines.append("instrument  geometry  azimuth        L*       a*       b*       C*      h"
                 "  source")
    flags = report.measured or (False,) * len(report.geometries)
    for row, g, m in zip(report.rows(), report.geometries, flags, strict=True):
        lines.append(f"{g.instrument:<10}  {g.name:<8}  {g.azimuth_deg:>7g}  {row['L']:8.2f} "
                     f"{row['a']:8.2f} {row['b']:8.2f} {row['C']:8.2f} {row['h_deg']:6.1f}"
                     f"  {'pair' if m else 'table'}")
    for key, fi in report.flop.items():
        lines.append(f"flop index {key.replace('@', ' at azimuth ')}: {fi:.2f}")
    if any(flags):
        lines.append("source: 'pair' = read directly by a pair of the scan at that geometry, "
                     "'table' = read from the reconstructed table")
    return "\n".join(lines)


def _diff_table(diff: Any) -> str:
    lines = [f"{diff.sample_name} against {diff.standard_name}: CIEDE2000, "
             f"{diff.conditions.label}",
             "instrument  geometry  azimuth       dL*      da*      db*     dE00"]
    for row, g in zip(diff.rows(), diff.geometries, strict=True):
        lines.append(f"{g.instrument:<10}  {g.name:<8}  {g.azimuth_deg:>7g}  {row['dL']:8.2f} "
                     f"{row['da']:8.2f} {row['db']:8.2f} {row['dE00']:8.2f}")
    per = diff.by_instrument()
    lines.append(f"max dE00 {diff.de00.max():.2f}, mean {diff.mean_de00:.2f} over the "
                 f"{diff.distinct_geometries} distinct geometries")
    if len(per) > 1:  # shared angles are in both instruments' rows; each set has its own mean
        lines.extend(f"  {name}: max {p['max_dE00']:.2f}, mean {p['mean_dE00']:.2f} over its "
                     f"{p['geometries']} geometries" for name, p in per.items())
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from gonio.brdf.colour.conditions import ViewingConditions
    from gonio.brdf.colour.report import compare
    from gonio.result_colour import (
        colour_warnings,
        difference_csv,
        in_reflectance,
        near_specular_note,
        no_colour_reason,
        result_report,
        shared_table_note,
    )
    from gonio.results import read_result

    if not args.result.is_file():
        raise UsageError(f"result file {args.result} does not exist")
    if args.csv is not None and str(args.csv) != "-" and not args.csv.parent.is_dir():
        raise UsageError(f"--csv {args.csv}: folder {args.csv.parent} does not exist")
    if args.csv is not None and str(args.csv) != "-" and args.csv.exists() \
            and not args.overwrite:
        # A colour CSV is often a lab's master (a stored standard): replaced without a word.
        raise UsageError(f"--csv {args.csv} already exists; give another name, move it away, "
                         "or add --overwrite to replace it (nothing was written)")
    if args.data_dir is not None and not args.data_dir.is_dir():
        raise UsageError(f"--data-dir {args.data_dir} is not a folder: give the data directory "
                         "whose standards/ folder holds the stored standards")
    azimuths = _azimuths(args.azimuth)
    instruments = args.instrument or list(DEFAULT_INSTRUMENTS)
    cond = ViewingConditions(args.illuminant, args.observer)
    res = read_result(args.result)
    report = result_report(res, cond, instruments, azimuths)
    warnings = colour_warnings(res)
    no_colour = no_colour_reason(res, args.result.name)
    diff = None
    shared: str | None = None
    if args.against is not None:
        if no_colour is not None:
            raise UsageError(f"no dE00 against {args.against}: {no_colour}")
        std, std_warnings = _standard(args.against,
                                      _standards_folder(args.result, args.data_dir), cond,
                                      instruments, azimuths)
        diff = compare(report, std)
        warnings += std_warnings
        if Path(args.against).is_file() and Path(args.against).suffix.lower() != ".csv":
            # Another scan's result: near-specular values both read from tables.
            shared = shared_table_note(report, std)
    for warning in warnings:
        print(f"warning: {warning}", file=sys.stderr)
    # Which near-specular geometries no pair read (the CSV's source column says it per row).
    notes = [n for n in (near_specular_note(report), diff and diff.note, shared) if n]
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    text_csv = difference_csv(diff, warnings) if diff is not None else report.csv(warnings)
    if args.json:
        out: dict[str, Any] = {"colour": report.as_dict()}
        if warnings:
            out["warnings"] = warnings
        if notes:
            out["notes"] = notes
        if no_colour is not None:
            out["no_colour"] = no_colour
        if diff is not None:
            out["difference"] = diff.as_dict()
        print(json.dumps(out, indent=2))
    elif str(args.csv) == "-":
        sys.stdout.write(text_csv)
    else:
        print(_table(report, no_colour, in_reflectance(res.samples.calibration)))
        if diff is not None:
            print()
            print(_diff_table(diff))
    if args.csv is not None and str(args.csv) != "-":
        args.csv.write_text(text_csv, encoding="utf-8")
        if not args.json:
            print(f"wrote {args.csv}")
    return 0
