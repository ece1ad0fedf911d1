"""Calibrate and validate ``predicted_log_rmse`` on materials held out of the basis.

Run from the project root (needs mitsuba and ``../shared/data/rgl``; about 5 min)::

    nice -n 5 .venv/bin/python bench/calibrate_log_rmse.py

Materials and readings are those of ``bench/bench_unseen.py`` (measured materials each with
a basis that leaves it out, mitsuba anisotropic specimens; 1 % noise). Scans: pairs designed
on the synthetic basis for n = 5, 10, 20, plus the MA68 and MA98 presets, each at r = 4, 8, 16
uniform stage angles. Materials at even positions (within each kind) calibrate, odd ones
validate. For each candidate model ``ln(log_rmse) = a + b ln(feature) [+ c ln(n r)]`` the script
prints its coefficients and the share of scans whose truth lies within x2 of the estimate; the
module's :data:`gonio.brdf.reconstruction.reconstruct.LOG_RMSE_MODEL` is the candidate with the
lowest calibration-half residual.
"""

from __future__ import annotations

# Run as `python bench/calibrate_log_rmse.py`, so the sibling script is importable.
import bench_unseen as bu
import numpy as np

from gonio.brdf.design.presets import get_preset
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.reconstruct import LOG_RMSE_MODEL, reconstruct
from gonio.brdf.reconstruction.samples import uniform_stage_angles
from gonio.brdf.tables import metrics


def main() -> int:
    mats = bu.measured_materials() + bu.aniso_materials()
    syn = default_basis(measured_weight=0.0)
    geoms = {f"designed n={n}": bu.design(syn, n) for n in (5, 10, 20)}
    geoms.update({p: get_preset(p).cells() for p in ("MA98", "MA68")})
    pos: dict[str, int] = {}
    for kind in ("measured", "aniso"):
        pos.update({m.name: i for i, m in enumerate(m for m in mats if m.kind == kind)})
    rows = []
    for i, m in enumerate(mats):
        b = default_basis(exclude=m.exclude)
        for cells, ph in geoms.values():
            for r in (4, 8, 16):
                alpha = uniform_stage_angles(r)
                vals = bu.read(m, cells, ph, alpha, 100 + i)
                rec = reconstruct(b, cells, ph, alpha, vals)
                rows.append((m.kind, pos[m.name] % 2, metrics.log_rmse(rec.table, m.truth),
                             rec.cv_log_error, rec.cv_sample_error, len(cells) * r))
    kind = np.array([r[0] for r in rows])
    cal = np.array([r[1] == 0 for r in rows])
    y = np.log([r[2] for r in rows])
    feats = {"cv_log_error": np.log([r[3] for r in rows]),
             "cv_sample_error": np.log([r[4] for r in rows])}
    nr = np.log([r[5] for r in rows])
    print(f"{cal.sum()} calibration scans, {(~cal).sum()} validation scans")
    print("| feature | with n r | a, b, c | calibration rms | within x2 cal | val | val measured "
          "| val aniso |")
    print("|---|---|---|---|---|---|---|---|")
    for name, f in feats.items():
        for use_nr in (False, True):
            X = np.column_stack([np.ones_like(f), f] + ([nr] if use_nr else []))
            c = np.linalg.lstsq(X[cal], y[cal], rcond=None)[0]
            res = X @ c - y
            ok = np.abs(res) <= np.log(2)
            print(f"| {name} | {use_nr} | {', '.join(f'{v:.3f}' for v in c)} | "
                  f"{np.sqrt(np.mean(res[cal] ** 2)):.3f} | {ok[cal].mean():.0%} | "
                  f"{ok[~cal].mean():.0%} | {ok[~cal & (kind == 'measured')].mean():.0%} | "
                  f"{ok[~cal & (kind == 'aniso')].mean():.0%} |")
    const = np.median(y[cal])
    print(f"constant {np.exp(const):.4f}: within x2 on "
          f"{(np.abs(const - y) <= np.log(2))[~cal].mean():.0%} of the validation scans")
    print(f"module LOG_RMSE_MODEL = {LOG_RMSE_MODEL}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
