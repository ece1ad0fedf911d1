"""Calibrate and validate ``predicted_log_rmse`` on materials held out of the basis.

Run from the project root (needs mitsuba and ``../shared/data/rgl``; several minutes)::

    nice -n 5 .venv/bin/python bench/calibrate_log_rmse.py

Materials and readings are those of ``bench/bench_unseen.py`` (measured materials each with
a basis that leaves it out, mitsuba anisotropic specimens; 1 % noise), plus the held-out
*training* panel of :mod:`gonio.brdf.design.heldout` (one synthetic material per library family,
held out of the panel basis). Scans: pairs designed on each material's own basis for n = 5,
10, 20, plus the MA68 and MA98 presets, each at r = 4, 8, 16 uniform stage angles.

Split: the **calibration** set is the synthetic panel and the measured materials at even
positions; the **validation** set is the measured materials at odd positions and all six
anisotropic mitsuba specimens (an independent renderer: never calibrated on). For each
candidate model ``ln(log_rmse) = a + sum_k b_k ln(feature_k)`` the script prints its
coefficients and the share of scans whose truth lies within x2 of the estimate, next to the
constant guess (the calibration median). Features: the joint posterior's expected error
(:attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.expected_log_rmse`), the
leave-one-pair-out log error (``cv_log_error``), the relative one (``cv_sample_error``) and
``n r``. The module's :data:`gonio.brdf.reconstruction.selfcheck.LOG_RMSE_MODEL` is the model
printed as ``chosen``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

# Run as `python bench/calibrate_log_rmse.py`, so the sibling script is importable.
import bench_unseen as bu
import numpy as np

from gonio.brdf.design.presets import get_preset
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import uniform_stage_angles
from gonio.brdf.reconstruction.selfcheck import LOG_RMSE_FEATURES, LOG_RMSE_MODEL
from gonio.brdf.tables import metrics

FEATURES = ("expected", "cv_log_error", "cv_sample_error", "nr")
#: Candidate models: the features each uses.
CANDIDATES: tuple[tuple[str, ...], ...] = (
    ("cv_sample_error", "nr"),
    ("cv_log_error",),
    ("expected",),
    ("expected", "cv_log_error"),
    ("expected", "cv_sample_error"),
    ("expected", "cv_log_error", "nr"),
)


def scans() -> list[dict[str, float | str | int]]:
    from gonio.brdf.design.heldout import _panel

    pb, synth, _ = _panel()
    mats = [(bu.Material(t.name, "panel", t, t, ()), pb) for t in synth]
    mats += [(m, default_basis(exclude=m.exclude)) for m in bu.measured_materials()]
    mats += [(m, default_basis()) for m in bu.aniso_materials()]
    pos: dict[str, int] = {}
    for kind in ("panel", "measured", "aniso"):
        pos.update({m.name: i for i, m in enumerate(m for m, _ in mats if m.kind == kind)})
    rows: list[dict[str, float | str | int]] = []
    for i, (m, b) in enumerate(mats):
        geoms = {f"designed n={n}": bu.design(b, n) for n in (5, 10, 20)}
        geoms.update({p: get_preset(p).cells() for p in ("MA98", "MA68")})
        for gname, (cells, ph) in geoms.items():
            for r in (4, 8, 16):
                alpha = uniform_stage_angles(r)
                vals = bu.read(m, cells, ph, alpha, 100 + i)
                rec = reconstruct(b, cells, ph, alpha, vals)
                rows.append({
                    "material": m.name, "kind": m.kind, "geom": gname, "r": r,
                    "cal": int(m.kind == "panel"
                               or (m.kind == "measured" and pos[m.name] % 2 == 0)),
                    "truth": metrics.log_rmse(rec.table, m.truth),
                    "expected": rec.expected_log_rmse,
                    "cv_log_error": rec.cv_log_error, "cv_sample_error": rec.cv_sample_error,
                    "nr": len(cells) * r, "predicted": rec.predicted_log_rmse,
                })
        print(f"  {m.name} done", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=Path, default=None,
                    help="JSON file of the scans: read it if it exists, else write it")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    if args.rows is not None and args.rows.is_file():
        rows = json.loads(args.rows.read_text())
    else:
        rows = scans()
        if args.rows is not None:
            args.rows.write_text(json.dumps(rows))
    if "predicted" not in rows[0] or args.rows is not None:
        from gonio.brdf.reconstruction.selfcheck import predict_log_rmse

        for r in rows:  # the module's current model (the file may predate it)
            r["predicted"] = predict_log_rmse(float(r["expected"]), float(r["cv_sample_error"]))
    kind = np.array([r["kind"] for r in rows])
    cal = np.array([bool(r["cal"]) for r in rows])
    y = np.log([float(r["truth"]) for r in rows])
    F = {f: np.log(np.maximum([float(r[f]) for r in rows], 1e-9)) for f in FEATURES}
    val = ~cal
    print(f"{cal.sum()} calibration scans, {val.sum()} validation scans")
    print("| features | a, b... | cal rms | within x2 cal | val | val measured | val aniso |")
    print("|---|---|---|---|---|---|---|")
    const = float(np.median(y[cal]))  # the constant guess: the calibration median
    ok = np.abs(const - y) <= np.log(2)
    print(f"| constant {np.exp(const):.4f} | | {np.sqrt(np.mean((const - y[cal]) ** 2)):.3f} | "
          f"{ok[cal].mean():.0%} | {ok[val].mean():.0%} | "
          f"{ok[val & (kind == 'measured')].mean():.0%} | "
          f"{ok[val & (kind == 'aniso')].mean():.0%} |")
    for feats in CANDIDATES:
        X = np.column_stack([np.ones_like(y)] + [F[f] for f in feats])
        c = np.linalg.lstsq(X[cal], y[cal], rcond=None)[0]
        res = X @ c - y
        ok = np.abs(res) <= np.log(2)
        print(f"| {' + '.join(feats)} | {', '.join(f'{v:.3f}' for v in c)} | "
              f"{np.sqrt(np.mean(res[cal] ** 2)):.3f} | {ok[cal].mean():.0%} | "
              f"{ok[val].mean():.0%} | {ok[val & (kind == 'measured')].mean():.0%} | "
              f"{ok[val & (kind == 'aniso')].mean():.0%} |")
    pred = np.log([float(r["predicted"]) for r in rows])
    ok = np.abs(pred - y) <= np.log(2)
    print(f"| chosen: module {LOG_RMSE_FEATURES} {LOG_RMSE_MODEL} | | | {ok[cal].mean():.0%} | "
          f"{ok[val].mean():.0%} | {ok[val & (kind == 'measured')].mean():.0%} | "
          f"{ok[val & (kind == 'aniso')].mean():.0%} |")
    default = np.array([r["geom"] == "designed n=10" and r["r"] == 8 for r in rows])
    for label, sel in (("default scan (designed n=10, r=8), unseen materials",
                        default & (kind != "panel")),
                       ("default scan, validation materials only", default & val)):
        okc = np.abs(const - y[sel]) <= np.log(2)
        print(f"{label}: module within x2 on {int(ok[sel].sum())} of {int(sel.sum())}; "
              f"constant {int(okc.sum())} of {int(sel.sum())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
