"""One-off prototype: a leaning specimen as a twofold-symmetric BRDF seen in a tilted frame.

Run from the project root (needs mitsuba: ``pip install 'gonio[rgl]'``)::

    GONIO_CACHE_DIR=<warm cache> nice -n 10 .venv/bin/python bench/bench_tiltfit_proto.py \
        [--set choice|fresh4] [--score loo|insample|both]

The hypothesis (issue 25; docs/notes/2026-11-27-tilted-frame-fit.md): the specimens of
``bench_asymmetric.py`` (mitsuba ``normalmap`` over a rough conductor or plastic, every facet
leaning ``t`` towards ``b``) are a twofold-symmetric BRDF ``g`` seen through the lean, so the
**default** (symmetric) basis can fit them once every reading's light and view directions are
turned by the rotation ``R`` taking the leaning normal to ``+z``. Checked here against mitsuba
(``--check``): the bench's truth is ``g(R wi, R wo) * c(wo)`` with ``c`` the cosine ratio
``(R wo)_z / wo_z`` times mitsuba's bump-terminator shadowing term, exactly
(:func:`gonio.brdf.reconstruction.tilt.tilt_factor`). The prototype mirrors it: each reading is
divided by ``c`` before the fit and the fit's table multiplied by it.

Protocol (the ``asym full r=12`` row of ``bench_asymmetric.py``): 10 pairs designed by the
joint fit's expected error for the asymmetric basis over a full turn, 12 uniform stage angles
over 360 deg (120 readings), mitsuba at the exact pair directions, 1 % noise, seed 500 + index.
On those same readings, per specimen:

* ``shipped``: the joint fit with ``default_basis(asymmetric=True)`` (the bench's row);
* ``plain``: the joint fit with the default basis (no lean);
* ``est``: the tilt search with the default basis. Candidates: t 0-35 deg by 5, b every
  30 deg, then two finer rounds (2.5 / 10 and 1.25 / 5 deg) around the best; each candidate
  scored by ``loo`` (each pair's readings predicted from the other pairs' through the lean,
  RMS cosine-weighted log error of the readings as read, the study module's score) or
  ``insample`` (the same fit's prediction of every reading, including its own pair: the
  misfit of the readings; readings the lean puts below its horizon predicted 0), and each of
  them with the readings in the leaning frame's grazing band (dropped from the fit although
  above its horizon) left out of the score (``loo-band``, ``insample-band``: written after
  the first runs on every set but ``asym-fresh``, then run once on it). The result:
  the joint fit of the mapped readings, one cell per (pair, angle) reading, tabulated
  through the lean on gonio's grid (:func:`gonio.brdf.reconstruction.tilt.reconstruct_through`);
* ``true``: the same at the specimen's own lean (its azimuth plus the holder angle): the
  idea's upper bound with these readings;
* ``lookup``: no fit at all: the untilted twin's truth table seen through the true lean (the
  tabulation's own loss);
* the tilt found and CPU seconds (``time.process_time``) of the search plus the final fit.

The untilted twins (tilt 0) are run the same way: the search must find t near 0 and lose
nothing against ``plain``. ``--readings auto`` reads instead as the auto-arc path does (the
default design's pairs, R = 6, bench_asymmetric's ``tilt_scan``), ``shipped`` being the fit
with the basis the arc test's verdict chooses.

Sets: ``choice`` (``ASYM``), ``fresh``, ``fresh2``, ``fresh3``, ``fresh4`` (the earlier tilt
study saw them all), ``asym-fresh`` (``ASYM_FRESH``: never run through a tilt fit before the
band scores were written down) and ``symmetric``.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import bench_asymmetric as ba  # the sibling benches (the script's folder is on sys.path)
import bench_unseen as bu
import numpy as np

from gonio.brdf.models.analytic import facet_rotation
from gonio.brdf.reconstruction.basis import Basis, default_basis, inverse_remap
from gonio.brdf.reconstruction.joint import JOINT_ETA, JOINT_LAM, joint_prior
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import pair_directions, uniform_stage_angles
from gonio.brdf.reconstruction.tilt import (
    map_readings,
    mapped_joint_fit,
    reconstruct_through,
    tilt_factor,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics

#: Coarse search grid (deg): tilts 0-35 by 5, azimuths every 30; then two finer rounds.
TILTS_DEG = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0)
AZIMUTHS_DEG = tuple(float(a) for a in range(0, 360, 30))
REFINE_DEG = (2.5, 10.0)
#: The candidates' scores (:func:`candidate_errors`).
SCORES = ("loo", "insample", "loo-band", "insample-band")

#: The asymmetric sets of ``bench_asymmetric.py`` (``symmetric``: bench_unseen's six
#: anisotropic, twofold-symmetric specimens, run as the untilted group only).
SETS = {"choice": ba.ASYM, "fresh": ba.FRESH, "fresh2": ba.FRESH2, "fresh3": ba.FRESH3,
        "fresh4": ba.FRESH4, "asym-fresh": ba.ASYM_FRESH, "symmetric": []}


def candidate_errors(basis: Basis, cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray,
                     vals: np.ndarray, tilt: float, azimuth: float, prior: np.ndarray
                     ) -> dict[str, float]:
    """RMS log error of the readings under one lean, for every score of :data:`SCORES`.

    ``loo`` and ``insample`` count every reading, those the lean drops from the fit predicted
    0. The ``-band`` variants leave out of the score the readings the fit drops although
    both their directions are above the leaning horizon (within ``HORIZON_COS`` of it): a
    grazing direction in the leaning frame, where the basis holds nothing but the truth can
    be bright (al-r0.25-t20's two brightest readings, 24.7 and 28.7 1/sr, have a light 0.4-1
    deg above the true lean's horizon). Readings below that horizon still count, predicted 0
    (the normal map's value there).

    Parameters
    ----------
    basis : Basis, the default (symmetric) basis
    cells, ph, alpha : the scan (pair cells and lab ``ph``, stage angles), radians
    vals : (n, r, C) readings, 1/sr
    tilt, azimuth : float, radians, the candidate lean in the specimen frame
    prior : (M, K, K), ``joint_prior(basis, lam / eta)``

    Returns
    -------
    dict score -> float
        Root mean square over the readings scored and channels of the cosine-weighted log
        error (the units of ``log_rmse``); inf when the candidate cannot be fitted.
    """
    n, r, _ = vals.shape
    m = map_readings(cells, ph, alpha, vals, tilt, azimuth)
    wi_lab, wo_lab = pair_directions(cells, ph)
    R = facet_rotation(tilt, azimuth)
    up_i = geo.lab_to_specimen(wi_lab[:, None, :], alpha[None, :]) @ R.T
    up_o = geo.lab_to_specimen(wo_lab[:, None, :], alpha[None, :]) @ R.T
    band = ~m.keep & (up_i[..., 2] > 0) & (up_o[..., 2] > 0)
    fail = {k: float("inf") for k in SCORES}
    fit = mapped_joint_fit(basis, m, (n, r), JOINT_ETA, prior)
    if fit is None:
        return fail
    held, fitted, mu, fmed, w = fit.held, fit.fitted, fit.mu, fit.fmed, fit.w
    out = {}
    c = m.cos_i[..., None]
    for name, y in (("loo", held), ("insample", fitted)):
        pred = np.zeros_like(vals)
        back = inverse_remap(np.minimum(y + mu, 300.0), fmed, w, basis.eps)
        pred[m.keep] = np.maximum(back, 0.0) * m.factor[:, None]
        err = np.log1p(np.maximum(pred, 0.0) * c) - np.log1p(vals * c)
        out[name] = float(np.sqrt(np.mean(err**2)))
        out[f"{name}-band"] = float(np.sqrt(np.mean(err[~band] ** 2)))
    return out


def search(basis: Basis, cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray,
           vals: np.ndarray, prior: np.ndarray, scores: list[str], starts: int = 1
           ) -> dict[str, tuple[float, float, float]]:
    """The lean of least error for each score: coarse grid, then two finer rounds.

    ``starts`` > 1 refines around each of that many best coarse candidates (leans) and keeps
    the best refined one (a multi-start search). With one start each refinement round moves
    to the best lean tried so far by any score (the leans are shared between scores).

    Returns
    -------
    dict score -> (tilt deg, azimuth deg, error)
    """
    tried: dict[tuple[float, float], dict[str, float]] = {}

    def err(t: float, b: float, s: str) -> float:
        key = (round(t, 6), round(b % 360.0, 6) if t > 0 else 0.0)
        if key not in tried:
            tried[key] = candidate_errors(basis, cells, ph, alpha, vals,
                                          np.deg2rad(key[0]), np.deg2rad(key[1]), prior)
        return tried[key][s]

    for t in TILTS_DEG:
        for b in AZIMUTHS_DEG if t > 0 else (0.0,):
            err(t, b, scores[0])
    out = {}
    coarse = list(tried)
    for s in scores:
        finals = []
        firsts = ([min(tried, key=lambda k: err(k[0], k[1], s))] if starts == 1
                  else sorted(coarse, key=lambda k: err(k[0], k[1], s))[:starts])
        for start in firsts:
            best = start
            if best[0] > 0:
                dt, db = REFINE_DEG
                for _ in range(2):
                    t_c, b_c = best
                    near = [(t, b) for t in (t_c - dt, t_c, t_c + dt)
                            for b in (b_c - db, b_c, b_c + db) if t >= 0]
                    for t, b in near:
                        err(t, b, s)
                    keys = [(round(t, 6), round(b % 360.0, 6) if t > 0 else 0.0)
                            for t, b in near]
                    # One start: the best of every lean tried so far (for any score), as
                    # the runs before the multi-start option did.
                    pool = list(tried) if starts == 1 else [best, *keys]
                    best = min(pool, key=lambda k: err(k[0], k[1], s))
                    dt, db = dt / 2, db / 2
            finals.append(best)
        best = min(finals, key=lambda k: err(k[0], k[1], s))
        out[s] = (best[0], best[1], err(best[0], best[1], s))
    return out


def one_specimen(plain: Basis, asym: Basis, prior: np.ndarray, m: bu.Material,
                 cells: np.ndarray, ph: np.ndarray, seed: int, true_lean: tuple[float, float],
                 scores: list[str], twin: bu.Material | None, readings: str = "row",
                 starts: int = 1) -> dict[str, Any]:
    """Every column of the table for one specimen (module notes)."""
    out: dict[str, Any] = {}
    t0 = time.process_time()
    if readings == "row":
        # The bench's own row: the same readings (seed, angles) and the shipped fit on them.
        out["shipped"], alpha, vals = ba.scan(asym, m, cells, ph, 12, 360.0, seed)
        assert np.allclose(alpha, uniform_stage_angles(12, span=2 * np.pi))
    else:
        # The auto-arc path (bench_asymmetric's tilt_scan, R = 6): the shipped fit is the one
        # with the basis the arc test's verdict chooses.
        from gonio.plans.arc import arc_test, fill_angles, first_round_angles

        first = first_round_angles(0.0, 6, 1)
        vals = bu.read(m, cells, ph, np.deg2rad(first), seed)
        test = arc_test(first, vals, 0.01)
        angles = list(first)
        if not test["symmetric"]:
            fill = fill_angles(0.0, 6, 1)
            vals = np.concatenate([vals, bu.read(m, cells, ph, np.deg2rad(fill), seed + 1)],
                                  axis=1)
            angles += fill
        alpha = np.deg2rad(angles)
        basis = plain if test["symmetric"] else asym
        out["shipped"] = metrics.log_rmse(reconstruct(basis, cells, ph, alpha, vals).table,
                                          m.truth)
    out["shipped_cpu"] = time.process_time() - t0
    t0 = time.process_time()
    out["plain"] = metrics.log_rmse(reconstruct(plain, cells, ph, alpha, vals).table, m.truth)
    out["plain_cpu"] = time.process_time() - t0
    t0 = time.process_time()
    found = search(plain, cells, ph, alpha, vals, prior, scores, starts)
    search_cpu = time.process_time() - t0
    for s, (t, b, e) in found.items():
        t1 = time.process_time()
        table = reconstruct_through(plain, cells, ph, alpha, vals, np.deg2rad(t),
                                    np.deg2rad(b))[1]
        out[f"est_{s}"] = metrics.log_rmse(table, m.truth)
        out[f"lean_{s}"] = (t, b % 360.0)
        out[f"score_{s}"] = e
        # The search is shared between scores; each is charged all of it.
        out[f"cpu_{s}"] = search_cpu + time.process_time() - t1
    tt, tb = true_lean
    # The scores at the true lean: below the found lean's, the search missed it; above, the
    # score itself prefers the wrong lean.
    at_true = candidate_errors(plain, cells, ph, alpha, vals, np.deg2rad(tt), np.deg2rad(tb),
                               prior)
    for s in scores:
        out[f"true_score_{s}"] = at_true[s]
    out["true"] = metrics.log_rmse(
        reconstruct_through(plain, cells, ph, alpha, vals, np.deg2rad(tt), np.deg2rad(tb))[1],
        m.truth)
    if twin is not None and tt > 0:
        from gonio.brdf.reconstruction.tilt import tilted_table

        out["lookup"] = metrics.log_rmse(
            tilted_table(twin.truth, np.deg2rad(tt), np.deg2rad(tb)), m.truth)
    return out


def check_truth(specs: list[tuple[str, float, float, dict[str, Any], float]]) -> None:
    """How the bench's truth relates to the untilted BSDF (module notes): mitsuba's normal map
    against the inner BSDF at the leaning frame's directions, three candidate factors."""
    rng = np.random.default_rng(0)
    print("\n| specimen | factor | median abs ln ratio | 90th pct | max |")
    print("|---|---|---|---|---|")
    for name, t, az, inner, holder in specs:
        tilted = bu.MitsubaSpecimen(ba.normalmap_spec(t, az, inner), holder)
        flat = bu.MitsubaSpecimen(inner, holder)
        th = np.arccos(rng.uniform(np.cos(np.deg2rad(69.0)), 1.0, (2, 400)))
        p = rng.uniform(0.0, 2 * np.pi, (2, 400))
        d = np.stack([np.sin(th) * np.cos(p), np.sin(th) * np.sin(p), np.cos(th)], axis=-1)
        wi, wo = d[0], d[1]
        R = facet_rotation(np.deg2rad(t), np.deg2rad(az + holder))
        ri, ro = wi @ R.T, wo @ R.T
        f_t = tilted.eval(wi, wo)[:, 0]
        up = (ri[:, 2] > 0.05) & (ro[:, 2] > 0.05) & (f_t > 1e-3)
        f_p = flat.eval(ri[up], ro[up])[:, 0]
        ok = f_p > 1e-3
        for label, c in (("1", np.ones(int(up.sum()))),
                         ("cos ratio", ro[up, 2] / wo[up, 2]),
                         ("cos ratio x shadowing", tilt_factor(R, wo[up]))):
            e = np.abs(np.log(f_t[up][ok] / (f_p[ok] * c[ok])))
            print(f"| {name} | {label} | {np.median(e):.4f} | {np.percentile(e, 90):.4f} | "
                  f"{e.max():.4f} |", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=sorted(SETS), default="choice",
                    help="the asymmetric specimens (bench_asymmetric's ASYM or FRESH4)")
    ap.add_argument("--score", choices=(*SCORES, "both", "all"), default="all",
                    help="the candidates' score (module notes; both: loo and insample)")
    ap.add_argument("--no-twins", action="store_true", help="skip the untilted twins")
    ap.add_argument("--readings", choices=("row", "auto"), default="row",
                    help="row: the asym full r=12 row's readings (default); auto: the auto-arc "
                         "path's (the default design's pairs, R = 6: 12 angles over the full "
                         "turn when the arc test calls the specimen asymmetric)")
    ap.add_argument("--starts", type=int, default=1,
                    help="refine around this many best coarse leans (a multi-start search)")
    ap.add_argument("--check", action="store_true",
                    help="only the truth check (mitsuba's normal map against the inner BSDF)")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    specs = SETS[args.set]
    if args.check:
        check_truth(specs)
        return 0
    scores = (["loo", "insample"] if args.score == "both" else list(SCORES)
              if args.score == "all" else [args.score])
    t0 = time.perf_counter()
    plain = default_basis()
    asym = default_basis(asymmetric=True)
    cells, ph = ba.design(asym, 360.0, 10) if args.readings == "row" else ba.design(plain, 180.0)
    prior = joint_prior(plain, JOINT_LAM / JOINT_ETA)
    mats = ba.asym_materials(specs=specs) if specs else []
    twins = ([] if args.no_twins else ba.asym_materials(tilted=False, specs=specs)
             if specs else bu.aniso_materials())
    print(f"ready in {time.perf_counter() - t0:.0f} s; " + (
        "10 pairs (asymmetric basis' design for a full turn), 12 angles over 360 deg"
        if args.readings == "row" else "the auto-arc path (default design, R = 6)")
        + ", 1 % noise, seed 500 + index")
    groups = [("tilted", mats, [(s[1], (s[2] + s[4]) % 360.0) for s in specs])] if specs else []
    if twins:
        groups.append(("untilted twins" if specs else "symmetric (bench_unseen's anisotropic)",
                       twins, [(0.0, 0.0)] * len(twins)))
    for label, group, leans in groups:
        est_cols = " | ".join(f"est ({s}) | lean found ({s}) | score found / true ({s}) | "
                              f"CPU s ({s})" for s in scores)
        print(f"\n{label} ({args.set}):\n\n| specimen | shipped (asym basis) | plain (default "
              f"basis) | {est_cols} | true lean | lookup | true t / b | CPU s shipped |")
        print("|---" * (7 + 4 * len(scores)) + "|")
        rows = []
        for i, (m, lean) in enumerate(zip(group, leans, strict=True)):
            twin = twins[i] if group is mats and twins else None
            r = one_specimen(plain, asym, prior, m, cells, ph, 500 + i, lean, scores, twin,
                             args.readings, args.starts)
            rows.append([r["shipped"], r["plain"], *[r[f"est_{s}"] for s in scores],
                         r["true"], r.get("lookup", np.nan)])
            est = " | ".join(f"{r[f'est_{s}']:.4f} | {r[f'lean_{s}'][0]:.2f} / "
                             f"{r[f'lean_{s}'][1]:.0f} | {r[f'score_{s}']:.4f} / "
                             f"{r[f'true_score_{s}']:.4f} | {r[f'cpu_{s}']:.1f}"
                             for s in scores)
            lookup = f"{r['lookup']:.4f}" if "lookup" in r else "-"
            print(f"| {m.name} | {r['shipped']:.4f} | {r['plain']:.4f} | {est} | "
                  f"{r['true']:.4f} | {lookup} | {lean[0]:.0f} / {lean[1]:.0f} | "
                  f"{r['shipped_cpu']:.1f} |", flush=True)
        a = np.array(rows, dtype=float)
        mean = a.mean(axis=0)
        cells_mean = [f"{mean[0]:.4f}", f"{mean[1]:.4f}"]
        for j in range(len(scores)):
            cells_mean += [f"**{mean[2 + j]:.4f}**", "", "", ""]
        cells_mean += [f"{mean[-2]:.4f}", f"{mean[-1]:.4f}" if np.isfinite(mean[-1]) else "-",
                       "", ""]
        print("| **mean** | " + " | ".join(cells_mean) + " |")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
