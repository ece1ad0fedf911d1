"""``gonio render``: pictures of measured BRDFs (sphere and swatch, point lights, studio)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gonio.cli import UsageError, refuse_to_replace


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "render",
        help="render result files or BRDF tables on a sphere and a swatch",
        description="Render the reconstructed BRDF of a result file (.h5) or a BRDF table "
        "(.npz) on a sphere under point lights at several elevations and azimuths, on a flat "
        "swatch under a flash, and on a sphere in a studio environment. A result measured on "
        "the simulated rig shows the true material above the reconstruction. Several inputs "
        "are shown row by row for comparison.",
    )
    p.add_argument("inputs", nargs="+", metavar="FILE", help="result .h5 or table .npz files")
    p.add_argument("-o", "--output", required=True,
                   help="PNG file to write (an existing file only with --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace the file -o names")
    p.add_argument("--size", type=int, default=512, help="pixels per view (default 512)")
    p.add_argument("--label", action="append", default=None,
                   help="row label for each input, in order (repeat the option)")
    p.set_defaults(func=_render)


def _render(args: argparse.Namespace) -> int:
    from gonio.figures import render_inputs

    if not 64 <= args.size <= 2048:
        raise UsageError(f"--size {args.size}: use 64 to 2048 pixels per view")
    if args.label is not None and len(args.label) != len(args.inputs):
        raise UsageError(f"{len(args.label)} --label options for {len(args.inputs)} inputs; "
                         "give one label per input or none")
    for f in args.inputs:
        if not Path(f).is_file():
            raise UsageError(f"{f} does not exist; give a result .h5 or a table .npz file")
    out = Path(args.output)
    if not out.parent.is_dir():
        raise UsageError(f"cannot write {out}: folder {out.parent} does not exist")
    png = render_inputs(args.inputs, size=args.size, labels=args.label)
    # After the inputs are read (what is wrong with them is said first), before the write.
    refuse_to_replace(out, args.overwrite, "the rendering was not written")
    out.write_bytes(png)
    for warning in _reconstruction_warnings(args.inputs):
        # What the result's colour report and exports say beside it (e.g. the highlight not
        # read, values outside physical bounds): a picture alone looks trustworthy.
        print(f"warning: {warning}", file=sys.stderr)
    print(f"wrote {out} ({len(png) / 1e6:.1f} MB, {len(args.inputs)} input(s), "
          f"{args.size} px per view)")
    return 0


def _reconstruction_warnings(inputs: Sequence[str]) -> list[str]:
    """The reconstruction's own warnings of each result file among ``inputs``
    (:func:`gonio.result_colour.colour_warnings`: the ones every export carries), each prefixed
    with its file's name when there are several inputs; tables (.npz) have none."""
    from gonio.result_colour import colour_warnings
    from gonio.results import read_result

    said: list[str] = []
    for f in inputs:
        if Path(f).suffix.lower() not in (".h5", ".hdf5"):
            continue
        for w in colour_warnings(read_result(f)):
            said.append(f"{Path(f).name}: {w}" if len(inputs) > 1 else w)
    return said
