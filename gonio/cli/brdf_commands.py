"""Science commands: ``gonio basis build``, ``simulate-scan``, ``reconstruct`` and ``demo``.

Angles on the command line and in pair files are degrees; the numerical core works in radians
and the conversion happens here, at the edge.

Pair files (``--pairs``) list one light/sensor pair per row, either as lab directions
``theta_i, phi_i, theta_v, phi_v`` (degrees, both vectors pointing away from the surface) or
as half/difference cells ``th, td, pd, ph`` (degrees, ``ph`` the lab half-vector azimuth).
Three spellings are read:

* CSV with a header row naming the four columns;
* JSON: ``{"pairs": [{"theta_i": 45, "phi_i": 0, "theta_v": 30, "phi_v": 180}, ...]}`` or the
  bare list;
* TOML: ``[[pairs]]`` tables with the same keys;
* TOML design fragment (``gonio design -o``) or rig config: ``[[lights]]`` and ``[[sensors]]``
  with ``name``, ``theta_deg``, ``phi_deg``, and ``[[pairs]]`` of ``light``/``sensor`` names
  (or ``pairs = "all"``).

docs/file-formats.md ("Pairs file") has examples of each.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, SPANS_DEG
from gonio.cli import UsageError, refuse_to_replace

FloatArray = NDArray[np.float64]
LAB_KEYS = ("theta_i", "phi_i", "theta_v", "phi_v")
CELL_KEYS = ("th", "td", "pd", "ph")
DEMO_MATERIAL = "brushed-metal-003"


# ---------------------------------------------------------------------------- pair files
def _rows_from_file(path: Path) -> list[Mapping[str, Any]]:
    from gonio.config import ConfigError, read_toml

    if not path.is_file():
        raise UsageError(f"pairs file {path} does not exist")
    suffix = path.suffix.lower()
    try:
        if suffix == ".csv":
            with open(path, newline="") as fh:
                return [
                    {k.strip(): v for k, v in row.items() if k is not None}
                    for row in csv.DictReader(fh)
                ]
        if suffix == ".json":
            data: Any = json.loads(path.read_text())
        elif suffix == ".toml":
            data = read_toml(path, noun="pairs file", example="docs/file-formats.md",
                             error=ConfigError)
        else:
            raise UsageError(
                f"pairs file {path}: unknown type {suffix!r}; use .csv, .json or .toml"
            )
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"pairs file {path} cannot be parsed: {exc}") from None
    except ConfigError as exc:  # read_toml's message names the file and what is wrong
        raise UsageError(str(exc)) from None
    if isinstance(data, Mapping):
        data = data.get("pairs")
    if not isinstance(data, list) or not all(isinstance(r, Mapping) for r in data):
        raise UsageError(
            f"pairs file {path}: expected a list of pairs (a top-level \"pairs\" list of tables "
            f"with keys {', '.join(LAB_KEYS)} or {', '.join(CELL_KEYS)})"
        )
    return list(data)


def _design_rows(path: Path) -> list[Mapping[str, Any]] | None:
    """Lab-direction rows of a design fragment or rig config (``[[lights]]``/``[[sensors]]``
    tables and named pairs), or None when the TOML file is a plain pairs list."""
    from gonio.config import ConfigError, read_toml
    from gonio.rigdesign import parse_fragment

    try:
        data = read_toml(path, noun="pairs file", example="docs/file-formats.md",
                         error=ConfigError)
    except ConfigError as exc:  # read_toml's message names the file and what is wrong
        raise UsageError(str(exc)) from None
    if "lights" not in data and "sensors" not in data:
        return None
    design = parse_fragment(data, path.name)  # ConfigError: one clear message
    return [
        {"theta_i": design.light(a).theta_deg, "phi_i": design.light(a).phi_deg,
         "theta_v": design.sensor(b).theta_deg, "phi_v": design.sensor(b).phi_deg}
        for a, b in design.pair_names()
    ]


def read_pairs(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """Cells (n, 3) and lab azimuths (n,), radians, from a pairs file (module docstring)."""
    from gonio.brdf.reconstruction.reconstruct import ReconstructionError, pair_cells

    p = Path(path)
    if p.suffix.lower() == ".toml" and p.is_file():
        rows = _design_rows(p)
        if rows is None:
            rows = _rows_from_file(p)
    else:
        rows = _rows_from_file(p)
    if not rows:
        raise UsageError(f"pairs file {p} lists no pairs")
    keys = set(rows[0])
    kind = LAB_KEYS if set(LAB_KEYS) <= keys else CELL_KEYS if set(CELL_KEYS) <= keys else None
    if kind is None:
        raise UsageError(
            f"pairs file {p}: columns {sorted(keys)}; give either {', '.join(LAB_KEYS)} "
            f"(lab directions) or {', '.join(CELL_KEYS)} (cells), in degrees"
        )
    try:
        deg = np.array([[float(r[k]) for k in kind] for r in rows])
    except (KeyError, TypeError, ValueError) as exc:
        raise UsageError(
            f"pairs file {p}: every pair needs numeric {', '.join(kind)} ({exc})"
        ) from None
    if not np.isfinite(deg).all():
        raise UsageError(f"pairs file {p}: angles must be finite numbers")
    rad = np.deg2rad(deg)
    if kind == CELL_KEYS:
        return rad[:, :3], rad[:, 3]
    if (deg[:, [0, 2]] >= 90).any() or (deg[:, [0, 2]] < 0).any():
        raise UsageError(f"pairs file {p}: theta_i and theta_v must be in [0, 90) degrees")
    from gonio.brdf.tables import geometry as geo

    try:
        return pair_cells(
            geo.spherical_to_direction(rad[:, 0], rad[:, 1]),
            geo.spherical_to_direction(rad[:, 2], rad[:, 3]),
        )
    except ReconstructionError as exc:
        raise UsageError(f"pairs file {p}: {exc}") from None


def simple_pairs(n: int) -> tuple[FloatArray, FloatArray]:
    """A deterministic fallback design of ``n`` pairs on the 5 degree grid.

    Used by the demo when no optimized design is available: ``th`` sweeps 0-50 deg, ``td``
    5-35 deg (so ``th + td <= 85`` deg and every cell is above the horizon whatever ``pd``)
    and ``pd`` follows a golden-ratio sequence over [0, 180) deg, so the pairs cover the
    specular peak, the off-specular ridge and a spread of separations; the lab azimuths are
    spread the same way so the pairs see different slices at each stage angle.
    """
    from gonio.brdf.tables import geometry as geo

    k = np.arange(n)
    th = np.rint((k + 0.5) / n * 10) * geo.STEP  # 0..50 deg
    td = np.rint(1 + ((k * 7) % n) / max(n - 1, 1) * 6) * geo.STEP  # 5..35 deg
    pd = np.rint(np.mod(k * 0.6180339887, 1.0) * geo.N_PD) % geo.N_PD * geo.STEP
    ph = np.rint(np.mod(k * 0.381966, 1.0) * geo.N_PH) % geo.N_PH * geo.STEP
    return np.stack([th, td, pd], axis=1), ph


# ---------------------------------------------------------------------------- commands
def _cmd_basis_build(args: argparse.Namespace) -> int:
    from gonio.brdf.materials import library
    from gonio.brdf.reconstruction.basis import build_basis

    if args.components < 1:
        raise UsageError(f"--components must be at least 1, got {args.components}")
    t0 = time.perf_counter()
    if args.output is None and args.extra:
        raise UsageError(
            "a basis with --extra tables is not the default basis; say where to write it with "
            "-o, or add the tables to the default basis with `gonio library import`"
        )
    if args.output is None:
        # The default basis (synthetic + shipped measured + imported tables), rebuilt where
        # default_basis() finds it.
        from gonio.brdf.reconstruction.basis import default_basis, default_basis_path

        out = default_basis_path(args.components)
        out.unlink(missing_ok=True)
        basis = default_basis(args.components, progress=True)
    else:
        tables = library.default_library(extra_dirs=args.extra, progress=True)
        basis = build_basis(tables, args.components, progress=True)
        out = Path(args.output)
        basis.save(out)
    print(
        f"basis: K={basis.K} from {len(basis.materials)} materials "
        f"({basis.provenance['n_columns']} columns) in {time.perf_counter() - t0:.1f} s -> {out}"
    )
    return 0


def _load_specimen(args: argparse.Namespace) -> tuple[Any, str]:
    if args.table is not None:
        from gonio.brdf.tables.table import BRDFTable

        t = BRDFTable.load(args.table)
        return t, t.name
    from gonio.brdf.materials.library import get_material

    return get_material(args.material), args.material


def _cmd_simulate_scan(args: argparse.Namespace) -> int:
    from gonio.brdf.reconstruction.samples import (
        NoiseModel,
        Samples,
        simulate_samples,
        uniform_stage_angles,
    )

    if args.rotations < 1:
        raise UsageError(f"--rotations must be at least 1, got {args.rotations}")
    specimen, name = _load_specimen(args)
    if args.pairs is not None:
        cells, ph = read_pairs(args.pairs)
        source = str(args.pairs)
    else:
        from gonio.brdf.design.presets import get_preset

        cells, ph = get_preset(args.design_preset).cells()
        source = f"preset {args.design_preset}"
    alpha = uniform_stage_angles(args.rotations, np.deg2rad(args.start), np.deg2rad(args.span))
    noise = NoiseModel(args.noise, args.abs_noise, args.seed)
    vals = simulate_samples(specimen, cells, ph, alpha, noise=noise)
    channels = tuple(getattr(specimen, "channels", ("R", "G", "B")))
    prov = {"simulated_from": name, "pairs": source, "noise_relative": args.noise,
            "noise_absolute": args.abs_noise, "seed": args.seed}
    out = Samples(cells, ph, alpha, vals, channels, prov).save(args.output)
    print(f"simulated {cells.shape[0]} pairs x {alpha.size} rotations over {args.span:g} deg of "
          f"{name} -> {out}")
    return 0


def _local_prior_text(settings: dict[str, Any]) -> str | None:
    from gonio.figures import local_prior_text

    return local_prior_text(settings)


def _highlight_warning(table: Any, cells: Any, ph_lab: Any, alpha: Any, values: Any
                       ) -> str | None:
    """The highlight-not-read sentence of a reconstruction (:mod:`gonio.brdf.highlightread`),
    as finishing records it for a scan; None when a reading comes near its peak."""
    from gonio.brdf.highlightread import highlight_read

    return highlight_read(table, cells, ph_lab, alpha,
                          np.maximum(np.asarray(values, dtype=float), 0.0)).message()


def _mirror_gap_note(cells: Any) -> str | None:
    """What the layout's distance from the mirror direction means for the estimate
    (:mod:`gonio.brdf.mirrorgap`), as finishing records it for a scan; None when a pair reads
    the mirror direction."""
    from gonio.brdf.mirrorgap import cells_gap_deg, gap_note

    return gap_note(cells_gap_deg(cells))


def _load_basis(path: str | None, progress: bool = True) -> Any:
    from gonio.brdf.reconstruction.basis import Basis, default_basis

    return Basis.load(path) if path is not None else default_basis(progress=progress)


def _scan_samples(path: str) -> Any:
    """The samples ``gonio reconstruct`` fits: a samples file (.npz), or a scan's result file
    (.h5), whose calibrated readings (its ``/samples``) are turned into the same samples
    (:meth:`gonio.calibration.CalibratedScan.to_samples`), so a lab can reconstruct a scan
    again with another method, basis or prior. A result file was refused as "not a gonio
    samples file", pointing at a Python function."""
    from gonio.brdf.reconstruction.samples import Samples

    p = Path(path)
    if p.suffix.lower() not in (".h5", ".hdf5"):
        return Samples.load(p)
    from gonio.results import ResultFileError, read_result

    try:
        res = read_result(p)
    except ResultFileError as exc:
        raise UsageError(str(exc)) from None
    if res.attrs.get("kind") == "calibration":
        raise UsageError(f"{p} is a calibration job's result: its readings are of the white "
                         "reference; give a scan's result file")
    if np.asarray(res.samples.values).size == 0:
        raise UsageError(f"{p} holds no readings to reconstruct from")
    if not res.samples.calibration.get("pairs"):
        print(f"warning: {p.name} was measured without a calibration: its values, and the "
              "table reconstructed from them, are in sensor units, not 1/sr", file=sys.stderr)
    samples = res.samples.to_samples({"from_result": p.name, "job_id": res.attrs.get("job_id")})
    # Dark-subtracted readings of dark or grazing pairs can fall just below 0; the job's own
    # finishing clamps them to 0 before it fits (gonio.finishing), and so does this.
    negative = int(np.count_nonzero(samples.values < 0.0))
    if negative:
        samples = dataclasses.replace(samples, values=np.maximum(samples.values, 0.0))
        print(f"note: {negative} of {samples.values.size} readings below 0 (dark-subtraction "
              "noise) taken as 0, as the job's own reconstruction did", file=sys.stderr)
    return samples


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    from gonio.brdf.reconstruction.reconstruct import reconstruct

    refuse_to_replace(args.output, args.overwrite, "nothing was reconstructed")
    refuse_to_replace(args.preview, args.overwrite, "nothing was reconstructed", "--preview")

    samples = _scan_samples(args.samples)
    basis = _load_basis(args.basis)
    name = args.name or Path(args.output).stem
    rec = reconstruct(
        basis, samples.cells, samples.ph_lab, samples.stage_angles, samples.values,
        channels=samples.channels, eta=args.eta, lam=args.lam, n_components=args.components,
        solver=args.solver, name=name, method=args.method,
        local=None if args.local_prior == "none" else "scan",
    )
    rec.table.save(args.output)
    s = rec.settings
    print(f"reconstructed {name}: K={s['K']} n={s['n']} r={s['r']} method={s['method']}")
    # The figures of the result's headline (gonio.figures, docs/science.md 7.1.1): this line
    # said "within x2 on 3 of 5", a count from long before, and said it of V&F's path too.
    how = ("within x2 of the truth on about 2 scans in 3 held out of the basis, 187 of 290"
           if s["method"] == "joint" else
           "calibrated for the joint fit; for this method it was not measured")
    print(f"  predicted log_rmse {rec.predicted_log_rmse:.3f} (expected cosine-weighted log "
          f"error against the true BRDF; {how}; docs/science.md 7.1.1)")
    if np.isfinite(rec.predicted_log_rmse_upper):
        print(f"  upper end of its interval {rec.predicted_log_rmse_upper:.3f} (the true error "
              "of held-out materials was below it on 98 % of the calibration scans)")
    if (line := _local_prior_text(rec.settings)) is not None:
        print(f"  {line}")
    if rec.misfit_warning is not None:
        print(f"  warning: {rec.misfit_warning}")
    if (unread := _highlight_warning(rec.table, samples.cells, samples.ph_lab,
                                     samples.stage_angles, samples.values)) is not None:
        print(f"  warning: {unread}")
    if (gap := _mirror_gap_note(samples.cells)) is not None:
        print(f"  note: {gap}")
    print(f"  sample error {100 * rec.rel_sample_error:.2f} %, "
          f"self-estimated MAPE {100 * rec.predicted_error:.1f} % "
          f"(V&F estimate {100 * rec.estimated_error:.2f} %), "
          f"time {s['seconds']:.3f} s -> {args.output}")
    if args.preview is not None:
        from gonio.brdf.pictures.preview import save_preview

        print(f"  preview -> {save_preview(rec.table, args.preview)}")
    return 0


def loo_basis(material: str, k: int) -> Any:
    """Leave-one-out basis of the default library without ``material``, cached on disk."""
    from gonio.brdf.materials import library
    from gonio.brdf.reconstruction.basis import Basis, BasisError, build_basis

    folder = library.cache_root() / "basis"
    path = folder / f"loo-{material}-K{k}-{library.library_key()[:16]}.npz"
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass  # damaged cache entry: rebuild
    tables = library.default_library(progress=True)
    kept = [t for t in tables if t.name != material]
    if len(kept) == len(tables):
        raise UsageError(f"{material!r} is not a library material")
    basis = build_basis(kept, k, progress=True)
    folder.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis


def _library_table(material: str) -> Any:
    """The cached library table of ``material`` (reading one file, not the whole library)."""
    from gonio.brdf.materials import library

    return library.library_table(material)


def _demo_pairs(basis: Any, n: int) -> tuple[FloatArray, FloatArray, str]:
    """Optimized pairs when the design module works, else :func:`simple_pairs`."""
    try:
        from gonio.brdf.design.constraints import RigConstraints
        from gonio.brdf.design.pairs import design_pairs

        # A simulated rig has no mounts to collide, so devices may sit close together.
        rig = RigConstraints(min_device_distance_deg=0.0)
        d = design_pairs(basis, n, rig, starts=2, descents=3, time_limit_s=10.0)
        return (np.asarray(d.cells), np.asarray(d.ph_lab),
                f"optimized by {d.objective}, kappa {d.kappa:.3g}")
    except (ImportError, ValueError) as exc:
        cells, ph = simple_pairs(n)
        return cells, ph, f"deterministic grid rule; no optimized design ({exc})"


def _cmd_demo(args: argparse.Namespace) -> int:
    from gonio.brdf.materials.library import get_material
    from gonio.brdf.pictures.preview import save_preview
    from gonio.brdf.reconstruction.reconstruct import reconstruct
    from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
    from gonio.brdf.tables import metrics

    if args.pairs < 1 or args.rotations < 1:
        raise UsageError("--pairs and --rotations must be at least 1")
    t0 = time.perf_counter()
    model = get_material(args.material)  # clear error for an unknown name before any work
    basis = loo_basis(args.material, args.components)
    t_basis = time.perf_counter() - t0
    cells, ph, how = _demo_pairs(basis, args.pairs)
    alpha = uniform_stage_angles(args.rotations, span=np.deg2rad(args.span))
    vals = simulate_samples(model, cells, ph, alpha, noise=NoiseModel(args.noise, seed=args.seed))
    rec = reconstruct(basis, cells, ph, alpha, vals, name=f"{args.material}-reconstructed")
    reference = _library_table(args.material)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rec.table.save(out / "reconstruction.npz")
    save_preview(rec.table, out / "reconstruction.png")
    save_preview(reference, out / "reference.png")
    print(f"demo: {args.material}, held out of a K={basis.K} basis of "
          f"{len(basis.materials)} materials (ready in {t_basis:.1f} s)")
    print(f"  pairs: {cells.shape[0]} ({how}), rotations: {alpha.size} over {args.span:g} deg, "
          f"noise {100 * args.noise:.1f} %")
    print(f"  log_rmse {metrics.log_rmse(rec.table, reference):.4f}   "
          f"log_psnr {metrics.log_psnr(rec.table, reference):.2f} dB   "
          f"predicted log_rmse {rec.predicted_log_rmse:.4f}")
    if np.isfinite(rec.predicted_log_rmse_upper):
        print(f"  upper end of its interval {rec.predicted_log_rmse_upper:.4f} "
              "(predicted_log_rmse_upper)")
    if (line := _local_prior_text(rec.settings)) is not None:
        print(f"  {line}")
    if rec.misfit_warning is not None:
        print(f"  warning: {rec.misfit_warning}")
    if (unread := _highlight_warning(rec.table, cells, ph, alpha, vals)) is not None:
        print(f"  warning: {unread}")
    if (gap := _mirror_gap_note(cells)) is not None:
        print(f"  note: {gap}")
    print(f"  self-estimated MAPE {100 * rec.predicted_error:.1f} % "
          f"(V&F estimate {100 * rec.estimated_error:.2f} %)")
    print(f"  reconstruction {rec.settings['seconds']:.3f} s, total "
          f"{time.perf_counter() - t0:.1f} s; wrote {out}/reconstruction.npz, "
          "reconstruction.png, reference.png")
    return 0


def _cmd_library_import(args: argparse.Namespace) -> int:
    from gonio.brdf.materials.imports import import_files
    from gonio.brdf.materials.measured import (
        PREFIX,
        measured_names,
        user_library_dir,
        user_table_files,
    )
    from gonio.brdf.tables.npzfile import HDF5_MAGIC, starts_with
    from gonio.brdf.tables.table import BRDFTable

    shipped = set(measured_names())
    for f in args.files:
        if Path(f).suffix.lower() == ".h5" and starts_with(f, HDF5_MAGIC):
            # A scan's result holds its reconstruction, but the library takes tables: the
            # step between is an export the lab would not guess from "unknown kind of file".
            # (Only an HDF5 file: a missing or text file named .h5 was called a result, and
            # the export the advice named then failed; the import says what it is.)
            table = Path(f).with_suffix(".table.npz")
            raise UsageError(
                f"{f} is a scan's result file; the library takes BRDF tables: export its "
                f"reconstruction first ('gonio export {f} --format table' writes {table}), "
                f"then 'gonio library import {table}'")
    written = import_files(args.files, replace=args.replace)
    for f in written:
        print(f"imported {f.stem} -> {f}")
        # The same material as a shipped one (RGL files are named <material>_rgb / _spec):
        # the default basis would then hold it twice, weighed toward it.
        base = f.stem.removesuffix("_rgb").removesuffix("_spec")
        if PREFIX + base in shipped:
            print(f"  note: gonio already ships this material as '{PREFIX}{base}' in its default "
                  "basis; imported as well, it counts twice there and weighs the basis toward "
                  f"it. If that is not what you want, delete {f}")
        # An RGL file records how far it is from reciprocal, which gonio's table assumes
        # (gonio.brdf.materials.rgl): say so where the lab looks, not only in the file.
        prov = BRDFTable.load(f).provenance
        # A table exported from a scan keeps its reconstruction's warnings (a calibration at
        # another exposure, outside physical bounds, ...): imported, it trains every default
        # basis and may be a later fit's local prior, so say them here.
        warned = prov.get("warnings")
        if isinstance(warned, list) and warned:
            print(f"  warning: the table's record carries {len(warned)} warning(s) from the "
                  "scan it came from; it now trains every default basis and can become the "
                  "shape a later fit leans on, so check it first (delete "
                  f"{f} to take it out):")
            for w in warned:
                print(f"    - {w}")
        rec = prov.get("reciprocity")
        if isinstance(rec, dict) and rec.get("median_abs_log_ratio") is not None:
            line = (f"  reciprocity: f(l, v) and f(v, l) differ by a median factor of "
                    f"{np.exp(rec['median_abs_log_ratio']):.2f} over the grid, by more than "
                    f"{np.exp(rec['p90_abs_log_ratio']):.2f} in 1 cell of 10")
            if rec.get("median_abs_log_ratio_below_80deg") is not None:
                line += (f" ({np.exp(rec['median_abs_log_ratio_below_80deg']):.2f} and "
                         f"{np.exp(rec['p90_abs_log_ratio_below_80deg']):.2f} with light and "
                         "view within 80 degrees of the normal)")
            print(line + "; gonio's table assumes they are equal, so a rendering of it can "
                  "differ from the file's on the mirrored half of each view "
                  "(docs/science.md 7.0.1)")
    held = len(user_table_files())
    print(f"{len(written)} table(s) imported; {held} in {user_library_dir()}; the default basis "
          "is rebuilt with them on next use (gonio scan, reconstruct, design, serve)")
    return 0


def _cmd_library_list(args: argparse.Namespace) -> int:
    from gonio.brdf.materials.library import ASYMMETRIC_FAMILY_COUNTS, FAMILY_COUNTS
    from gonio.brdf.materials.measured import measured_names, user_library_dir, user_table_files

    def ranges(counts: dict[str, int]) -> str:
        return ", ".join(f"{family}-000 .. {family}-{n - 1:03d}" for family, n in counts.items())

    # The synthetic library: what `--material NAME` of the simulators and simulate-scan take.
    print(f"synthetic library materials ({sum(FAMILY_COUNTS.values())}; --material NAME of "
          "gonio sim, scan --sim, serve --sim, simulate-scan): " + ranges(FAMILY_COUNTS))
    # `--material` takes these too (get_material); they train only the basis for specimens
    # without twofold symmetry (docs/science.md 7.4), so a lab testing --arc auto finds them.
    print(f"synthetic materials without twofold symmetry "
          f"({sum(ASYMMETRIC_FAMILY_COUNTS.values())}; --material NAME as well; in the basis "
          "for such specimens only): " + ranges(ASYMMETRIC_FAMILY_COUNTS))
    print(f"shipped measured materials ({len(measured_names())}, RGL, CC0; in the default "
          "basis, not --material names): " + ", ".join(measured_names()))
    files = user_table_files()
    print(f"imported ({len(files)}) in {user_library_dir()}"
          + (": " + ", ".join(f.stem for f in files) if files else "")
          + (" (--material takes their files, e.g. "
             f"--material {files[0]})" if files else ""))
    return 0


# ---------------------------------------------------------------------------- parsers
def register(subparsers: Any) -> None:
    """Add ``basis``, ``simulate-scan``, ``reconstruct`` and ``demo`` to the ``gonio`` command."""
    from gonio.brdf.reconstruction.basis import DEFAULT_COMPONENTS

    p = subparsers.add_parser("basis", help="build the linear BRDF basis")
    sub = p.add_subparsers(dest="basis_command", metavar="ACTION", required=True)
    b = sub.add_parser("build", help="learn a basis from the synthetic library (+ your tables)")
    b.add_argument("--components", "-k", type=int, default=DEFAULT_COMPONENTS,
                   help=f"number of components K (default {DEFAULT_COMPONENTS})")
    b.add_argument("--extra", action="append", default=[], metavar="DIR",
                   help="folder of extra gonio table .npz files to train on (repeatable)")
    b.add_argument("-o", "--output", help="basis file (default: the cached default basis)")
    b.set_defaults(func=_cmd_basis_build)

    lib = subparsers.add_parser("library", help="the measured tables the default basis trains on")
    lsub = lib.add_subparsers(dest="library_command", metavar="ACTION", required=True)
    li = lsub.add_parser(
        "import", help="add your own measured BRDFs (RGL .bsdf, MERL .binary, gonio .npz)"
    )
    li.add_argument("files", nargs="+", metavar="FILE")
    li.add_argument("--replace", action="store_true", help="overwrite tables of the same name")
    li.set_defaults(func=_cmd_library_import)
    ll = lsub.add_parser("list", help="list the synthetic library and the shipped and imported "
                         "measured materials")
    ll.set_defaults(func=_cmd_library_list)

    s = subparsers.add_parser("simulate-scan", help="simulate a sparse scan of a known BRDF")
    what = s.add_mutually_exclusive_group(required=True)
    what.add_argument("--material", help="library material name, e.g. brushed-metal-003")
    what.add_argument("--table", help="gonio table .npz file")
    geom = s.add_mutually_exclusive_group(required=True)
    geom.add_argument("--pairs", help="pairs file: .csv, .json or .toml of lab directions or "
                      "cells (degrees), or a design fragment from gonio design -o "
                      "(docs/file-formats.md)")
    geom.add_argument("--design-preset", help="industrial geometry: MA68, MA98, BYK-mac, MultiFX10")
    s.add_argument("--rotations", "-r", type=int, required=True, help="stage angles, evenly spaced")
    s.add_argument("--start", type=float, default=0.0, help="first stage angle, degrees")
    s.add_argument("--span", type=float, choices=SPANS_DEG, default=DEFAULT_SPAN_DEG,
                   metavar="DEG",
                   help="arc of the stage angles: 180 (half a turn, the scans' default) or 360")
    s.add_argument("--noise", type=float, default=0.01, help="relative noise (0.01 = 1 %%)")
    s.add_argument("--abs-noise", type=float, default=0.0, help="additive noise, 1/sr")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("-o", "--output", required=True, help="samples file to write (.npz)")
    s.set_defaults(func=_cmd_simulate_scan)

    r = subparsers.add_parser("reconstruct", help="reconstruct a full BRDF from a samples file "
                              "or a scan's result")
    r.add_argument("samples", help="samples .npz (from simulate-scan), or a scan's result .h5 "
                   "(its calibrated readings: reconstruct it again with another --method, "
                   "--basis or prior; the default basis is the twofold-symmetric one, which a "
                   "job whose symmetry test called its specimen asymmetric did not use)")
    r.add_argument("--basis", help="basis file (default: the cached default basis)")
    r.add_argument("--components", "-k", type=int, help="use only the first K components")
    r.add_argument("--method", choices=("joint", "vf"), default="joint",
                   help="joint fit of every reading (default) or V&F's per-slice path")
    r.add_argument("--eta", type=float, default=None,
                   help="reading noise / prior ratio (default: the method's, V&F: 40)")
    r.add_argument("--lam", type=float, default=None, help="th=0 consistency weight (V&F: 0.1)")
    r.add_argument("--solver", choices=("closed", "iterative"), default="closed",
                   help="for --method vf: closed form or V&F's L-BFGS")
    r.add_argument("--local-prior", choices=("scan", "none"), default="scan",
                   help="joint fit: lean on the basis' folded-in table the readings favour "
                        "(scan, default) or keep the library's prior (none)")
    r.add_argument("--name", help="material name stored in the table (default: file stem)")
    r.add_argument("--preview", help="also write a PNG preview here")
    r.add_argument("-o", "--output", required=True,
                   help="table file to write (.npz; an existing file only with --overwrite)")
    r.add_argument("--overwrite", action="store_true",
                   help="replace the files -o and --preview name")
    r.set_defaults(func=_cmd_reconstruct)

    d = subparsers.add_parser(
        "demo", help="the whole path on a library material held out of the basis"
    )
    d.add_argument("--material", default=DEMO_MATERIAL, help=f"default {DEMO_MATERIAL}")
    d.add_argument("--pairs", "-n", type=int, default=20)
    d.add_argument("--rotations", "-r", type=int, default=12)
    d.add_argument("--span", type=float, choices=SPANS_DEG, default=DEFAULT_SPAN_DEG,
                   metavar="DEG",
                   help="arc of the stage angles: 180 (half a turn, the scans' default) or 360")
    d.add_argument("--components", "-k", type=int, default=DEFAULT_COMPONENTS)
    d.add_argument("--noise", type=float, default=0.01, help="relative noise (0.01 = 1 %%)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--out", default="gonio-demo", help="output folder (default ./gonio-demo)")
    d.set_defaults(func=_cmd_demo)
