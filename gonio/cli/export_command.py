"""``gonio export RESULT.h5 --format FORMAT -o FILE``: a result in a renderer's format."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from gonio.cli import UsageError

_FORMATS_HELP = (
    "factored: the factored fit of paper 000 (.npz); mtlx: MaterialX standard_surface; "
    "gltf: glTF 2.0 material with KHR_materials_anisotropy; merl: MERL .binary, azimuthally "
    "averaged; table: gonio's BRDF table (.npz). Formats: docs/file-formats.md"
)


def register(sub: Any) -> None:
    p = sub.add_parser(
        "export", help="write a result's BRDF as factored/MaterialX/glTF/MERL/table",
        description="Export a job's HDF5 result for renderers and other tools. " + _FORMATS_HELP,
    )
    p.add_argument("result", type=Path, help="a gonio result file (HDF5)")
    p.add_argument("--format", "-f", required=True, dest="fmt",
                   choices=["factored", "mtlx", "gltf", "merl", "table"])
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="file to write (default: the result's name with the format's suffix, "
                   "RESULT.factored.npz / RESULT.table.npz for the two .npz formats)")
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


def run(args: argparse.Namespace) -> int:
    from gonio.export import export_result

    result: Path = args.result
    if not result.is_file():
        raise UsageError(f"result file {result} does not exist")
    out: Path = args.output or default_output(result, args.fmt)
    if out.resolve() == result.resolve():
        raise UsageError(f"-o {out} is the result file itself; choose another output name")
    if not out.parent.is_dir():
        raise UsageError(f"folder {out.parent} does not exist; create it or choose another -o")
    t0 = time.perf_counter()
    path = export_result(result, args.fmt, out)
    print(f"wrote {path} ({args.fmt}, {path.stat().st_size:,} bytes, "
          f"{time.perf_counter() - t0:.1f} s)")
    return 0
