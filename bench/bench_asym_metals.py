"""Study: where the asymmetric metals' error is, and which levers move it (issue 25).

Run from the project root (needs mitsuba)::

    nice -n 10 .venv/bin/python bench/bench_asym_metals.py [--set even|odd] [options]

The specimens are ``bench_asymmetric.py``'s :data:`bench_asymmetric.ASYM` (mitsuba normal maps
over rough metals and plastics, facets leaning 10-30 deg). ``--set even`` takes those at even
positions of the list (al-r0.10, au, red-plastic-r0.10, blue-plastic: where levers are chosen),
``--set odd`` the others (al-r0.25, cu, red-plastic-r0.25, ag-aniso: reported once for the
choice), ``--set all`` all eight. Each specimen is read with 1 % noise at ``--seeds`` seeds
(``500 + index`` first, as ``bench_asymmetric.py``'s ``asym full r=12`` column) and fitted with
the asymmetric basis (``default_basis(asymmetric=True)``); the pairs are designed for a full turn
by the joint fit's expected error with the asymmetric basis.

Per specimen the table gives the fit's ``log_rmse``, the basis' ceiling (every cell known), and
where the squared error lies: the share in the lobe's peak (cells whose half vector lies within
``PEAK_DEG`` of the tilted mirror direction, found as the truth's brightest half vector at
``td = 0``), in its flank (up to ``FLANK_DEG``) and in the body, with the same split for the
ceiling; and how close the readings come to the tilted mirror direction (the smallest angle
between a reading's half vector and it, and how many readings lie within ``PEAK_DEG``).

Levers (each alone against the default row): ``--design-mix`` (the design's render weighting
share; ``None`` the default 0.5, ``0`` unweighted), ``--design-rotations`` (the angles the design
assumes), ``--pairs`` / ``--rotations`` (the same 120 readings split otherwise), ``--eta``,
``--local`` (local priors forced on the asymmetric basis, which skips them by default),
``--rho``, ``--adaptive`` (the product's adaptive auto-arc plan capped at 12 angles, its
refinement planned with the asymmetric basis), ``--design-basis default --design-span 180`` (the
pairs the default design makes, which a scan has when its arc test calls the specimen
asymmetric), ``--max-elevation``; and two new ones: ``--design-weight band`` (the design's second
weighting is the tilted facets' mirror band, ``th_h`` between :data:`BAND_DEG`, in place of the
renderings' pixel counts) and ``--peak-round K`` (:func:`peak_round`: K of the angles read where
the first angles saw the lobes). ``--design-seed`` takes several designs (the greedy's first
pair) and averages over them: one pair more or less moves a specimen by up to 0.08.
Findings: docs/notes/2026-11-28-asymmetric-metals.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import bench_asymmetric as ba  # sibling benches (the script's folder is on sys.path)
import bench_unseen as bu
import numpy as np

from gonio.brdf.design.constraints import RigConstraints
from gonio.brdf.design.pairs import design_pairs
from gonio.brdf.reconstruction import reconstruct as rec_mod
from gonio.brdf.reconstruction.basis import Basis, default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import pair_directions, uniform_stage_angles
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics

MASK = geo.valid_mask()
PEAK_DEG = 8.0
"""Half vectors within this angle of the tilted mirror direction are the lobe's peak."""
FLANK_DEG = 20.0
"""... and up to this angle its flank; the rest is the body."""
BAND_DEG = (5.0, 35.0)
"""The mirror band of facets leaning 5-30 deg (the library's tilted families), ``th_h``."""


def design(b: Basis, n: int, rotations: int, mix: float | None, weight: str,
           span: float = 360.0, seed: int = 0, max_elevation: float = 80.0
           ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs designed for ``span`` deg with ``b`` (cached by the settings and the code)."""
    tag = f"n{n}-rot{rotations}-mix{mix}-{weight}-span{span:g}-seed{seed}-el{max_elevation:g}"
    path = bu.CACHE / f"metals-design-{bu.basis_id(b)}-{tag}-{bu.fit_fingerprint()}.npz"
    if path.is_file():
        with np.load(path) as z:
            return z["cells"], z["ph_lab"]
    kw: dict[str, Any] = {}
    if weight == "band":
        th, _, _ = geo.grid_angles()
        w = ((th >= np.deg2rad(BAND_DEG[0])) & (th <= np.deg2rad(BAND_DEG[1]))).astype(float)
        kw = {"cell_weight": w * geo.volume_weight(), "cell_mix": 0.5 if mix is None else mix}
    elif mix is not None:
        kw = {"cell_mix": mix}
    t0 = time.process_time()
    d = design_pairs(b, n, RigConstraints(max_elevation_deg=max_elevation),
                     objective="posterior", span_deg=span, rotations=rotations, seed=seed, **kw)
    print(f"  design {tag}: {time.process_time() - t0:.0f} s CPU", flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, cells=d.cells, ph_lab=d.ph_lab)
    return np.asarray(d.cells), np.asarray(d.ph_lab)


def mirror_direction(truth: Any) -> np.ndarray:
    """The truth's brightest half vector at ``td = 0``, ``th_h <= 40`` deg (the tilted mirror
    direction; a plastic's grazing Fresnel rise is left out), unit."""
    v = np.asarray(truth.values, dtype=float)[1, :, :9, 0, 0]  # G, (72 ph, 9 th)
    k, i = np.unravel_index(np.nanargmax(v), v.shape)
    return geo.spherical_to_direction(geo.TH_GRID[i], geo.PH_GRID[k])


def half_angles(n_t: np.ndarray) -> np.ndarray:
    """(72, 18, 18, 36) angle (deg) between each cell's half vector and ``n_t``."""
    h = geo.spherical_to_direction(geo.TH_GRID[None, :], geo.PH_GRID[:, None])  # (72, 18, 3)
    a = np.rad2deg(np.arccos(np.clip(h @ n_t, -1.0, 1.0)))
    return np.broadcast_to(a[:, :, None, None], geo.TABLE_SHAPE)


def error_split(fit: Any, truth: Any, ang: np.ndarray) -> tuple[float, float, float]:
    """Shares of the squared (weighted) log error in the peak, the flank and the body."""
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    a = np.asarray(fit.values if hasattr(fit, "values") else fit, dtype=float)
    b = np.asarray(truth.values, dtype=float)
    d = (np.log1p(np.maximum(a, 0) * ci) - np.log1p(np.maximum(b, 0) * ci)) ** 2
    d = np.where(np.isfinite(d), d, 0.0) * geo.volume_weight() * MASK
    e = d.sum(axis=0)  # (72, 18, 18, 36)
    tot = e.sum()
    return (float(e[ang < PEAK_DEG].sum() / tot),
            float(e[(ang >= PEAK_DEG) & (ang < FLANK_DEG)].sum() / tot),
            float(e[ang >= FLANK_DEG].sum() / tot))


def reading_angles(cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray, n_t: np.ndarray
                   ) -> np.ndarray:
    """(n, r) angle (deg) between each reading's half vector and ``n_t``."""
    wi_lab, wo_lab = pair_directions(cells, ph)
    wi = geo.lab_to_specimen(wi_lab[:, None, :], alpha[None, :])
    wo = geo.lab_to_specimen(wo_lab[:, None, :], alpha[None, :])
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    return np.rad2deg(np.arccos(np.clip(h @ n_t, -1.0, 1.0)))


def peak_round(vals: np.ndarray, alpha: np.ndarray, k: int) -> np.ndarray:
    """``k`` midpoints of the uniform ``alpha`` where the pairs' lobes were seen (module notes).

    Each pair votes for the midpoint between its brightest stage angle and the brighter of
    that angle's two neighbours (a peak between two angles lies on the brighter side), with
    its contrast (the largest log reading over the median, channels summed) as the weight,
    and for the midpoint on the other side with half of it; the ``k`` midpoints with the most
    votes are returned. A linear-Gaussian posterior cannot place these angles: its variance
    does not depend on the readings' values."""
    r = alpha.size
    lv = np.log(np.maximum(vals, 1e-12)).sum(axis=2)  # (n, r)
    score = np.zeros(r)  # midpoint j lies between angles j and j + 1
    for q in range(lv.shape[0]):
        c = float(lv[q].max() - np.median(lv[q]))
        k_max = int(np.argmax(lv[q]))
        right = lv[q][(k_max + 1) % r] >= lv[q][(k_max - 1) % r]
        near, far = (k_max, (k_max - 1) % r) if right else ((k_max - 1) % r, k_max)
        score[near] += c
        score[far] += 0.5 * c
    picks = np.argsort(-score, kind="stable")[:k]
    return np.sort(alpha[picks] + np.pi / r)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=("even", "odd", "all"), default="even")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--pairs", type=int, default=10)
    ap.add_argument("--rotations", type=int, default=12)
    ap.add_argument("--design-rotations", type=int, default=8)
    ap.add_argument("--design-mix", type=float, default=None)
    ap.add_argument("--design-weight", choices=("render", "band"), default="render")
    ap.add_argument("--design-basis", choices=("asym", "default"), default="asym",
                    help="the basis the pairs are designed with (default: the product's own "
                         "pairs, the default basis over --design-span)")
    ap.add_argument("--design-span", type=float, choices=(180.0, 360.0), default=360.0)
    ap.add_argument("--design-seed", type=int, nargs="+", default=[0],
                    help="the greedy design's first pair (0: the best); several: the mean over "
                         "the designs")
    ap.add_argument("--max-elevation", type=float, default=80.0,
                    help="the design's largest light or sensor zenith angle (deg)")
    ap.add_argument("--eta", type=float, default=None)
    ap.add_argument("--rho", default="scan",
                    help="the joint fit's prior factor: scan (default), scan-bands, none or a "
                         "number")
    ap.add_argument("--local", action="store_true",
                    help="force local priors on the asymmetric basis")
    ap.add_argument("--adaptive", action="store_true",
                    help="the adaptive auto-arc plan (12 angles at most) on the pairs")
    ap.add_argument("--peak-round", type=int, default=0, metavar="K",
                    help="read --rotations minus K uniform angles, then K midpoints where the "
                         "lobes were seen (peak_round)")
    ap.add_argument("--diag", action="store_true", help="the error split and the readings' reach")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}", flush=True)
    t0 = time.perf_counter()
    if args.local:
        rec_mod.local_prior_skipped = lambda basis, cells: None  # type: ignore[assignment]
    asym = default_basis(asymmetric=True)
    rho: Any = (None if args.rho == "none" else args.rho if args.rho in ("scan", "scan-bands")
                else float(args.rho))
    plain = default_basis() if args.adaptive or args.design_basis == "default" else asym
    designs = [design(asym if args.design_basis == "asym" else plain, args.pairs,
                      args.design_rotations, args.design_mix, args.design_weight,
                      args.design_span, ds, args.max_elevation) for ds in args.design_seed]
    for cells, _ in designs:
        print("pairs th_h / td / pd (deg): " + ", ".join(
            "/".join(f"{x:.0f}" for x in np.rad2deg(c)) for c in cells), flush=True)
    index = {"even": range(0, 8, 2), "odd": range(1, 8, 2), "all": range(8)}[args.set]
    mats = ba.asym_materials()
    alpha = uniform_stage_angles(args.rotations, span=2 * np.pi)
    head = ["log_rmse", "ceiling"]
    if len(designs) > 1:
        head += ["per design"]
    if args.diag:
        head += ["fit peak/flank/body %", "ceiling peak/flank/body %", "lean t (deg)",
                 "closest reading (deg)", f"readings < {PEAK_DEG:g} deg", "pairs |th-t|<8"]
    print("\n| specimen | " + " | ".join(head) + " |")
    print("|---" * (len(head) + 1) + "|")
    rows = []
    nread = 0
    for i in index:
        m = mats[i]
        per_design = []
        fit = None
        for cells, ph in designs:
            errs = []
            for s in range(args.seeds):
                seed = 500 + i + 1000 * s
                if args.adaptive:
                    out = ba.adaptive_scan(plain, asym, m, cells, ph, seed, True, "auto", 12)
                    errs.append(out["log_rmse"])
                    nread = out["readings"]
                    continue
                a_scan = alpha
                if args.peak_round:
                    a_scan = uniform_stage_angles(args.rotations - args.peak_round,
                                                  span=2 * np.pi)
                    vals = bu.read(m, cells, ph, a_scan, seed)
                    extra = peak_round(vals, a_scan, args.peak_round)
                    vals = np.concatenate([vals, bu.read(m, cells, ph, extra, seed + 1)], axis=1)
                    a_scan = np.concatenate([a_scan, extra])
                else:
                    vals = bu.read(m, cells, ph, alpha, seed)
                r = reconstruct(asym, cells, ph, a_scan, vals, eta=args.eta, rho=rho)
                errs.append(metrics.log_rmse(r.table, m.truth))
                fit = fit if fit is not None else r.table
                nread = vals.shape[0] * vals.shape[1]
            per_design.append(float(np.mean(errs)))
        ceil = bu.ceiling(asym, m.truth)
        row = [float(np.mean(per_design)), metrics.log_rmse(ceil, m.truth)]
        rows.append(row)
        cols = [f"{v:.4f}" for v in row]
        if len(designs) > 1:
            cols += [" ".join(f"{v:.3f}" for v in per_design)]
        if args.diag and fit is not None:
            cells, ph = designs[0]
            n_t = mirror_direction(m.truth)
            ang = half_angles(n_t)
            t_deg = float(np.rad2deg(np.arccos(n_t[2])))
            ra = reading_angles(cells, ph, alpha, n_t)
            th_p = np.rad2deg(cells[:, 0])
            cols += ["/".join(f"{100 * x:.0f}" for x in error_split(fit, m.truth, ang)),
                     "/".join(f"{100 * x:.0f}" for x in error_split(ceil, m.truth, ang)),
                     f"{t_deg:.0f}", f"{ra.min():.1f}", f"{int((ra < PEAK_DEG).sum())}",
                     f"{int((np.abs(th_p - t_deg) < PEAK_DEG).sum())}"]
        print(f"| {m.name} | " + " | ".join(cols) + " |", flush=True)
    mean = np.mean(rows, axis=0)
    print(f"| **mean** | {mean[0]:.4f} | {mean[1]:.4f} |")
    print(f"readings per scan {nread}; total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
