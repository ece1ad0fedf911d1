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
compares tables cell by cell, so no interpolation changes it. HDR-FLIP is the standard one,
averaged over the sphere's pixels (:func:`gonio.brdf.pictures.appearance.standard_flip`).

Then, for the measured materials, what the grid's reciprocity fold costs (docs/science.md
7.0.1). gonio's tables hold ``pd`` over half a turn: ``pd + 180 deg`` is the same cell with
light and view exchanged (math.md 2), right for a reciprocal BRDF. The RGL files evaluated by
mitsuba are not reciprocal, so half of a rendering's pixels (those whose unfolded ``pd`` lies
in ``[180, 360)`` deg) read the transposed BRDF from the table. Printed per material: the
median and 90th percentile over the grid's valid cells of ``|ln(f(i, o) / f(o, i))|`` (sums of
the three channels), the grid limit (log-pchip), and the grid limit of a prototype that is
not a gonio format: those pixels look up a second table, the truth tabulated with light and
view exchanged (what a table holding ``pd`` over a full turn would hold).
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
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.interpolation import INTERPOLATIONS, Interpolation
from gonio.brdf.tables.table import BRDFTable


def flip(table: BRDFTable, m: bu.Material, how: Interpolation) -> float:
    """Mean HDR-FLIP of ``table`` rendered through ``how`` against the truth's rendering."""
    test = appearance.render_appearance(TableLookup(table, how))
    return appearance.standard_flip(bu.truth_images(m), test).mean


def unfolded_pd(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N,) the difference azimuth ``pd`` in ``[0, 2 pi)`` of (N, 3) direction pairs, before the
    reciprocity fold of :func:`gonio.brdf.tables.geometry.directions_to_half_diff`."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    th = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])
    d = geo.rotate_z(wi, -np.arctan2(h[:, 1], h[:, 0]))
    dx = np.cos(th) * d[:, 0] - np.sin(th) * d[:, 2]
    return np.mod(np.arctan2(d[:, 1], dx), 2 * np.pi)


class FullTurnPrototype:
    """A truth looked up as if its table held ``pd`` over a full turn: pairs whose unfolded
    ``pd`` is at least 180 deg read ``transposed`` (the truth tabulated with light and view
    exchanged), the rest ``table``; both by gonio's default lookup."""

    def __init__(self, table: BRDFTable, transposed: BRDFTable) -> None:
        self.table, self.transposed = TableLookup(table), TableLookup(transposed)

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        i = np.asarray(wi, dtype=float).reshape(-1, 3)
        o = np.asarray(wo, dtype=float).reshape(-1, 3)
        out = self.table.eval(i, o)
        swap = (i[:, 2] > 0) & (o[:, 2] > 0)
        swap[swap] = unfolded_pd(i[swap], o[swap]) >= np.pi
        if swap.any():
            out[swap] = self.transposed.eval(i[swap], o[swap])
        return out


def reciprocity(m: bu.Material) -> tuple[float, float, float, float]:
    """Median and 90th percentile of ``|ln f / f^T|`` over the valid cells, the grid limit and
    the full-turn prototype's grid limit (module docstring) of a measured material."""
    mask = geo.valid_mask()
    th, td, pd = geo.grid_angles()
    wi, wo = geo.half_diff_to_directions(th[mask], 0.0, td[mask], pd[mask])
    f, g = m.reference.eval(wi, wo), m.reference.eval(wo, wi)  # (N, 3) each, 1/sr
    ok = (f.sum(axis=1) > 0) & (g.sum(axis=1) > 0)
    ratio = np.abs(np.log(f.sum(axis=1)[ok] / g.sum(axis=1)[ok]))
    full = np.full((3, *geo.SLICE_SHAPE), np.nan)
    full[:, mask] = g.T
    transposed = BRDFTable(np.broadcast_to(full[:, None], (3, *geo.TABLE_SHAPE)).astype(
        np.float32), m.truth.channels, f"{m.name} transposed")
    ref = bu.truth_images(m)
    limit = appearance.standard_flip(ref, appearance.render_appearance(m.truth)).mean
    proto = appearance.standard_flip(ref, appearance.render_appearance(
        FullTurnPrototype(m.truth, transposed))).mean
    return float(np.median(ratio)), float(np.percentile(ratio, 90)), limit, proto


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
    print("|---" * (3 + len(kinds)) + "|")
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
    measured = [m for m in mats if m.kind == "measured"]
    if measured:
        print("\nThe reciprocity fold (measured materials; docs/science.md 7.0.1):\n")
        print("| material | median / p90 abs ln(f/f^T) | grid limit | pd over a full turn "
              "(prototype) |")
        print("|---|---|---|---|")
        recs = [reciprocity(m) for m in measured]
        for m, (med, p90, limit, proto) in zip(measured, recs, strict=True):
            print(f"| {m.name} | {med:.3f} / {p90:.3f} | {limit:.3f} | {proto:.3f} |")
        print(f"| **mean** | | **{np.mean([r[2] for r in recs]):.3f}** | "
              f"**{np.mean([r[3] for r in recs]):.3f}** |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
