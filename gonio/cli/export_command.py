"""``gonio export RESULT.h5 --format FORMAT -o FILE [--with-mesh] [--overwrite]``: a result in
a renderer's format, with a report of what the file is (specimen, simulated or measured, the
fitted model's rendered difference from the reconstruction, warnings; docs/export.md). An
existing output file is replaced only with ``--overwrite``; an output that is a folder, or whose
suffix is another format's, is refused before anything is fitted."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from gonio.cli import UsageError

_FORMATS_HELP = (
    "factored: the factored fit of paper 000 (.npz); mtlx: MaterialX standard_surface and "
    "open_pbr_surface; "
    "gltf: glTF 2.0 material with KHR_materials_anisotropy (.gltf, JSON); glb: the same in "
    "glTF's binary container (.glb, as Blender, three.js and model-viewer open it); merl: "
    "MERL .binary, azimuthally "
    "averaged, with a .json sidecar; table: gonio's BRDF table (.npz). Formats: docs/export.md"
)


def register(sub: Any) -> None:
    p = sub.add_parser(
        "export", help="write a result's BRDF as factored/MaterialX/glTF/GLB/MERL/table",
        description="Export a job's HDF5 result for renderers and other tools. " + _FORMATS_HELP,
    )
    p.add_argument("result", type=Path, help="a gonio result file (HDF5)")
    p.add_argument("--format", "-f", required=True, dest="fmt",
                   choices=["factored", "mtlx", "gltf", "glb", "merl", "table"])
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="file to write (default: the result's name with the format's suffix, "
                   "RESULT.factored.npz / RESULT.table.npz for the two .npz formats)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the output file (and a merl export's .json sidecar) if it "
                   "exists; without it an existing file is refused")
    p.add_argument("--with-mesh", action="store_true",
                   help="gltf, glb: add a preview sphere (normals, UVs, tangents) so any viewer "
                   "shows the material; without it the file is a material library")
    p.set_defaults(func=run)


def default_output(result: Path, fmt: str) -> Path:
    """Where an export goes without ``-o``: the result's name with the format's suffix.

    ``factored`` and ``table`` are both ``.npz``; they get ``.factored.npz`` / ``.table.npz`` so
    exporting one result in every format does not overwrite one with the other.
    """
    from gonio.export import FORMATS

    suffix = FORMATS[fmt]
    if list(FORMATS.values()).count(suffix) > 1:
        suffix = f".{fmt}{suffix}"
    return result.with_suffix(suffix)


def _check_suffix(out: Path, fmt: str) -> None:
    """Refuse an ``-o`` whose suffix is another format's (``-f gltf -o felt.mtlx`` wrote glTF
    JSON that a MaterialX reader then fails on, ``-f gltf -o felt.glb`` JSON that a viewer reading
    a ``.glb`` by its binary header refuses); a suffix of no gonio format is the lab's own.
    """
    from gonio.export import FORMATS

    suffix = out.suffix.lower()
    if suffix and suffix != FORMATS[fmt] and suffix in FORMATS.values():
        theirs = ", ".join(f for f, s in FORMATS.items() if s == suffix)
        raise UsageError(f"-o {out} has the suffix of the {theirs} format, but --format is "
                         f"{fmt}, whose files end in {FORMATS[fmt]}: name it "
                         f"{out.with_suffix(FORMATS[fmt]).name} or choose the format its name "
                         f"says, --format {theirs.replace(', ', ' or ')} (nothing was written)")


def run(args: argparse.Namespace) -> int:
    from gonio.export import MESH_FORMATS, result_fits, write_export

    result: Path = args.result
    if not result.is_file():
        raise UsageError(f"result file {result} does not exist")
    with result.open("rb") as f:
        if f.read(4) == b"PK\x03\x04":  # a zip: numpy's .npz, not HDF5
            raise UsageError(
                f"{result} is a .npz archive (a gonio table or samples file), not a scan's "
                "result file: gonio export reads the HDF5 result of a scan (the page's "
                "'Download HDF5 result', gonio scan -o, or DATA_DIR/results/job-N.h5); a "
                "gonio table is itself one of the export formats (gonio render draws it)")
    out: Path = args.output or default_output(result, args.fmt)
    if out.resolve() == result.resolve():
        raise UsageError(f"-o {out} is the result file itself; choose another output name")
    if not out.parent.is_dir():
        raise UsageError(f"folder {out.parent} does not exist; create it or choose another -o")
    if out.is_dir():
        # Refused as "already exists ... --overwrite", which then failed after the fit naming
        # a temporary file.
        raise UsageError(f"-o {out} is a folder; give a file name in it, e.g. -o "
                         f"{default_output(out / result.name, args.fmt)}")
    _check_suffix(out, args.fmt)
    if args.with_mesh and args.fmt not in MESH_FORMATS:
        raise UsageError(f"--with-mesh applies to --format {' or '.join(MESH_FORMATS)} only")
    if not args.overwrite:
        # -o naming another scan's result replaced it with a 16 kB glTF without a word.
        from gonio.export.merl import sidecar_path

        taken = [p for p in ([out, sidecar_path(out)] if args.fmt == "merl" else [out])
                 if p.exists()]
        if taken:
            names = " and ".join(str(p) for p in taken)
            raise UsageError(f"{names} already exist{'s' if len(taken) == 1 else ''}; give "
                             "another -o, move it away, or add --overwrite to replace it "
                             "(nothing was written)")
    t0 = time.perf_counter()
    fits, prov = result_fits(result)
    path = write_export(fits, args.fmt, out, prov, with_mesh=args.with_mesh)
    print(f"wrote {path} ({args.fmt}, {path.stat().st_size:,} bytes, "
          f"{time.perf_counter() - t0:.1f} s)")
    for line in report(args.fmt, path, prov):
        print(line)
    if args.fmt in MESH_FORMATS and not args.with_mesh:
        # A glTF viewer opened on it shows an empty scene, which looked like a broken export.
        print("  the file holds the material only, no mesh: a glTF viewer shows an empty scene "
              "until it is applied to a model (--with-mesh adds a preview sphere)")
    return 0


def report(fmt: str, path: Path, prov: dict[str, Any]) -> list[str]:
    """What the written file is, in a few lines (the same facts as its provenance)."""
    import json

    from gonio.export import export_warnings

    lines = []
    who = prov.get("specimen", "?")
    if not prov.get("specimen_named"):
        who += " (no specimen name was given at the scan: gonio scan --specimen NAME)"
    lines.append(f"  specimen {who}, {prov.get('source', '?')}, job {prov.get('job_id')}")
    err = (prov.get("reconstruction_error") or {}).get("predicted_log_rmse")
    if err is not None:
        lines.append(f"  reconstruction: predicted log_rmse {err:.3f} (expected cosine-weighted "
                     "log error against the true BRDF)")
    model = {"mtlx": "principled", "gltf": "principled", "glb": "principled",
             "factored": "factored"}.get(fmt)
    rendered = ((prov.get("fits") or {}).get(model) or {}).get("rendered") if model else None
    if isinstance(rendered, dict) and rendered.get("value") is not None:
        lines.append(f"  {model} fit renders {rendered['metric']} {rendered['value']:.3f} "
                     "from the reconstruction (sphere and swatch under point lights)")
    if fmt == "merl":
        from gonio.export.merl import sidecar_path

        side = sidecar_path(path)
        from gonio.export.merl import ANISOTROPY_WARN

        sidecar = json.loads(side.read_text())
        lost = float(sidecar["merl"]["anisotropy_lost"])
        # "anisotropy lost: log RMSE 0.000" of an isotropic paint said something was lost.
        what = (f"anisotropy lost: log RMSE {lost:.3f}" if lost > ANISOTROPY_WARN else
                f"little lost: the result is nearly isotropic, log RMSE {lost:.3f} to its "
                "average")
        lines.append(f"  provenance in {side.name}; MERL is isotropic: the result was averaged "
                     f"over azimuth ({what})")
    lines.extend(f"  warning: {w}" for w in export_warnings(fmt, path, prov))
    return lines
