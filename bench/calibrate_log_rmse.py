"""Calibrate and validate ``predicted_log_rmse`` on materials held out of the basis.

Run from the project root (needs mitsuba and ``../shared/data/rgl``)::

    nice -n 5 .venv/bin/python bench/calibrate_log_rmse.py [--rows FILE] [--fit-on ...]

One command does everything: it scans, records every witness, fits every candidate and
prints the table. Each scan's witnesses and the expected-error designs are cached under ``<gonio
cache>/bench-unseen/calibrate-<fingerprint>``, where the fingerprint is a digest of what the
current joint fit and the default design produce on a fixed probe
(``bench_unseen.fit_fingerprint``) and of the default and scanned arcs (:func:`fit_fingerprint`):
a re-run with both unchanged only refits (seconds); after a change of either every design
and scan is redone (11 min wall as two processes with ``--only`` over halves of the
materials, which share the cache, on the 2-core machine; 30 min under heavier load). The
condition-number designs are cached per basis and fingerprint, as ``bench_unseen.py`` caches
them. ``--rows FILE`` also
writes (or, if present, reads: then nothing is checked against the fingerprint) all rows as
one JSON file; ``--only NAME...`` scans a subsample to debug.

Materials and readings are those of ``bench/bench_unseen.py`` (measured materials each with a
basis that leaves it out, mitsuba anisotropic specimens; 1 % noise), plus the held-out
*training* panel of :mod:`gonio.brdf.design.heldout` (one synthetic material per library
family, held out of the panel basis), plus ``bench_prior.py``'s fresh synthetic materials
(:func:`fresh_materials`: library recipes drawn with ``seed=7``, in no basis, read on the
default basis and its designs; 18 anisotropic, 6 isotropic). Scans (:data:`LAYOUTS`, arcs
:data:`SPANS`): the product's default layouts, pairs designed by the joint fit's expected error
(``objective="posterior"``) for a scan over half a turn (``span_deg=180``, the default arc) for
n = 5, 10, 20 at r = 8 and read over half a turn at r = 4, 8, 16, and n = 10 designed for r = 4
and 16 over half a turn; the same n = 10 layouts designed for and read over a full turn
(``span_deg=360``, a user's choice); the MA68 and MA98 presets at r = 4, 8, 16 over half and
over a full turn; V&F's condition-number designs (``objective="kappa"``, the older default) for
n = 5, 10, 20 over half a turn and n = 10 over a full turn, each at r = 4, 8, 16. The arc is
part of each row (``span_deg``) and of its cache key. ``--fit-on`` and ``--fit-arcs`` say which
designs' and arcs' calibration scans the models are fitted on.

Split: the **calibration** set is the synthetic panel, the fresh synthetic materials and the
measured materials at even positions; the **validation** set is the measured materials at odd
positions and all six anisotropic mitsuba specimens (an independent renderer: never calibrated
on). Every candidate model is fitted by least squares in ``ln(log_rmse)`` on the calibration
set and scored by

* its calibration rms (ln units);
* a leave-one-material-out cross-validation *within* the calibration set (rms and share
  within x2): the honest way to choose features, since the validation set is never used to
  choose;
* the same CV on the calibration scans with the default (expected-error) design;
* the same CV on the fresh synthetic materials alone, beside the module's (and the previous
  module's) own residual there (:func:`fresh_check`): a module fitted without them is out of
  sample on them, so this says whether a refit is preferred on the calibration side;
* the share of validation scans whose truth lies within x2 of the estimate: overall; with the
  default design over half a turn (all, measured, anisotropic); with the presets; with the
  kappa designs; over a full turn (every design); and the count at the default scan
  (expected-error design n = 10, r = 8, half a turn) over the 17 unseen materials.

Two model forms: log-linear ``ln t = a + sum_k b_k ln(feature_k)`` and the two-term form of
:mod:`gonio.brdf.reconstruction.selfcheck`,
``t^2 = exp(a) expected^2 + exp(b) prod_k feature_k^{c_k}`` (the posterior's error plus a
discrepancy term). Witnesses recorded per scan (:func:`witnesses`): the posterior's expected
error, its prior scale ``s2``, anisotropy factor ``rho`` and log evidence per reading, the
fit's normalised residual, the leave-one-pair-out / leave-one-angle-out errors (relative, in
log units, and standardised by their posterior variance), the Mahalanobis norm of the fit
under the prior (per pair and per reading), the reconstruction's log level, peak-to-median
ratio and albedo proxy, the spread of the readings along the stage angle, ``n``, ``r``, the
number of distinct azimuths each pair sees (``azimuths``: angles half a turn apart read the
same under the prior, so ``r`` over half a turn, ``r / 2`` over a full turn) and the arc.
The module's :data:`gonio.brdf.reconstruction.selfcheck.LOG_RMSE_MODEL` is printed as
``module``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
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
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, uniform_stage_angles
from gonio.brdf.reconstruction.selfcheck import (
    LOG_RMSE_CAPS,
    LOG_RMSE_FEATURES,
    LOG_RMSE_MODEL,
    predict_joint_log_rmse,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import VALID_ROWS

LN2 = float(np.log(2.0))
#: The module's model before the half-turn layouts (calibrated on full-turn scans only):
#: ``(a, b, c, d)`` and caps, printed beside the current one for comparison.
PREVIOUS_MODEL = ((0.553, 2.431, 0.911, 0.973), (1.021e-3, 4.699))


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
    f = np.maximum(np.nan_to_num(f[:, ::3][:, :, VALID_ROWS]), 0.0)
    ci, wv = _cos_ti_rows(), _volume_weight_rows()
    w = wv / wv.sum()
    level = np.log1p(f * ci).mean(axis=(0, 1))
    th, td, pd = np.asarray(cells).T
    ci_s, _ = geo.cell_cosines(th, td, pd)
    lr = np.log1p(vals * ci_s[:, None, None])
    ang = rec.angle_log_errors
    # Distinct azimuths each pair sees: the prior along ph has only even harmonics, so angles
    # half a turn apart read the same (r over half a turn: r; r even over a full turn: r / 2).
    half = np.mod(np.asarray(alpha, dtype=float), np.pi)
    half = np.where(half > np.pi - 1e-9, 0.0, half)
    azimuths = int(np.unique(np.round(half, 9)).size)
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
        "azimuths": float(azimuths), "n_azimuths": float(n * azimuths),
    }


#: Layout families (``--layouts``). ``posterior`` is what the product runs by default
#: (``design_pairs``' ``DEFAULT_OBJECTIVE`` and ``DEFAULT_SPAN_DEG``): pairs designed by the joint
#: fit's expected error for a half-turn scan, n = 5, 10, 20 at ``rotations=8`` (the CLI's and
#: the API's default), read at r = 4, 8, 16 over half a turn (a design at 8 read at other r is
#: what an adaptive scan or a changed plan does), plus n = 10 designed *for* r = 4 and r = 16
#: and read there (``gonio design --rotations R``); and the same n = 10 layouts designed for and
#: read over a full turn (a user's choice of 360 degrees). ``presets``: MA68 and MA98 at
#: r = 4, 8, 16 over half and over a full turn. ``kappa``: V&F's condition-number designs
#: (the older default; they do not depend on the arc), n = 5, 10, 20 at r = 4, 8, 16 over half
#: a turn, and n = 10 over a full turn.
LAYOUTS: tuple[str, ...] = ("posterior", "presets", "kappa")
ROTATIONS: tuple[int, ...] = (4, 8, 16)
#: The arcs scanned (degrees): the product's default first.
SPANS: tuple[float, ...] = (DEFAULT_SPAN_DEG, 360.0)
#: Pair counts scanned over each arc; a full turn only for n = 10 (and the presets).
PAIRS: dict[float, tuple[int, ...]] = {DEFAULT_SPAN_DEG: (5, 10, 20), 360.0: (10,)}

#: One scan layout: ``(design, geom, cells, ph_lab, r, span_deg)``.
Layout = tuple[str, str, np.ndarray, np.ndarray, int, float]


def _posterior_design(b: Basis, n: int, r: int, span_deg: float,
                      cache: Path) -> tuple[np.ndarray, np.ndarray]:
    """``design_pairs(b, n, objective="posterior", rotations=r, span_deg=span_deg)``, cached.

    The expected-error design depends on the joint fit's prior, so it is cached with the rows
    under the fingerprint (a changed fit redesigns), not in ``bench_unseen.py``'s per-basis
    cache.
    """
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    path = cache / f"design-{bu.basis_id(b)}-n{n}-r{r}-span{span_deg:g}.npz"
    if path.is_file():
        with np.load(path) as z:
            return z["cells"], z["ph_lab"]
    d = design_pairs(b, n, RigConstraints(), objective="posterior", rotations=r,
                     span_deg=span_deg)
    np.savez(path, cells=d.cells, ph_lab=d.ph_lab)
    return np.asarray(d.cells), np.asarray(d.ph_lab)


def layouts(b: Basis, family: str, cache: Path) -> list[Layout]:
    """``(design, geom, cells, ph_lab, r, span_deg)`` of every scan of one layout family."""
    out: list[Layout] = []
    for span in SPANS:
        if family == "posterior":
            for n in PAIRS[span]:
                cells, ph = _posterior_design(b, n, 8, span, cache)
                out += [("posterior", f"posterior n={n}", cells, ph, r, span) for r in ROTATIONS]
            for r in ROTATIONS:
                if r != 8:
                    cells, ph = _posterior_design(b, 10, r, span, cache)
                    out.append(("posterior", f"posterior n=10 for r={r}", cells, ph, r, span))
        elif family == "kappa":  # the condition number depends on the basis alone
            bu.CHOOSE["objective"] = "kappa"
            for n in PAIRS[span]:
                cells, ph = bu.design(b, n)
                out += [("kappa", f"designed n={n}", cells, ph, r, span) for r in ROTATIONS]
        else:
            for p in ("MA98", "MA68"):
                cells, ph = get_preset(p).cells()
                out += [("preset", p, cells, ph, r, span) for r in ROTATIONS]
    return out


#: Kinds of the fresh synthetic materials (:func:`fresh_materials`): calibration only.
FRESH_KINDS: tuple[str, ...] = ("fresh-aniso", "fresh-iso")


def fresh_materials() -> list[bu.Material]:
    """``bench_prior.py``'s fresh materials, for calibration: in no basis, read on the default.

    The library's own recipes drawn with another seed (``library_specs(seed=7)``), as many per
    family as ``bench_prior.FRESH`` (8 brushed metals, 6 fabrics, 4 metals: ``fresh-aniso``;
    6 isotropic ones: ``fresh-iso``), named ``f7-<name>``. Without them the calibration set
    holds one clearly anisotropic material (the panel's brushed metal), so its
    leave-one-material-out CV cannot see how anisotropic specimens behave.
    """
    from bench_prior import FRESH

    from gonio.brdf.materials import library
    from gonio.brdf.models import analytic as bm

    out: list[bu.Material] = []
    count: dict[str, int] = {}
    for s in library.library_specs(seed=7):
        if count.get(s.family, 0) >= FRESH[s.family]:
            continue
        count[s.family] = count.get(s.family, 0) + 1
        vals = bu._cached(f"fresh7-{s.name}", lambda s=s: np.asarray(
            bm.tabulate_valid(s.model), dtype=np.float32))
        if vals.shape[1] == 1:  # isotropic: one slice broadcast to every ph
            vals = np.repeat(vals, geo.N_PH, axis=1)
        aniso = s.family in ("brushed-metal", "fabric", "metal")
        kind = FRESH_KINDS[0] if aniso else FRESH_KINDS[1]
        out.append(bu.Material(f"f7-{s.name}", kind, bu._full_table(vals, s.name), s.model, ()))
    return out


def fit_fingerprint() -> str:
    """``bench_unseen.fit_fingerprint`` combined with the arcs this script scans.

    Cached rows and expected-error designs are reused only while this is unchanged. The probe
    (``bench_unseen.fit_fingerprint``) covers the joint fit and the expected-error design with
    ``design_pairs``' default arc, so a change of the default arc changes it through the
    design; its probe scan reads a full turn, and the reconstruction code is the same for
    either arc. The default arc and the scanned arcs and pair counts (:data:`SPANS`,
    :data:`PAIRS`) are hashed too, so a change of any of them redoes the rows even where the
    probe would not see it.
    """
    arcs = f"{DEFAULT_SPAN_DEG:g}|{SPANS}|{PAIRS}"
    return hashlib.sha256(f"{bu.fit_fingerprint()}|{arcs}".encode()).hexdigest()[:12]


def scans(families: tuple[str, ...], only: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """Witnesses of every scan of ``families`` (cached per scan under the fit's fingerprint)."""
    from gonio.brdf.design.heldout import _panel

    pb, synth, _ = _panel()
    mats = [(bu.Material(t.name, "panel", t, t, ()), pb) for t in synth]
    mats += [(m, default_basis(exclude=m.exclude)) for m in bu.measured_materials()]
    mats += [(m, default_basis()) for m in bu.aniso_materials()]
    # Appended last, so the seeds (100 + position) and cache keys of the others are unchanged.
    mats += [(m, default_basis()) for m in fresh_materials()]
    pos: dict[str, int] = {}
    for kind in ("panel", "measured", "aniso"):
        pos.update({m.name: i for i, m in enumerate(m for m, _ in mats if m.kind == kind)})
    fp = fit_fingerprint()
    cache = bu.CACHE / f"calibrate-{fp}"
    (cache / "rows").mkdir(parents=True, exist_ok=True)
    print(f"joint fit fingerprint {fp}; rows cached in {cache}", flush=True)
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    hits = 0
    for i, (m, b) in enumerate(mats):
        if only and m.name not in only:
            continue
        for family in families:
            for design, gname, cells, ph, r, span in layouts(b, family, cache):
                alpha = uniform_stage_angles(r, span=np.deg2rad(span))
                key = hashlib.sha256(
                    f"{m.name}|{bu.basis_id(b)}|{r}|{span:g}|{100 + i}".encode()
                    + np.ascontiguousarray(cells, dtype=float).tobytes()
                    + np.ascontiguousarray(ph, dtype=float).tobytes()).hexdigest()[:20]
                path = cache / "rows" / f"{key}.json"
                row: dict[str, Any] = {
                    "material": m.name, "kind": m.kind, "design": design, "geom": gname,
                    "span_deg": span,
                    "cal": int(m.kind in ("panel", *FRESH_KINDS)
                               or (m.kind == "measured" and pos[m.name] % 2 == 0)),
                }
                if path.is_file():
                    row.update(json.loads(path.read_text()))
                    hits += 1
                else:
                    vals = bu.read(m, cells, ph, alpha, 100 + i)
                    w = witnesses(b, cells, ph, alpha, vals, m.truth)
                    path.write_text(json.dumps(w))
                    row.update(w)
                rows.append(row)
        print(f"  {m.name} done ({time.perf_counter() - t0:.0f} s)", flush=True)
    print(f"{len(rows)} scans, {hits} from the cache", flush=True)
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


def cap(F: dict[str, np.ndarray], sel: np.ndarray,
        feats: tuple[str, ...]) -> dict[str, np.ndarray]:
    """``F`` with ``feats`` capped at their largest value on the rows ``sel`` (ln units).

    A power law fitted on witnesses up to some size says nothing about witnesses far beyond
    it; capping keeps the discrepancy term from extrapolating (chm_mint's leave-one-pair-out
    error reaches 23 with the default design, the calibration scans stop at 4.7).
    """
    out = dict(F)
    for f in feats:
        out[f] = np.minimum(F[f], F[f][sel].max())
    return out


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
        "reading_spread_alpha", "nr", "azimuths", "n_azimuths", "span_deg")),
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
    # Coverage: fewer pairs (or readings) leave more of the unrepresented structure unseen.
    ("two-term", "two", ("mahalanobis", "n")),
    ("two-term", "two", ("mahalanobis", "cv_sample_error", "n")),
    ("two-term", "two", ("mahalanobis", "cv_sample_error", "nr")),
    ("two-term", "two", ("mahalanobis_per_reading", "cv_sample_error", "n")),
    # The same forms with the discrepancy witnesses capped at their calibration maximum.
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error")),
    ("two-term, capped", "two-cap", ("mahalanobis_per_reading", "cv_sample_error")),
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error", "nr")),
    # The arc: r angles over half a turn show each pair r distinct azimuths, over a full turn
    # r / 2 (the prior holds only even harmonics along ph), so coverage by distinct azimuths,
    # or the arc itself, may say what r alone cannot.
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error", "r")),
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error", "n")),
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error", "azimuths")),
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error", "n_azimuths")),
    ("two-term, capped", "two-cap", ("mahalanobis", "cv_sample_error", "span_deg")),
    ("two-term, capped", "two-cap", ("mahalanobis_per_azimuth", "cv_sample_error")),
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rows", type=Path, default=None,
                    help="JSON file of the scans: read it if it exists, else write it")
    ap.add_argument("--layouts", nargs="+", choices=LAYOUTS, default=list(LAYOUTS),
                    help="layout families to scan (default: all; see LAYOUTS)")
    ap.add_argument("--only", nargs="+", default=[], metavar="MATERIAL",
                    help="scan only these materials (to debug on a subsample)")
    ap.add_argument("--fit-on", nargs="+", choices=("posterior", "preset", "kappa"),
                    default=["posterior", "preset", "kappa"],
                    help="designs whose calibration scans the models are fitted on")
    ap.add_argument("--fit-arcs", nargs="+", type=float, choices=SPANS, default=list(SPANS),
                    help="arcs (degrees) whose calibration scans the models are fitted on")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    t0 = time.perf_counter()
    if args.rows is not None and args.rows.is_file():
        rows = json.loads(args.rows.read_text())
    else:
        rows = scans(tuple(args.layouts), tuple(args.only))
        if args.rows is not None:
            args.rows.write_text(json.dumps(rows))
    print(f"scans ready in {time.perf_counter() - t0:.0f} s")
    for r in rows:  # the module's current model (the file may predate it)
        r["predicted"] = predict_joint_log_rmse(r["expected"], r["mahalanobis"],
                                                r["cv_sample_error"])
    fit_rows = [r for r in rows if r["design"] in args.fit_on
                and float(r.get("span_deg", 360.0)) in args.fit_arcs]
    report(rows, fit_rows)
    misses(rows)
    return 0


def _arrays(rows: list[dict[str, Any]]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    feats = [k for k, v in rows[0].items() if isinstance(v, float) and k != "truth"]
    F = {}
    for f in feats:
        v = np.array([float(r.get(f, np.nan)) for r in rows])
        F[f] = v if f == "log_evidence" else np.log(np.maximum(np.nan_to_num(v, nan=1.0), 1e-12))
    # The Mahalanobis norm per distinct azimuth (ln units): per reading, with a full turn's
    # repeated azimuths counted once.
    F["mahalanobis_per_azimuth"] = F["mahalanobis"] - F["azimuths"]
    return F, np.log([float(r["truth"]) for r in rows])


def report(rows: list[dict[str, Any]], fit_rows: list[dict[str, Any]]) -> None:
    """Fit every candidate on the calibration scans of ``fit_rows``; print the table."""
    F, y = _arrays(rows)
    kind = np.array([r["kind"] for r in rows])
    design = np.array([r["design"] for r in rows])
    mat = np.array([r["material"] for r in rows])
    cal = np.array([bool(r["cal"]) for r in rows])
    fitted = {id(r) for r in fit_rows}
    calf = cal & np.array([id(r) in fitted for r in rows])
    val = ~cal
    span = np.array([float(r.get("span_deg", 360.0)) for r in rows])
    half = span == DEFAULT_SPAN_DEG
    # The product's default layouts: expected-error designs over the default arc.
    post = (design == "posterior") & half
    default = (np.array([r["geom"] == "posterior n=10" and r["r"] == 8 for r in rows])
               & half & np.isin(kind, ("measured", "aniso")))
    print(f"{cal.sum()} calibration scans of {len(set(mat[cal]))} materials, "
          f"{calf.sum()} fitted on (designs {sorted(set(design[calf]))}); "
          f"{val.sum()} validation scans of {len(set(mat[val]))} materials "
          f"({(val & post).sum()} with the default design over {DEFAULT_SPAN_DEG:g} deg, "
          f"{(val & post & (kind == 'measured')).sum()} measured; "
          f"{(val & (design == 'preset')).sum()} presets, {(val & (design == 'kappa')).sum()} "
          f"kappa, {(val & ~half).sum()} over a full turn)")
    print("| form | features | coefficients | cal rms | CV rms | CV rms, default design | "
          "CV within x2, default design | validation within x2 | default design | "
          "measured | anisotropic | presets | kappa | full turn | default scan |")
    print("|---" * 15 + "|")

    def share(ok: np.ndarray, sel: np.ndarray) -> str:
        return f"{ok[sel].mean():.0%} ({int(ok[sel].sum())})" if sel.any() else ""

    def line(label: str, feats: str, coef: str, res: np.ndarray, cv: np.ndarray) -> None:
        ok = np.abs(res) <= LN2
        cvs = ("", "", "")
        if cv.size:
            cvs = (f"{np.sqrt(np.mean(cv[calf] ** 2)):.3f}",
                   f"{np.sqrt(np.mean(cv[cal & post] ** 2)):.3f}" if (cal & post).any() else "",
                   share(np.abs(cv) <= LN2, cal & post))
        print(f"| {label} | {feats} | {coef} | {np.sqrt(np.mean(res[calf] ** 2)):.3f} | "
              f"{' | '.join(cvs)} | {share(ok, val)} | {share(ok, val & post)} | "
              f"{share(ok, val & post & (kind == 'measured'))} | "
              f"{share(ok, val & post & (kind == 'aniso'))} | "
              f"{share(ok, val & (design == 'preset'))} | {share(ok, val & (design == 'kappa'))} | "
              f"{share(ok, val & ~half)} | {int(ok[default].sum())} of {int(default.sum())} |")

    med = float(np.median(y[calf]))
    line("constant (calibration median)", f"{np.exp(med):.4f}", "", med - y, np.zeros(0))
    cvs: dict[str, np.ndarray] = {}
    for label, form, feats in CANDIDATES:
        model, k = (loglinear if form == "lin" else two_term)(feats)
        capped = form == "two-cap"
        Fc = cap(F, calf, feats) if capped else F
        p = fit(model, k, Fc, y, calf, form == "lin")
        cvres = np.full(y.shape, np.nan)
        for m in np.unique(mat[cal]):  # leave one calibration material out
            te, tr = cal & (mat == m), calf & (mat != m)
            Ft = cap(F, tr, feats) if capped else F  # caps from the training fold only
            cvres[te] = model(fit(model, k, Ft, y, tr, form == "lin"), Ft)[te] - y[te]
        caps = (" (caps " + ", ".join(f"{np.exp(Fc[f][calf].max()):.3g}" for f in feats) + ")"
                if capped else "")
        line(label, " + ".join(feats) or "constant", ", ".join(f"{v:.3f}" for v in p) + caps,
             model(p, Fc) - y, cvres)
        cvs[f"{label}: {' + '.join(feats) or 'constant'}"] = cvres
    line("**module**", " + ".join(LOG_RMSE_FEATURES),
         ", ".join(map(str, LOG_RMSE_MODEL)) + f" (caps {', '.join(map(str, LOG_RMSE_CAPS))})",
         np.log([float(r["predicted"]) for r in rows]) - y, np.zeros(0))
    (a, b, c, d), (m_cap, v_cap) = PREVIOUS_MODEL
    e, m, v = (np.exp(F[f]) for f in LOG_RMSE_FEATURES)
    previous = 0.5 * np.logaddexp(a + 2.0 * np.log(e), b + c * np.log(np.minimum(m, m_cap))
                                  + d * np.log(np.minimum(v, v_cap)))
    line("previous module (full-turn layouts)", " + ".join(LOG_RMSE_FEATURES),
         f"{a}, {b}, {c}, {d} (caps {m_cap}, {v_cap})", previous - y, np.zeros(0))
    paired_cv(cvs, mat, cal, calf)
    fresh_check(cvs, {"module": np.log([float(r["predicted"]) for r in rows]) - y,
                      "previous module": previous - y}, kind, post, calf)
    with_without_fresh(F, y, kind, mat, cal, calf, post)


def paired_cv(cvs: dict[str, np.ndarray], mat: np.ndarray, cal: np.ndarray,
              calf: np.ndarray) -> None:
    """Each candidate's CV against the module's form, per left-out calibration material.

    The CV rms differences between candidates are small; what decides whether one is better
    is whether it is better on most materials, not on the pooled sum: the mean over the
    calibration materials of the difference of their mean squared CV residuals (ln units
    squared; negative: the candidate is better), with its standard error.
    """
    ref_key = "two-term, capped: " + " + ".join(LOG_RMSE_FEATURES[1:])
    ref = cvs[ref_key]
    mats = np.unique(mat[calf])
    print(f"\nCV against `{ref_key}` (mean over the {mats.size} calibration materials of the "
          "difference in mean squared CV residual, +- standard error):")
    for key, res in cvs.items():
        d = np.array([np.mean(res[calf & (mat == m)] ** 2) - np.mean(ref[calf & (mat == m)] ** 2)
                      for m in mats])
        print(f"  {key}: {d.mean():+.4f} +- {d.std(ddof=1) / np.sqrt(d.size):.4f}")


def fresh_check(cvs: dict[str, np.ndarray], fixed: dict[str, np.ndarray], kind: np.ndarray,
                post: np.ndarray, calf: np.ndarray) -> None:
    """Residuals on the fresh synthetic materials: the candidates' CV, the fixed models' own.

    A fixed model not fitted on the fresh materials (the module before they joined the
    calibration set) is out of sample there, as each candidate's leave-one-material-out CV
    is, so the two rms (ln units) and shares within x2 compare like with like: the
    calibration-side test of whether a refit is preferred.
    """
    fresh = calf & np.isin(kind, FRESH_KINDS)
    if not fresh.any():
        return
    print("\nOn the fresh calibration materials (candidates: leave-one-material-out CV; fixed "
          "models: their own residual), rms (ln units) and within x2, all designs | default "
          "design over half a turn | anisotropic | isotropic:")
    groups = (fresh, fresh & post, fresh & (kind == FRESH_KINDS[0]),
              fresh & (kind == FRESH_KINDS[1]))
    for key, res in [*cvs.items(), *fixed.items()]:
        cells = [f"{np.sqrt(np.mean(res[g] ** 2)):.3f}, {np.mean(np.abs(res[g]) <= LN2):.0%}"
                 for g in groups]
        print(f"  {key}: {' | '.join(cells)}")


def with_without_fresh(F: dict[str, np.ndarray], y: np.ndarray, kind: np.ndarray,
                       mat: np.ndarray, cal: np.ndarray, calf: np.ndarray,
                       post: np.ndarray) -> None:
    """The module's form fitted with and without the fresh materials, per calibration kind.

    Both by leave-one-material-out CV over every calibration material (a fresh material is
    out of sample for the fit without them either way), so the two compare like with like:
    rms (ln units) and share within x2 of the CV residuals per kind, over every design and
    over the default design on half a turn; then the per-material paired difference (mean
    squared CV residual, with minus without; negative: the fit with them is better), mean +-
    standard error over the materials of each group.
    """
    if not np.isin(kind[calf], FRESH_KINDS).any():
        return
    feats = LOG_RMSE_FEATURES[1:]
    model, k = two_term(feats)
    fresh = np.isin(kind, FRESH_KINDS)
    res = {}
    for label, train in (("without", calf & ~fresh), ("with", calf)):
        r = np.full(y.shape, np.nan)
        for m in np.unique(mat[cal]):
            te, tr = cal & (mat == m), train & (mat != m)
            Ft = cap(F, tr, feats)
            r[te] = model(fit(model, k, Ft, y, tr, False), Ft)[te] - y[te]
        res[label] = r
    print(f"\nThe module's form ({' + '.join(feats)}, capped) fitted without / with the fresh "
          "materials, leave-one-material-out CV: rms, within x2 (all designs; default design "
          "over half a turn) | paired per-material difference with - without:")
    groups = {"all calibration": calf, "panel": calf & (kind == "panel"),
              "measured": calf & (kind == "measured"),
              "fresh-aniso": calf & (kind == FRESH_KINDS[0]),
              "fresh-iso": calf & (kind == FRESH_KINDS[1]), "panel + measured": calf & ~fresh}
    for g, sel in groups.items():
        cells = []
        for label in ("without", "with"):
            r = res[label]
            cells.append("; ".join(f"{np.sqrt(np.mean(r[t] ** 2)):.3f}, "
                                   f"{np.mean(np.abs(r[t]) <= LN2):.0%}"
                                   for t in (sel, sel & post)))
        mats = np.unique(mat[sel])
        d = np.array([np.mean(res["with"][sel & (mat == m)] ** 2)
                      - np.mean(res["without"][sel & (mat == m)] ** 2) for m in mats])
        se = d.std(ddof=1) / np.sqrt(d.size) if d.size > 1 else float("nan")
        print(f"  {g} ({mats.size}): without {cells[0]} | with {cells[1]} | "
              f"{d.mean():+.4f} +- {se:.4f}")


def misses(rows: list[dict[str, Any]]) -> None:
    """Where the module's estimate misses: per group, the count within x2 and the median ratio.

    Groups are (set, material kind, design, arc); ratio = estimate / truth. Then the module's
    estimate per material at the default scan (expected-error design n = 10, r = 8, half a
    turn), the 17 materials held out of their basis.
    """
    print("\nmodule within x2 by group (ratio = predicted / truth):")
    print("| set | kind | design | arc | within x2 | median ratio | under x0.5 | over x2 |")
    print("|---" * 8 + "|")
    groups: dict[tuple[str, str, str, str], list[float]] = {}
    for r in rows:
        key = ("calibration" if r["cal"] else "validation", r["kind"], r["design"],
               f"{r.get('span_deg', 360.0):g}")
        groups.setdefault(key, []).append(float(r["predicted"]) / float(r["truth"]))
    for key in sorted(groups):
        q = np.array(groups[key])
        ok = int(np.sum(np.abs(np.log(q)) <= LN2))
        print(f"| {' | '.join(key)} | {ok} of {q.size} | x{np.median(q):.2f} | "
              f"{int(np.sum(q < 0.5))} | {int(np.sum(q > 2.0))} |")
    print("\nmodule at the default scan (posterior n=10, r = 8, half a turn):")
    print("| material | set | true log_rmse | expected | mahalanobis | cv_sample_error | "
          "predicted_log_rmse (ratio) |")
    print("|---" * 7 + "|")
    for r in rows:
        if (r["geom"] == "posterior n=10" and r["r"] == 8 and r["kind"] in ("measured", "aniso")
                and r.get("span_deg") == DEFAULT_SPAN_DEG):
            print(f"| {r['material']} | {'calibration' if r['cal'] else 'validation'} | "
                  f"{r['truth']:.4f} | {r['expected']:.4f} | {r['mahalanobis']:.2e} | "
                  f"{r['cv_sample_error']:.2f} | {r['predicted']:.4f} "
                  f"(x{r['predicted'] / r['truth']:.2f}) |")


if __name__ == "__main__":
    raise SystemExit(main())
