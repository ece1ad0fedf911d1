"""Write the standard renderings' cell weighting where the design room reads it.

``python -m gonio.brdf.pictures.designweight`` counts the pixel lookups of the standard
renderings (:func:`gonio.brdf.pictures.appearance.render_importance`) and writes them to the
design package's ``data/render-importance.npz``
(:mod:`gonio.brdf.design.renderweight` reads it; the design room cannot import the renderer).
Run it after any change to the standard renderings; the suite's
``test_designweight.py`` fails until it is run.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.pictures import appearance
from gonio.brdf.tables import geometry as geo

#: The file's format and version; the reader (:mod:`gonio.brdf.design.renderweight`, which this
#: room may not import) checks both, and ``test_designweight.py`` reads what this writes.
FORMAT = "gonio-render-weight"
VERSION = 1


def views_description() -> dict[str, object]:
    """What the counts were made with: the view kind, size and each light's angles."""
    return {"size": appearance.APPEARANCE_SIZE,
            "views": [{"kind": v.kind, "polar_deg": v.light.theta_deg,
                       "azimuth_deg": v.light.phi_deg}
                      for v in appearance.APPEARANCE_VIEWS if v.light is not None]}


def shipped_path() -> Path:
    """The file in the source tree's design package (``gonio/brdf/design/data``)."""
    return Path(__file__).resolve().parents[1] / "design" / "data" / "render-importance.npz"


def write_render_weight(path: Path, counts: NDArray[np.float64],
                        views: dict[str, object]) -> None:
    """Write ``counts`` ((18, 18, 36) pixel counts) and ``views`` to ``path`` in the layout
    :mod:`gonio.brdf.design.renderweight` describes (non-zero nodes only)."""
    counts = np.asarray(counts, dtype=np.float64)
    if counts.shape != geo.SLICE_SHAPE:
        raise ValueError(f"a render weight has shape {geo.SLICE_SHAPE}, got {counts.shape}")
    flat = counts.reshape(-1)
    index = np.flatnonzero(flat).astype(np.int32)
    np.savez_compressed(path, format=np.array(FORMAT), version=np.array(VERSION),
                        shape=np.array(geo.SLICE_SHAPE), index=index, value=flat[index],
                        views=np.array(json.dumps(views, sort_keys=True)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gonio.brdf.pictures.designweight",
        description="Count the standard renderings' pixel lookups per grid cell and write them "
                    "where the default design reads them.")
    ap.add_argument("output", nargs="?", type=Path, default=None,
                    help="file to write (.npz is added if missing); default: the design "
                         "package's data/render-importance.npz in this source tree")
    args = ap.parse_args(argv)
    path = shipped_path() if args.output is None else args.output
    if path.suffix != ".npz":  # numpy would add it; say the name it really writes
        path = path.with_name(path.name + ".npz")
    write_render_weight(path, appearance.render_importance(), views_description())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
