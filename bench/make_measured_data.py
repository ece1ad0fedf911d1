"""Make the measured-material tables shipped in the package.

They go to ``gonio/brdf/materials/data/measured.npz``.

Run from the project root (needs mitsuba, ``pip install 'gonio[rgl]'``)::

    .venv/bin/python bench/make_measured_data.py [RGL_DIR]

``RGL_DIR`` defaults to ``../shared/data/rgl``: eleven isotropic materials of the RGL EPFL
material database (Dupuy & Jakob 2018, CC0). Each ``.bsdf`` file is evaluated once with
:func:`gonio.brdf.materials.rgl.read_rgl` (mitsuba ``scalar_rgb``) on the valid cells of one ``ph``
slice; the tables are isotropic, so one slice is the whole material. Of the two
``irid_flake_paint1`` files (one swatch, two outgoing grids) only the standard one is shipped,
so the shipped set holds each material once.

Output: one compressed ``.npz`` with ``names (M,)``, ``descriptions (M,)``, ``files (M,)``,
``values (M, 3, 7861) float32`` (1/sr, R, G, B at the valid cells in C order) and a
``source`` note. About 1 MB.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from gonio.brdf.materials.rgl import read_rgl
from gonio.brdf.tables import geometry as geo

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "gonio" / "brdf" / "data" / "measured.npz"
#: Second file of a material already shipped (same swatch, finer outgoing grid).
DUPLICATES = {"irid_flake_paint1_fine_rgb"}


def main(argv: list[str]) -> int:
    src = Path(argv[0]) if argv else ROOT.parent / "shared" / "data" / "rgl"
    files = [p for p in sorted(src.glob("*.bsdf")) if p.stem not in DUPLICATES]
    if not files:
        print(f"no .bsdf files in {src}")
        return 1
    mask = geo.valid_mask()
    names, descs, values = [], [], []
    for p in files:
        t = read_rgl(p)
        name = p.stem.removesuffix("_rgb")
        names.append(name)
        descs.append(str(t.provenance.get("description", "")).strip())
        values.append(np.asarray(t.values[:, 0][:, mask], dtype=np.float32))
        print(f"{name}: {descs[-1]}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        OUT, names=np.array(names), descriptions=np.array(descs),
        files=np.array([p.name for p in files]), values=np.stack(values),
        source=np.array("RGL EPFL material database (Dupuy & Jakob 2018), CC0; "
                        "evaluated with mitsuba scalar_rgb 'measured' by "
                        "bench/make_measured_data.py"),
    )
    print(f"wrote {OUT.relative_to(ROOT)} ({OUT.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
