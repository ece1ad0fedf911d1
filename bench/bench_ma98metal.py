"""Diagnostic: why the self-estimate is low for rough metals read with the MA98 preset.

Run from the project root (docs/science.md 7.1.1.3)::

    nice -n 10 .venv/bin/python bench/bench_ma98metal.py ROWS [MATERIAL ...]
    nice -n 10 .venv/bin/python bench/bench_ma98metal.py lobe-rows OUT
    nice -n 10 .venv/bin/python bench/bench_ma98metal.py ROWS lobe-study OUT
    nice -n 10 .venv/bin/python bench/bench_ma98metal.py lobe-truth MATERIAL ...

``ROWS`` is a rows file of ``bench_selfestimate.py --rows``. Prints, from the rows alone, the
truth against the shipped estimate per plan for the metals by roughness and for the
non-metals, and the parts of the estimate for the rough metals. With ``MATERIAL`` names, it
re-reads those materials with the default plan and MA98 exactly as ``bench_selfestimate``
does (same seed) and prints where on the grid the reconstruction's squared log error lies
(``theta_h``, ``theta_d`` and the larger of ``theta_i``, ``theta_o``), and whether the
reconstruction is too high or too low there.
"""

from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path
from typing import Any

import bench_asymmetric as ba  # sibling benches (the script's folder is on sys.path)
import bench_selfestimate as bs
import bench_unseen as bu
import numpy as np

from gonio.brdf.design.presets import get_preset
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, uniform_stage_angles
from gonio.brdf.reconstruction.selfcheck import final_parts
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics

ROUGH_ALPHA = 0.2  # a "rough" metal: isotropic or mean alpha at least this


def inner_specs() -> dict[str, dict[str, Any]]:
    """Material name -> its mitsuba BSDF before any normal map (tilted and untilted)."""
    out: dict[str, dict[str, Any]] = {}
    for name, _tilt, _az, inner, _holder in ba.ASYM:
        out[name] = out[f"{name}-untilted"] = inner
    for attr in dir(bs):
        if attr.startswith("FRESH") and isinstance(getattr(bs, attr), tuple):
            for name, inner, *_ in getattr(bs, attr):
                out[name] = inner
    return out


def category(row: dict[str, Any], specs: dict[str, dict[str, Any]]) -> tuple[str, float]:
    """``(category, alpha)``: "metal" (a mitsuba roughconductor; alpha its roughness, the
    geometric mean of the two for an anisotropic one), the BSDF's type for other specimens,
    the bench's kind for materials without a spec (measured, library); alpha NaN there."""
    s = specs.get(row["material"])
    if s is None:
        return row["kind"], float("nan")
    a = s.get("alpha", np.sqrt(s.get("alpha_u", np.nan) * s.get("alpha_v", np.nan)))
    return ("metal" if s["type"] == "roughconductor" else s["type"]), float(a)


def _summary(label: str, sel: list[dict[str, Any]]) -> None:
    q = np.array([r["truth"] / r["widened"] for r in sel])
    t = np.array([r["truth"] for r in sel])
    e = np.array([r["widened"] for r in sel])
    print(f"| {label} | {len(sel)} | {np.median(t):.3f} | {np.median(e):.3f} | "
          f"{np.median(q):.2f} | {q.max():.2f} | {int(np.sum(q > 2))} | "
          f"{int(np.sum((q >= 0.5) & (q <= 2)))} |")


def rows_tables(rows: list[dict[str, Any]]) -> None:
    """The rows-only tables of docs/science.md 7.1.1.3."""
    specs = inner_specs()
    for r in rows:
        r["cat"], r["alpha"] = category(r, specs)
    plans = [p[0] for p in bs.PLANS]
    print("| group, plan | scans | true (median) | estimate (median) | true / estimate "
          "(median) | (max) | more than 2x low | within x2 |")
    print("|---|---|---|---|---|---|---|---|")
    groups = (
        ("metals alpha < 0.1", lambda r: r["cat"] == "metal" and r["alpha"] < 0.1),
        ("metals 0.1 <= alpha < 0.2",
         lambda r: r["cat"] == "metal" and 0.1 <= r["alpha"] < ROUGH_ALPHA),
        ("metals alpha >= 0.2", lambda r: r["cat"] == "metal" and r["alpha"] >= ROUGH_ALPHA),
        ("rough plastics alpha >= 0.2",
         lambda r: r["cat"] == "roughplastic" and r["alpha"] >= ROUGH_ALPHA),
        ("every non-metal", lambda r: r["cat"] != "metal"),
    )
    for g, pick in groups:
        for p in plans:
            sel = [r for r in rows if r["plan"] == p and pick(r)]
            if sel:
                _summary(f"{g}, {p}", sel)
    print()
    print("| material | set | plan | true | estimate | true / est | undetermined | outside "
          "| unseen | expected | cv_sample_error | cv_log_error | cv_log_under | "
          "highlight_excess | misfit chi2 | uncovered |")
    print("|---" * 16 + "|")
    rough = sorted({r["material"] for r in rows
                    if r["cat"] == "metal" and r["alpha"] >= ROUGH_ALPHA})
    for m in rough:
        for r in rows:
            if r["material"] == m and r["plan"] in ("default n=10 r=8", "MA98 r=8"):
                u, o, c = final_parts(r["expected"], r["mahalanobis"], r["cv_sample_error"],
                                      r["uncovered"], bs.row_misfit(r),
                                      r["highlight_excess"], r["cv_log_under"])
                print(f"| {m} | {r['set']} | {r['plan']} | {r['truth']:.3f} | "
                      f"{r['widened']:.3f} | {r['truth'] / r['widened']:.2f} | {u:.3f} | "
                      f"{o:.3f} | {c:.3f} | {r['expected']:.3f} | "
                      f"{r['cv_sample_error']:.2f} | {r['cv_log_error']:.3f} | "
                      f"{r['cv_log_under']:.3f} | {r['highlight_excess']:.2f} | "
                      f"{r['misfit_chi2']:.1f} | {r['uncovered']:.3f} |")


def _bins(values: np.ndarray, edges: tuple[float, ...]) -> np.ndarray:
    return np.digitize(values, np.deg2rad(np.asarray(edges)))


def error_map(rec_table: Any, truth: Any) -> dict[str, Any]:
    """Where the squared log error of ``log_rmse`` lies: shares of the total per bin of
    ``theta_h``, ``theta_d`` and ``max(theta_i, theta_o)``, with the mean signed log error
    (reconstruction minus truth) per bin."""
    mask = geo.valid_mask()
    ci = metrics.cell_cos_ti()[mask]
    a = np.asarray(rec_table.values, dtype=float)[:, :, mask]
    b = np.asarray(truth.values, dtype=float)[:, :, mask]
    d = np.log1p(np.maximum(a, 0) * ci) - np.log1p(np.maximum(b, 0) * ci)  # (C, 72, cells)
    w = geo.volume_weight()[mask]
    d2 = np.nanmean(d**2, axis=(0, 1))  # per cell, over channels and ph
    ds = np.nanmean(d, axis=(0, 1))
    total = float(np.sum(w * d2))
    th, td, pd = (g[mask] for g in geo.grid_angles())
    c_i, c_o = geo.cell_cosines(th, td, pd)
    tmax = np.arccos(np.clip(np.minimum(c_i, c_o), -1, 1))
    out: dict[str, Any] = {"log_rmse": float(np.sqrt(total / np.sum(w)))}
    for name, v, edges in (("theta_h", th, (10.0, 20.0, 30.0, 45.0, 60.0)),
                           ("theta_d", td, (10.0, 20.0, 30.0, 45.0, 60.0)),
                           ("max(theta_i, theta_o)", tmax, (30.0, 45.0, 60.0, 70.0, 80.0))):
        k = _bins(v, edges)
        labels = ([f"<{edges[0]:g}"] + [f"{lo:g}-{hi:g}"
                                          for lo, hi in itertools.pairwise(edges)]
                  + [f">={edges[-1]:g}"])
        out[name] = [(labels[j], float(np.sum(w[k == j]) / np.sum(w)),
                      float(np.sum((w * d2)[k == j]) / total),
                      float(np.sum((w * ds)[k == j]) / max(np.sum(w[k == j]), 1e-300)))
                     for j in range(len(labels))]
    return out


def rescan(names: list[str]) -> None:
    """Re-read ``names`` with the default plan and MA98 (bench_selfestimate's seeds) and print
    :func:`error_map` of each reconstruction."""
    bu.CHOOSE["objective"] = "posterior"
    bu.SPAN["scan"] = bu.SPAN["design"] = DEFAULT_SPAN_DEG
    for i, (m, _kind, _which) in enumerate(bs.materials()):
        if m.name not in names:
            continue
        b = default_basis(exclude=m.exclude)
        for label, design, r in bs.PLANS:
            if label not in ("default n=10 r=8", "MA98 r=8"):
                continue
            cells, ph = bu.design(b, 10) if design == "posterior" else get_preset(design).cells()
            alpha = uniform_stage_angles(r, span=np.deg2rad(DEFAULT_SPAN_DEG))
            vals = bu.read(m, cells, ph, alpha, 100 + i)
            rec = reconstruct(b, cells, ph, alpha, vals)
            emap = error_map(rec.table, m.truth)
            print(f"\n{m.name}, {label}: log_rmse {emap['log_rmse']:.3f}, estimate "
                  f"{rec.predicted_log_rmse:.3f}")
            for key in ("theta_h", "theta_d", "max(theta_i, theta_o)"):
                print(f"  {key:22s} " + "  ".join(
                    f"{lab}: w {wt:.2f} err {sh:.2f} sign {sg:+.2f}"
                    for lab, wt, sh, sg in emap[key]))


#: The candidate term studied (docs/science.md 7.1.1.3; rule written and committed before any
#: value of the witness was computed): ``sqrt(shipped^2 + (k lobe)^2)`` on the preset scans
#: (MA68, MA98) only, ``lobe`` = :func:`unread_lobe` of the reconstruction, ``k`` over
#: :data:`LOBE_GRID`. Choice on the calibration set: the largest ``k`` that leaves it no more
#: scans more than 2x low and at most :data:`LOBE_CAL_SLACK` fewer within x2 than the shipped
#: estimate (the calibration set has no preset scan more than 2x low, so there is nothing to
#: minimise there). Check on the choice set: no more scans low and at most one fewer within x2;
#: otherwise not proposed. The test set and the fresh sets are then reported once (within x2 /
#: more than 2x low / more than 2x high), with no condition (the study proposes nothing itself).
LOBE_GRID = tuple(round(0.05 * i, 2) for i in range(0, 61))
LOBE_CAL_SLACK = 2
PRESET_PLANS = ("MA98 r=8", "MA68 r=8")


def unread_lobe(table: Any, cells: np.ndarray) -> float:
    """The structure a reconstruction puts where the layout reads no ``theta_d``.

    The ``log_rmse``-weighted RMS, over the valid cells whose ``theta_d`` is more than half a
    grid step beyond the layout's largest, of the table's log value (``ln(1 + f cos ti)``,
    ``f`` averaged over channels and ``ph``) minus that of the table made flat along
    ``theta_h`` (its weighted mean over ``theta_h`` at the same ``(theta_d, phi_d)``),
    normalised by the weight of every valid cell (``log_rmse`` units).

    A matte table is flat along ``theta_h`` there (0); a lobe that the fit carries from the
    read ``theta_d`` into the unread ones gives a large value. Reconstruction and layout
    only, never the truth.

    Parameters
    ----------
    table : BRDFTable
        The reconstruction, (C, 72, 18, 18, 36) values in 1/sr.
    cells : (n, 3) array, radians
        The layout's ``(theta_h, theta_d, phi_d)``.
    """
    mask = geo.valid_mask()
    ci = np.maximum(metrics.cell_cos_ti(), 0.0)
    f = np.nanmean(np.maximum(np.asarray(table.values, dtype=float), 0.0), axis=(0, 1))
    w = np.where(mask, geo.volume_weight(), 0.0)
    _th, td, _pd = geo.grid_angles()
    unread = mask & (td > float(np.max(cells[:, 1])) + geo.STEP / 2)
    wsum = np.sum(w, axis=0)  # per (td, pd) column
    flat = np.sum(w * np.where(mask, f, 0.0), axis=0) / np.where(wsum > 0, wsum, 1.0)
    dev2 = np.where(unread, (np.log1p(f * ci) - np.log1p(flat[None] * ci)) ** 2, 0.0)
    return float(np.sqrt(np.sum(w * dev2) / np.sum(w)))


def lobe_rows(out: Path) -> None:
    """Re-read every material with the presets (bench_selfestimate's seeds) and write one JSON
    line per scan to ``out``: material, plan, the truth and :func:`unread_lobe`."""
    bu.CHOOSE["objective"] = "posterior"
    bu.SPAN["scan"] = bu.SPAN["design"] = DEFAULT_SPAN_DEG
    with out.open("w") as fh:
        for i, (m, _kind, which) in enumerate(bs.materials()):
            b = default_basis(exclude=m.exclude)
            for label, design, r in bs.PLANS:
                if label not in PRESET_PLANS:
                    continue
                cells, ph = get_preset(design).cells()
                alpha = uniform_stage_angles(r, span=np.deg2rad(DEFAULT_SPAN_DEG))
                vals = bu.read(m, cells, ph, alpha, 100 + i)
                rec = reconstruct(b, cells, ph, alpha, vals)
                fh.write(json.dumps({
                    "material": m.name, "set": which, "plan": label,
                    "truth": metrics.log_rmse(rec.table, m.truth),
                    "widened": rec.predicted_log_rmse,
                    "lobe": unread_lobe(rec.table, np.asarray(cells))}) + "\n")
                fh.flush()
            print(f"  {m.name}", flush=True)


def lobe_truth(names: list[str]) -> None:
    """For ``names`` read with MA98 (bench_selfestimate's seeds): :func:`unread_lobe` of the
    reconstruction beside that of the truth (the lobe the specimen really has there)."""
    bu.CHOOSE["objective"] = "posterior"
    bu.SPAN["scan"] = bu.SPAN["design"] = DEFAULT_SPAN_DEG
    print("| material | log_rmse | unread lobe, reconstruction | unread lobe, truth |")
    print("|---|---|---|---|")
    for i, (m, _kind, _which) in enumerate(bs.materials()):
        if m.name not in names:
            continue
        cells, ph = get_preset("MA98").cells()
        alpha = uniform_stage_angles(8, span=np.deg2rad(DEFAULT_SPAN_DEG))
        vals = bu.read(m, cells, ph, alpha, 100 + i)
        rec = reconstruct(default_basis(exclude=m.exclude), cells, ph, alpha, vals)
        c = np.asarray(cells)
        print(f"| {m.name} | {metrics.log_rmse(rec.table, m.truth):.3f} | "
              f"{unread_lobe(rec.table, c):.3f} | {unread_lobe(m.truth, c):.3f} |", flush=True)


def _count(sel: list[dict[str, Any]], est: Any) -> tuple[int, int, int]:
    q = np.array([r["truth"] / est(r) for r in sel])
    return int(np.sum((q >= 0.5) & (q <= 2))), int(np.sum(q > 2)), int(np.sum(q < 0.5))


def lobe_study(rows: list[dict[str, Any]], lobes: list[dict[str, Any]]) -> None:
    """The candidate of :data:`LOBE_GRID` by its rule, on every plan's rows (the designed
    plans' estimates unchanged)."""
    lobe = {(r["material"], r["plan"]): r["lobe"] for r in lobes}

    def est(k: float) -> Any:
        return lambda r: (float(np.hypot(r["widened"], k * lobe[(r["material"], r["plan"])]))
                          if r["plan"] in PRESET_PLANS else r["widened"])

    def by(sets: tuple[str, ...]) -> list[dict[str, Any]]:
        return [r for r in rows if r["set"] in sets]

    cal = by(("cal",))
    w0, low0, _ = _count(cal, est(0.0))
    ok = [k for k in LOBE_GRID if _count(cal, est(k))[1] <= low0
          and _count(cal, est(k))[0] >= w0 - LOBE_CAL_SLACK]
    k = max(ok)
    print(f"calibration: shipped {_count(cal, est(0.0))}, chosen k = {k}: "
          f"{_count(cal, est(k))} (within x2, low, high)")
    for k2 in LOBE_GRID[::4]:
        print(f"  k = {k2}: cal {_count(cal, est(k2))}")
    groups = (("choice",), ("test",), ("fresh", "fresh-inplane", "fresh-confirm"),
              ("fresh-wide", "fresh-coat", "fresh-high", "fresh-cov", "fresh-mirror"))
    print("| sets | scans | shipped | candidate |")
    print("|---|---|---|---|")
    for g in (("cal",), *groups):
        sel = by(g)
        print(f"| {', '.join(g)} | {len(sel)} | {_count(sel, est(0.0))} | "
              f"{_count(sel, est(k))} |")
    print("\nMA98 scans more than 2x low (shipped), with the candidate:")
    for r in rows:
        if r["plan"] in PRESET_PLANS and r["truth"] > 2 * r["widened"]:
            print(f"  {r['material']} {r['set']} {r['plan']}: true {r['truth']:.3f}, shipped "
                  f"{r['widened']:.3f}, lobe {lobe[(r['material'], r['plan'])]:.3f}, "
                  f"candidate {est(k)(r):.3f}")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args:
        print(__doc__)
        return 2
    if args[0] == "lobe-truth":
        lobe_truth(args[1:])
        return 0
    if args[0] == "lobe-rows":
        lobe_rows(Path(args[1]))
        return 0
    rows = json.loads(Path(args[0]).read_text())
    if len(args) == 3 and args[1] == "lobe-study":
        lobes = [json.loads(line) for line in Path(args[2]).read_text().splitlines()]
        lobe_study(rows, lobes)
        return 0
    rows_tables(rows)
    if args[1:]:
        rescan(args[1:])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
