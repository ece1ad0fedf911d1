"""Benchmark: the representation's own limit by lookup (issue 23 item 2).

Run from the project root (needs mitsuba, ``pip install 'gonio[rgl]'``, and flip-evaluator)::

    nice -n 5 .venv/bin/python bench/bench_grid_limit.py [--no-reconstructions]

The materials, truths, reference renderings and scans are bench_unseen's (its docstring): the
eleven measured RGL materials and six anisotropic mitsuba specimens. For each interpolation of
:class:`gonio.brdf.pictures.render.TableLookup` (``multilinear``, math.md 3, and ``log-pchip``,
:mod:`gonio.brdf.tables.interpolation`) it renders

* the truth tabulated on gonio's grid (the "grid limit": no reconstruction on this grid
  can look closer on average), and, unless ``--no-reconstructions``,
* gonio's default reconstruction (10 designed pairs, 8 stage angles over half a turn, joint
  fit) and the basis ceiling (every cell known, least squares),

and prints the mean HDR-FLIP against the truth rendered by mitsuba over the measured and the
anisotropic materials, per material, and the lookup's cost (microseconds per direction pair
on 200,000 random pairs of one table). ``log_rmse`` is printed beside the reconstructions: it
compares tables cell by cell, so no interpolation changes it.
"""

from __future__ import annotations

import argparse
import sys
import time

import bench_unseen as bu
import numpy as np

from gonio.brdf.design.pairs import DEFAULT_OBJECTIVE
from gonio.brdf.pictures import appearance
from gonio.brdf.pictures.render import TableLookup
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.tables import metrics
from gonio.brdf.tables.interpolation import INTERPOLATIONS, Interpolation
from gonio.brdf.tables.table import BRDFTable


def flip(table: BRDFTable, m: bu.Material, how: Interpolation) -> float:
    """Mean HDR-FLIP of ``table`` rendered through ``how`` against the truth's rendering."""
    test = appearance.render_appearance(TableLookup(table, how))
    return appearance.rendered_flip(bu.truth_images(m), test).mean


def lookup_cost(table: BRDFTable, how: Interpolation, n: int = 200_000) -> float:
    """Microseconds per direction pair (upper hemisphere, random), one table."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    look = TableLookup(table, how)
    t0 = time.perf_counter()
    look.eval(v[0], v[1])
    return (time.perf_counter() - t0) / n * 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-reconstructions", action="store_true",
                    help="only the grid limit (the truth on the grid), no scans")
    ap.add_argument("--only", choices=["measured", "aniso"], default=None)
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    bu.CHOOSE["objective"] = DEFAULT_OBJECTIVE  # bench_unseen's default design
    mats = ((bu.measured_materials() if bu.RGL_DIR.is_dir() and args.only != "aniso" else [])
            + (bu.aniso_materials() if args.only != "measured" else []))
    rows: dict[str, dict[str, float]] = {}
    lrm: dict[str, dict[str, float]] = {}
    # bench_unseen's noise seeds: 100 + the material's place among all seventeen.
    order = [m.name for m in bu.measured_materials()] if bu.RGL_DIR.is_dir() else []
    order += [name for name, _spec, _holder in bu.ANISO]
    for m in mats:
        i = order.index(m.name)
        tables = {"grid limit": m.truth}
        if not args.no_reconstructions:
            b = default_basis(exclude=m.exclude)
            cells, ph = bu.design(b, 10)
            alpha = bu.scan_angles(8)
            rec = reconstruct(b, cells, ph, alpha, bu.read(m, cells, ph, alpha, 100 + i))
            tables["gonio n=10 r=8"] = rec.table
            tables["basis ceiling"] = bu.ceiling(b, m.truth)
        for label, t in tables.items():
            lrm.setdefault(label, {})[m.name] = metrics.log_rmse(t, m.truth)
            for how in INTERPOLATIONS:
                rows.setdefault(f"{label}, {how}", {})[m.name] = flip(t, m, how)
        print(f"  {m.name}: " + ", ".join(f"{r} {v[m.name]:.3f}" for r, v in rows.items()),
              flush=True)
    cost = {how: lookup_cost(mats[-1].truth, how) for how in INTERPOLATIONS}
    kinds = [k for k in ("measured", "aniso") if any(m.kind == k for m in mats)]
    print("\n| row | " + " | ".join(f"{k} ({sum(m.kind == k for m in mats)}) HDR-FLIP"
                                    for k in kinds) + " | log_rmse (measured / aniso) | "
          "lookup us/pair |")
    print("|---" * (4 + len(kinds)) + "|")
    for row, per in rows.items():
        label, how_text = row.rsplit(", ", 1)
        how = next(h for h in INTERPOLATIONS if h == how_text)
        f = " | ".join(f"{np.mean([per[m.name] for m in mats if m.kind == k]):.3f}"
                       for k in kinds)
        lr = " / ".join(f"{np.mean([lrm[label][m.name] for m in mats if m.kind == k]):.4f}"
                        for k in kinds)
        print(f"| {row} | {f} | {lr} | {cost[how]:.1f} |")
    print("\n| material | " + " | ".join(rows) + " |")
    print("|---" * (1 + len(rows)) + "|")
    for m in mats:
        print(f"| {m.name} | " + " | ".join(f"{rows[r][m.name]:.3f}" for r in rows) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
