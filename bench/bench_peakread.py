"""Benchmark: does the scan read the reconstruction's highlight? (issue 23 item 4: a warning).

Run from the project root (needs mitsuba and flip-evaluator: ``pip install 'gonio[rgl]'``)::

    nice -n 10 .venv/bin/python bench/bench_peakread.py choose --save choose.json
    nice -n 10 .venv/bin/python bench/bench_peakread.py test --save test.json
    nice -n 10 .venv/bin/python bench/bench_peakread.py fresh --save fresh.json
    .venv/bin/python bench/bench_peakread.py rule choose.json --check test.json fresh.json

The statistic (:func:`gonio.brdf.highlightread.highlight_read`, from the scan alone): where
the reconstructed table's projected value ``f cos ti cos to`` peaks at ``td`` up to
:data:`TD_MAX_DEG`, the angle between that cell's half vector and the nearest reading's
(``nearest``, degrees), the same with the ``td`` difference added in quadrature
(``nearest_td``), and the projected peak over the largest projected reading (``excess``).

What it should warn of (needs the truth, so only here): the highlight came back wrong, i.e.
in some channel the reconstruction's largest projected value at ``td`` up to
:data:`TD_MAX_DEG` is more than 2x off the truth's there (``peak ratio`` = reconstruction /
truth, per channel). The rows also keep both over every valid cell (``"all"``).

History of the rule: its first version (committed before any run) looked at every valid cell
with candidates ``nearest`` and ``excess``. The first choice run showed that both designs read a
half vector within 2.5 degrees of the normal, where every peak lay, so ``nearest`` was 0-2.5
everywhere, and that the peak over every cell sits at ``td`` 75-85 for the measured materials,
rows no rendering looks at. Before any test or fresh run, the highlight was restricted to ``td``
up to 45 degrees and ``nearest_td`` added; the choice set's numbers of both versions are in
docs/notes/2026-11-28-highlight-read.md. The simulated rig's twelve pairs were added as a third
plan then too (the plan of the red-highlight note, whose pairs come no nearer than 7 degrees of
``th`` to the normal).

Sets and scans are bench_flipdesign's (docs/science.md 7.2.2): ``choose`` = the measured RGL
materials at even positions of bench_unseen's order and ``CHOICE_ANISO``; ``test`` = the
measured materials at odd positions and bench_unseen's six anisotropic specimens; ``fresh`` =
``FRESH_FLIP``. Each material is read with the default design (bench_flipdesign's ``a = 0.5``
row: 10 pairs), with the MA98 preset and with the default simulated rig's twelve pairs (the
red-highlight note's, bench_red_highlight's ``rig_pairs``), each at 8 stage angles over half a
turn, 1 % noise seeded per material, the default joint fit on a basis that leaves a measured
material out; HDR-FLIP against mitsuba's truth, and the truth on the grid's (the grid limit).

The rule (written down and committed before any ``test`` or ``fresh`` run;
docs/notes/2026-11-28-highlight-read.md):

* a scan is **bad** when its peak ratio is outside [1/2, 2] in any channel;
* on the choice set alone, for each candidate ``nearest > t``, ``nearest_td > t`` and
  ``excess > t``, the
  threshold ``t`` is the midpoint between consecutive observed values that maximises
  (bad scans flagged share) - (good scans flagged share); ties: the larger ``t``. The candidate
  with the larger difference is chosen (tie: ``nearest``);
* the chosen candidate and threshold are applied **once** to ``test`` and ``fresh``. The
  warning **separates** if over those two sets together it flags at least half of the bad
  scans and at most a quarter of the good ones. Otherwise it is not wired.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import bench_flipdesign as fd  # the sibling benches (the script's folder is on sys.path)
import bench_unseen as bu
import numpy as np
from bench_red_highlight import rig_pairs

from gonio.brdf.design.presets import get_preset
from gonio.brdf.highlightread import highlight_read
from gonio.brdf.pictures.appearance import render_importance
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.bounds import projection_weight
from gonio.brdf.tables.table import BRDFTable

#: A scan's highlight is wrong when some channel's peak is off by more than this factor.
WRONG_FACTOR = 2.0
#: Over test and fresh together, the least share of bad scans and the most share of good
#: ones the chosen warning may flag for it to be wired.
MIN_BAD_FLAGGED, MAX_GOOD_FLAGGED = 0.5, 0.25
CANDIDATES = ("nearest", "nearest_td", "excess")
#: The highlight is looked for (in the reconstruction and in the truth) at ``td`` up to this,
#: degrees: where the standard renderings (``td`` 10-35) and a lab's usual geometries look.
TD_MAX_DEG = 45.0


def projected_peaks(table: BRDFTable, td_max_deg: float | None = None) -> np.ndarray:
    """(C,) largest projected value ``f cos ti cos to`` of each channel over the valid cells
    (at ``td`` up to ``td_max_deg`` degrees; None: all)."""
    v = np.asarray(table.values, dtype=float)
    w = projection_weight()
    if td_max_deg is not None:
        w = np.where(np.rad2deg(geo.TD_GRID)[None, :, None] <= td_max_deg + 1e-9, w, 0.0)
    with np.errstate(invalid="ignore"):  # -inf * 0 at the cells the weight leaves out
        p = np.where(w > 0, np.nan_to_num(v, nan=-np.inf) * w, -np.inf)
    return np.asarray(p.reshape(v.shape[0], -1).max(axis=1))


def _stat(rec_table: BRDFTable, truth: BRDFTable, cells: np.ndarray, ph: np.ndarray,
          alpha: np.ndarray, vals: np.ndarray, td_max: float | None) -> dict[str, Any]:
    h = highlight_read(rec_table, cells, ph, alpha, vals, td_max_deg=td_max)
    ratio = projected_peaks(rec_table, td_max) / projected_peaks(truth, td_max)
    return {"nearest": h.nearest_deg, "nearest_td": h.nearest_td_deg, "excess": h.excess,
            "peak": [h.peak_th_deg, h.peak_ph_deg, h.peak_td_deg, h.peak_pd_deg],
            "peak_ratio": [float(x) for x in ratio],
            "bad": bool(np.any((ratio > WRONG_FACTOR) | (ratio < 1 / WRONG_FACTOR)))}


def scan_row(m: bu.Material, b: Any, cells: np.ndarray, ph: np.ndarray, seed: int,
             plan: str, grid_flip: float) -> dict[str, Any]:
    """One scan: the statistic and the peak ratio per channel at ``td`` up to
    :data:`TD_MAX_DEG` (and, under ``"all"``, over every valid cell), ``log_rmse`` and
    HDR-FLIP."""
    alpha = bu.scan_angles(8)
    vals = bu.read(m, cells, ph, alpha, seed)
    rec = reconstruct(b, cells, ph, alpha, vals)
    return {"material": m.name, "kind": m.kind, "plan": plan,
            **_stat(rec.table, m.truth, cells, ph, alpha, vals, TD_MAX_DEG),
            "all": _stat(rec.table, m.truth, cells, ph, alpha, vals, None),
            "log_rmse": metrics.log_rmse(rec.table, m.truth),
            "flip": bu.flip_of(rec.table, m), "grid_flip": grid_flip,
            "predicted": rec.predicted_log_rmse}


def run(mats: list[bu.Material]) -> list[dict[str, Any]]:
    importance = render_importance()
    ma98 = get_preset("MA98").cells()
    rig = rig_pairs(False)
    rows = []
    t0 = time.perf_counter()
    for m in mats:
        b = default_basis(exclude=m.exclude)
        seed = 100 + int(hashlib.sha256(m.name.encode()).hexdigest()[:6], 16) % 1000
        grid_flip = bu.flip_of(m.truth, m)
        cells, ph = fd.design(b, 0.5, importance)
        rows.append(scan_row(m, b, cells, ph, seed, "default", grid_flip))
        rows.append(scan_row(m, b, ma98[0], ma98[1], seed, "MA98", grid_flip))
        rows.append(scan_row(m, b, rig[0], rig[1], seed, "sim rig", grid_flip))
        print(f"  {m.name} ({time.perf_counter() - t0:.0f} s)", flush=True)
    return rows


def print_rows(rows: list[dict[str, Any]], flag: tuple[str, float] | None = None) -> None:
    head = ("| material | plan | nearest (deg) | excess | peak th/ph/td (deg) | peak ratio R/G/B "
            "| bad | log_rmse | HDR-FLIP | grid limit |")
    if flag:
        head += " flags |"
    print(head)
    print("|---" * (head.count("|") - 1) + "|")
    for r in rows:
        pr = " / ".join(f"{x:.2f}" for x in r["peak_ratio"])
        line = (f"| {r['material']} | {r['plan']} | {r['nearest']:.1f} | {r['excess']:.3g} | "
                f"{r['peak'][0]:.0f} / {r['peak'][1]:.0f} / {r['peak'][2]:.0f} | {pr} | "
                f"{'yes' if r['bad'] else ''} | {r['log_rmse']:.4f} | {r['flip']:.3f} | "
                f"{r['grid_flip']:.3f} |")
        if flag:
            line += f" {'yes' if r[flag[0]] > flag[1] else ''} |"
        print(line)


def choose(rows: list[dict[str, Any]]) -> tuple[str, float, float]:
    """(candidate, threshold, J) by the module's rule on ``rows`` (the choice set)."""
    bad = np.array([r["bad"] for r in rows])
    best: tuple[str, float, float] | None = None
    for cand in CANDIDATES:
        x = np.array([r[cand] for r in rows], dtype=float)
        xs = np.unique(x[np.isfinite(x)])
        ts = np.concatenate([[xs[0] - 1.0], (xs[1:] + xs[:-1]) / 2]) if xs.size else []
        top: tuple[float, float] | None = None
        for t in ts:
            f = x > t
            j = (f[bad].mean() if bad.any() else 0.0) - (f[~bad].mean() if (~bad).any() else 0.0)
            if top is None or j > top[1] + 1e-12 or (abs(j - top[1]) <= 1e-12 and t > top[0]):
                top = (float(t), float(j))
        assert top is not None
        print(f"  {cand}: threshold {top[0]:.4g}, flagged bad share - good share {top[1]:.3f}")
        if best is None or top[1] > best[2] + 1e-12:
            best = (cand, top[0], top[1])
    assert best is not None
    return best


def counts(rows: list[dict[str, Any]], cand: str, t: float) -> tuple[int, int, int, int]:
    """(bad flagged, bad, good flagged, good)."""
    bad = [r for r in rows if r["bad"]]
    good = [r for r in rows if not r["bad"]]
    return (sum(r[cand] > t for r in bad), len(bad), sum(r[cand] > t for r in good), len(good))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stage", choices=["choose", "test", "fresh", "fresh2", "rule"])
    ap.add_argument("files", nargs="*", help="rule: the choice set's saved rows")
    ap.add_argument("--check", nargs="*", default=[], help="rule: the held-out sets' rows")
    ap.add_argument("--save", default=None, help="write the rows to this JSON file")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    if args.stage == "rule":
        rows = [r for f in args.files for r in json.loads(Path(f).read_text())]
        cand, t, _j = choose(rows)
        print(f"chosen on {len(rows)} choice scans: {cand} > {t:.4g}")
        print_rows(rows, (cand, t))
        bf, nb, gf, ng = counts(rows, cand, t)
        print(f"choice: flags {bf} of {nb} bad, {gf} of {ng} good")
        held: list[dict[str, Any]] = []
        for f in args.check:
            rs = json.loads(Path(f).read_text())
            held += rs
            print(f"\n{f}:")
            print_rows(rs, (cand, t))
            bf, nb, gf, ng = counts(rs, cand, t)
            print(f"{f}: flags {bf} of {nb} bad, {gf} of {ng} good")
        if held:
            bf, nb, gf, ng = counts(held, cand, t)
            ok = nb and gf <= MAX_GOOD_FLAGGED * ng and bf >= MIN_BAD_FLAGGED * nb
            print(f"held out together: flags {bf} of {nb} bad, {gf} of {ng} good: "
                  f"{'separates' if ok else 'does not separate'}")
        return 0
    make = {"choose": lambda: fd.material_sets()[0], "test": lambda: fd.material_sets()[1],
            "fresh": lambda: bu.aniso_materials(fd.FRESH_FLIP),
            "fresh2": lambda: bu.aniso_materials(fd.FRESH2_FLIP)}
    rows = run(make[args.stage]())
    print_rows(rows)
    if args.save:
        Path(args.save).write_text(json.dumps(rows, indent=1))
        print(f"rows written to {args.save}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
