"""Calibrate and validate ``predicted_log_rmse`` on materials held out of the basis.

Run from the project root (needs mitsuba and ``../shared/data/rgl``; several minutes)::

    nice -n 5 .venv/bin/python bench/calibrate_log_rmse.py [--rows FILE] [--objective posterior]

Materials and readings are those of ``bench/bench_unseen.py`` (measured materials each with
a basis that leaves it out, mitsuba anisotropic specimens; 1 % noise), plus the held-out
*training* panel of :mod:`gonio.brdf.design.heldout` (one synthetic material per library family,
held out of the panel basis). Scans: pairs designed on each material's own basis for n = 5,
10, 20, plus the MA68 and MA98 presets, each at r = 4, 8, 16 uniform stage angles. With
``--objective posterior`` the scans are n = 10 pairs designed by the joint fit's expected
error (``design_pairs(..., objective="posterior")``) at r = 4, 8, 16: a check that the
module's model, calibrated on the default layouts, holds for the other design objective
(nothing is refitted on them unless ``--refit`` is given).

Split: the **calibration** set is the synthetic panel and the measured materials at even
positions; the **validation** set is the measured materials at odd positions and all six
anisotropic mitsuba specimens (an independent renderer: never calibrated on). Every
candidate model is fitted by least squares in ``ln(log_rmse)`` on the calibration set and
scored by

* its calibration rms (ln units);
* a leave-one-material-out cross-validation *within* the calibration set (rms and share
  within x2): the honest way to choose features, since the validation set is never used to
  choose;
* the share of validation scans whose truth lies within x2 of the estimate (overall,
  measured, anisotropic), and the count at the default scan (designed n = 10, r = 8) over the
  17 unseen materials.

Two model forms: log-linear ``ln t = a + sum_k b_k ln(feature_k)`` and the two-term form of
:mod:`gonio.brdf.reconstruction.selfcheck`,
``t^2 = exp(a) expected^2 + exp(b) prod_k feature_k^{c_k}`` (the posterior's error plus a
discrepancy term). Witnesses recorded per scan (:func:`witnesses`): the posterior's expected
error, its prior scale ``s2``, anisotropy factor ``rho`` and log evidence per reading, the
fit's normalised residual, the leave-one-pair-out / leave-one-angle-out errors (relative, in
log units, and standardised by their posterior variance), the Mahalanobis norm of the fit
under the prior (per pair and per reading), the reconstruction's log level, peak-to-median
ratio and albedo proxy, the spread of the readings along the stage angle, ``n`` and ``r``.
The module's :data:`gonio.brdf.reconstruction.selfcheck.LOG_RMSE_MODEL` is printed as
``module``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

# Run as `python bench/calibrate_log_rmse.py`, so the sibling script is importable.
import bench_unseen as bu
import numpy as np
import scipy.linalg
from scipy.optimize import least_squares

from gonio.brdf.design.presets import get_preset
from gonio.brdf.reconstruction.basis import Basis, default_basis
from gonio.brdf.reconstruction.posterior import (
    ScanPosterior,
    _cos_ti_rows,
    _volume_weight_rows,
)
from gonio.brdf.reconstruction.reconstruct import _VALID_ROWS, reconstruct
from gonio.brdf.reconstruction.samples import uniform_stage_angles
from gonio.brdf.reconstruction.selfcheck import (
    LOG_RMSE_FEATURES,
    LOG_RMSE_MODEL,
    predict_log_rmse,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics

LN2 = float(np.log(2.0))


def witnesses(b: Basis, cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray,
              vals: np.ndarray, truth: Any) -> dict[str, float]:
    """Every candidate witness of one scan, and the truth (``log_rmse`` against ``truth``)."""
    rec = reconstruct(b, cells, ph, alpha, vals)
    post = ScanPosterior(b, cells, ph, alpha, vals, table=rec.table.values)
    n, r = vals.shape[:2]
    y = post.y
    N, C = y.shape
    cho = post._chol
    beta = scipy.linalg.cho_solve(cho, y)
    logdet = 2.0 * float(np.sum(np.log(np.diag(cho[0]))))
    # Standardised leave-one-out errors: each left-out block's squared error over the
    # posterior predictive variance of that error (1 on average if the model were right).
    Ginv = scipy.linalg.cho_solve(cho, np.eye(N)).reshape(n, r, n, r)
    bq = beta.reshape(n, r, C)
    z_pair = sum(float(np.sum(bq[q] * np.linalg.solve(Ginv[q, :, q, :], bq[q])))
                 for q in range(n)) / (N * C * post.s2)
    z_angle = (sum(float(np.sum(bq[:, j] * np.linalg.solve(Ginv[:, j, :, j], bq[:, j])))
                   for j in range(r)) / (N * C * post.s2)) if r > 1 else float("nan")
    f = np.asarray(rec.table.values, dtype=float).reshape(3, geo.N_PH, geo.N_ROWS)
    f = np.maximum(np.nan_to_num(f[:, ::3][:, :, _VALID_ROWS]), 0.0)
    ci, wv = _cos_ti_rows(), _volume_weight_rows()
    w = wv / wv.sum()
    level = np.log1p(f * ci).mean(axis=(0, 1))
    th, td, pd = np.asarray(cells).T
    ci_s, _ = geo.cell_cosines(th, td, pd)
    lr = np.log1p(vals * ci_s[:, None, None])
    ang = rec.angle_log_errors
    return {
        "truth": metrics.log_rmse(rec.table, truth),
        "predicted": rec.predicted_log_rmse,
        "expected": rec.expected_log_rmse,
        "mahalanobis": rec.mahalanobis,
        "mahalanobis_per_reading": rec.mahalanobis / r,
        "cv_sample_error": rec.cv_sample_error,
        "cv_log_error": rec.cv_log_error,
        "cv_angle_log_error": (float(np.sqrt(np.mean(ang**2))) if ang is not None
                               else float("nan")),
        "z_loo_pair": z_pair,
        "z_loo_angle": z_angle,
        "s2": post.s2,
        "rho": post.rho,
        "log_evidence": -0.5 * np.log(post.s2) - 0.5 * logdet / N,
        "chi2_fit": post.eta * float(np.sum(beta**2)) / (N * C * post.s2),
        "log_level": float(np.sum(level * w)),
        "peak_to_median": float(np.max(f) + 1e-6) / float(np.median(f) + 1e-6),
        "albedo": float(np.sum((f * ci).mean(axis=(0, 1)) * w)),
        "reading_spread_alpha": float(np.sqrt(np.mean(lr.var(axis=1)))) if r > 1 else 1e-9,
        "n": float(n), "r": float(r), "nr": float(n * r),
    }


def scans(objective: str) -> list[dict[str, Any]]:
    from gonio.brdf.design.heldout import _panel

    pb, synth, _ = _panel()
    mats = [(bu.Material(t.name, "panel", t, t, ()), pb) for t in synth]
    mats += [(m, default_basis(exclude=m.exclude)) for m in bu.measured_materials()]
    mats += [(m, default_basis()) for m in bu.aniso_materials()]
    pos: dict[str, int] = {}
    for kind in ("panel", "measured", "aniso"):
        pos.update({m.name: i for i, m in enumerate(m for m, _ in mats if m.kind == kind)})
    bu.CHOOSE["objective"] = objective
    rows: list[dict[str, Any]] = []
    for i, (m, b) in enumerate(mats):
        if objective == "kappa":
            geoms = {f"designed n={n}": bu.design(b, n) for n in (5, 10, 20)}
            geoms.update({p: get_preset(p).cells() for p in ("MA98", "MA68")})
        else:
            geoms = {f"{objective} n=10": bu.design(b, 10)}
        for gname, (cells, ph) in geoms.items():
            for r in (4, 8, 16):
                alpha = uniform_stage_angles(r)
                vals = bu.read(m, cells, ph, alpha, 100 + i)
                row: dict[str, Any] = {
                    "material": m.name, "kind": m.kind, "geom": gname,
                    "cal": int(m.kind == "panel"
                               or (m.kind == "measured" and pos[m.name] % 2 == 0)),
                }
                row.update(witnesses(b, cells, ph, alpha, vals, m.truth))
                rows.append(row)
        print(f"  {m.name} done", flush=True)
    return rows


# ---------------------------------------------------------------------------- models
Model = Callable[[np.ndarray, dict[str, np.ndarray]], np.ndarray]


def loglinear(feats: tuple[str, ...]) -> tuple[Model, int]:
    def model(p: np.ndarray, F: dict[str, np.ndarray]) -> np.ndarray:
        return p[0] + sum((p[1 + k] * F[f] for k, f in enumerate(feats)),
                          np.zeros_like(F["expected"]))
    return model, 1 + len(feats)


def two_term(feats: tuple[str, ...]) -> tuple[Model, int]:
    """``ln t = ln(exp(a) expected^2 + exp(b) prod feature^c) / 2``."""
    def model(p: np.ndarray, F: dict[str, np.ndarray]) -> np.ndarray:
        disc = p[1] + sum((p[2 + k] * F[f] for k, f in enumerate(feats)),
                          np.zeros_like(F["expected"]))
        return 0.5 * np.logaddexp(p[0] + 2.0 * F["expected"], disc)
    return model, 2 + len(feats)


def fit(model: Model, k: int, F: dict[str, np.ndarray], y: np.ndarray,
        sel: np.ndarray, linear: bool) -> np.ndarray:
    if linear:  # closed form
        X = np.column_stack([model(np.eye(k)[j], F) - model(np.zeros(k), F)
                             for j in range(k)])
        return np.asarray(np.linalg.lstsq(X[sel], y[sel], rcond=None)[0])
    p0 = np.r_[0.0, 8.0, 1.0, np.zeros(k - 3)]
    return np.asarray(least_squares(lambda p: model(p, F)[sel] - y[sel], p0).x)


#: (label, form, features). The module's choice is marked in the table.
CANDIDATES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("log-linear", "lin", ()),
    *(("log-linear", "lin", (f,)) for f in (
        "expected", "cv_sample_error", "cv_log_error", "cv_angle_log_error", "z_loo_pair",
        "z_loo_angle", "s2", "rho", "log_evidence", "chi2_fit", "mahalanobis",
        "mahalanobis_per_reading", "log_level", "peak_to_median", "albedo",
        "reading_spread_alpha", "nr")),
    ("log-linear", "lin", ("cv_sample_error", "nr")),
    ("log-linear", "lin", ("expected", "cv_sample_error")),
    ("log-linear", "lin", ("expected", "mahalanobis")),
    ("log-linear", "lin", ("expected", "mahalanobis", "cv_sample_error")),
    ("log-linear", "lin", ("expected", "mahalanobis", "log_evidence")),
    ("two-term", "two", ("cv_sample_error",)),
    ("two-term", "two", ("s2",)),
    ("two-term", "two", ("mahalanobis_per_reading",)),
    ("two-term", "two", ("mahalanobis",)),
    ("two-term", "two", ("mahalanobis_per_reading", "cv_sample_error")),
    ("two-term", "two", ("mahalanobis", "cv_sample_error")),
    ("two-term", "two", ("mahalanobis", "cv_sample_error", "rho")),
    ("two-term", "two", ("mahalanobis", "cv_sample_error", "log_evidence")),
    ("two-term", "two", ("mahalanobis", "cv_angle_log_error")),
    ("two-term", "two", ("mahalanobis", "cv_sample_error", "reading_spread_alpha")),
    ("two-term", "two", ("mahalanobis", "log_level")),
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rows", type=Path, default=None,
                    help="JSON file of the scans: read it if it exists, else write it")
    ap.add_argument("--objective", choices=("kappa", "posterior"), default="kappa",
                    help="design objective of the scanned layouts (see the module notes)")
    ap.add_argument("--calibration-rows", type=Path, default=None,
                    help="with --objective posterior: the default layouts' rows file, to fit "
                         "the candidates on (default: only the module's model is scored)")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    if args.rows is not None and args.rows.is_file():
        rows = json.loads(args.rows.read_text())
    else:
        rows = scans(args.objective)
        if args.rows is not None:
            args.rows.write_text(json.dumps(rows))
    for r in rows:  # the module's current model (the file may predate it)
        r["predicted"] = predict_log_rmse(r["expected"], r["mahalanobis"], r["cv_sample_error"])
    fit_rows = rows
    if args.calibration_rows is not None:
        fit_rows = json.loads(args.calibration_rows.read_text())
    report(rows, fit_rows)
    return 0


def _arrays(rows: list[dict[str, Any]]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    feats = [k for k, v in rows[0].items() if isinstance(v, float) and k != "truth"]
    F = {}
    for f in feats:
        v = np.array([float(r[f]) for r in rows])
        F[f] = v if f == "log_evidence" else np.log(np.maximum(np.nan_to_num(v, nan=1.0), 1e-12))
    return F, np.log([float(r["truth"]) for r in rows])


def report(rows: list[dict[str, Any]], fit_rows: list[dict[str, Any]]) -> None:
    F, y = _arrays(rows)
    Ff, yf = _arrays(fit_rows)
    kind = np.array([r["kind"] for r in rows])
    cal = np.array([bool(r["cal"]) for r in rows])
    calf = np.array([bool(r["cal"]) for r in fit_rows])
    matf = np.array([r["material"] for r in fit_rows])
    val = ~cal
    default = np.array([r["geom"] in ("designed n=10", "posterior n=10") and r["r"] == 8
                        for r in rows]) & (kind != "panel")
    same = rows is fit_rows
    print(f"{cal.sum()} calibration scans ({len(set(matf[calf]))} materials), "
          f"{val.sum()} validation scans; fitted on {'these' if same else 'the calibration rows'}")
    print("| form | features | coefficients | cal rms | CV rms | CV within x2 | "
          "val within x2 | measured | anisotropic | default scan |")
    print("|---|---|---|---|---|---|---|---|---|---|")

    def line(label: str, feats: str, coef: str, res: np.ndarray, cv: np.ndarray) -> None:
        ok = np.abs(res) <= LN2
        cv_rms = f"{np.sqrt(np.mean(cv**2)):.3f}" if cv.size else ""
        cv_ok = f"{np.mean(np.abs(cv) <= LN2):.0%}" if cv.size else ""
        cal_rms = f"{np.sqrt(np.mean(res[cal] ** 2)):.3f}" if cal.any() else ""
        print(f"| {label} | {feats} | {coef} | {cal_rms} | {cv_rms} | {cv_ok} | "
              f"{ok[val].mean():.0%} | {ok[val & (kind == 'measured')].mean():.0%} | "
              f"{ok[val & (kind == 'aniso')].mean():.0%} | {int(ok[default].sum())} of "
              f"{int(default.sum())} |")

    med = float(np.median(yf[calf]))  # last round's baseline: the calibration median
    line("constant (calibration median)", f"{np.exp(med):.4f}", "", med - y, np.zeros(0))
    for label, form, feats in CANDIDATES:
        model, k = (loglinear if form == "lin" else two_term)(feats)
        p = fit(model, k, Ff, yf, calf, form == "lin")
        cv = np.zeros(0)
        if same:
            cvres = np.full(y.shape, np.nan)
            for m in np.unique(matf[calf]):  # leave one calibration material out
                tr, te = calf & (matf != m), calf & (matf == m)
                cvres[te] = model(fit(model, k, Ff, yf, tr, form == "lin"), F)[te] - y[te]
            cv = cvres[cal]
        line(label, " + ".join(feats) or "constant", ", ".join(f"{v:.3f}" for v in p),
             model(p, F) - y, cv)
    line("**module**", " + ".join(LOG_RMSE_FEATURES), ", ".join(map(str, LOG_RMSE_MODEL)),
         np.log([float(r["predicted"]) for r in rows]) - y, np.zeros(0))


if __name__ == "__main__":
    raise SystemExit(main())
