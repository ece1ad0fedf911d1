"""Benchmark: how well the self-estimated error tracks the true whole-BRDF error.

Run from the project root::

    .venv/bin/python bench/bench_error_estimate.py [--per-family 4] [--no-rgl]

Protocol
--------
* Held out of the basis: the first ``--per-family`` materials of every library family (28 of
  the 175 by default). The basis (K = 64, the default) is trained on the other materials and
  cached next to the library.
* The held-out materials are split in two halves by their position within the family:
  positions 0, 2, ... form the **calibration** set, positions 1, 3, ... the **validation**
  set. The six measured RGL materials in ``../shared/data/rgl`` (needs mitsuba) are a second,
  harder validation set (real materials the synthetic basis represents poorly).
* Scans: ``n`` pairs in two layouts, the deterministic grid rule of ``gonio demo``
  (:func:`gonio.cli.brdf_commands.simple_pairs`: cells clustered at th <= 50, td <= 35 deg)
  and the pairs optimised by :func:`gonio.brdf.design.pairs.design_pairs` (spread over the
  domain); ``r`` uniform stage angles, 1 % relative noise (seed 0), closed form with
  eta = 40, lam = 0.1; every (layout, n, r) of ``--pairs`` x ``--rotations``. ``--no-design``
  keeps the grid rule only.
* Truth: the volume-weighted MAPE over the whole table (:func:`gonio.brdf.tables.metrics.mape`).
* Estimators: V&F's ``estimated_error = 0.8 x rel_sample_error`` and gonio's
  ``predicted_error = s(n) x cv_sample_error`` (leave-one-pair-out). For each n the factor
  ``s`` is fitted here as the geometric median of ``mape / cv_sample_error`` over the
  calibration set (both layouts pooled) and printed next to the module's
  :data:`gonio.brdf.reconstruction.reconstruct.CV_ERROR_SCALES`, which are set from it; the reported
  ``predicted_error`` is the module's.
* Reported for each set and estimator: the ratio ``estimate / mape`` (median, IQR, the share
  within a factor of 2 of the truth) and the Spearman rank correlation of estimate and truth,
  overall, per layout, per n and per r.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

# Run as `python bench/bench_error_estimate.py`, so the sibling script is importable.
from bench_quality import rgl_tables
from scipy.stats import spearmanr

from gonio.brdf.materials.library import cache_root, default_library, library_key, library_specs
from gonio.brdf.reconstruction.basis import DEFAULT_COMPONENTS, Basis, build_basis
from gonio.brdf.reconstruction.reconstruct import CV_ERROR_SCALES, reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable
from gonio.cli.brdf_commands import simple_pairs


@dataclass(frozen=True)
class Trial:
    """One reconstruction of one material: the true error and the raw estimators."""

    material: str
    layout: str
    n: int
    r: int
    mape: float
    vf: float  # estimated_error, 0.8 x rel_sample_error
    cv: float  # cv_sample_error, uncalibrated
    pred: float  # predicted_error, calibrated by the module's CV_ERROR_SCALES


def held_out_split(per_family: int) -> tuple[list[str], list[str]]:
    """Calibration and validation material names (alternating positions within a family)."""
    seen: dict[str, int] = defaultdict(int)
    calib: list[str] = []
    valid: list[str] = []
    for s in library_specs():
        k = seen[s.family]
        if k < per_family:
            (calib if k % 2 == 0 else valid).append(s.name)
        seen[s.family] += 1
    return calib, valid


def holdout_basis(train: list[BRDFTable], per_family: int, k: int) -> Basis:
    path = cache_root() / "basis" / f"bench-holdout{per_family}-K{k}-{library_key()[:16]}.npz"
    if path.is_file():
        return Basis.load(path)
    basis = build_basis(train, k)
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis


PairsFn = Callable[[int], tuple[np.ndarray, np.ndarray]]


def grid_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    return simple_pairs(n)


def designed(basis: Basis) -> PairsFn:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    @functools.cache
    def pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
        # Device collisions are a rig question; quality only depends on the cells.
        d = design_pairs(basis, n, RigConstraints(min_device_distance_deg=0.0), starts=3,
                         descents=4, time_limit_s=30.0)
        return np.asarray(d.cells), np.asarray(d.ph_lab)

    return pairs


def run(basis: Basis, tables: list[BRDFTable], ns: list[int], rs: list[int],
        layouts: dict[str, PairsFn]) -> list[Trial]:
    out = []
    for layout, pairs in layouts.items():
        for n in ns:
            cells, ph = pairs(n)
            for r in rs:
                alpha = uniform_stage_angles(r)
                for t in tables:
                    vals = simulate_samples(t, cells, ph, alpha, noise=NoiseModel(0.01, seed=0))
                    rec = reconstruct(basis, cells, ph, alpha, vals)
                    out.append(Trial(t.name, layout, n, r, metrics.mape(rec.table, t),
                                     rec.estimated_error, rec.cv_sample_error,
                                     rec.predicted_error))
    return out


def summary(est: np.ndarray, truth: np.ndarray) -> str:
    ratio = est / truth
    q1, med, q3 = np.percentile(ratio, [25, 50, 75])
    within2 = np.mean((ratio > 0.5) & (ratio < 2.0))
    rho = spearmanr(est, truth).statistic
    return (f"median {med:6.3f}  IQR {q1:6.3f}-{q3:6.3f}  within x2 {100 * within2:3.0f} %  "
            f"Spearman {rho:5.2f}")


def report(title: str, trials: list[Trial]) -> None:
    print(f"\n{title} ({len({t.material for t in trials})} materials, {len(trials)} scans)")
    truth = np.array([t.mape for t in trials])
    print(f"  true MAPE: median {np.median(truth):.3f}, "
          f"IQR {np.percentile(truth, 25):.3f}-{np.percentile(truth, 75):.3f}")
    groups: list[tuple[str, list[Trial]]] = [("all", trials)]
    groups += [(lay[:5], [t for t in trials if t.layout == lay])
               for lay in sorted({t.layout for t in trials})]
    groups += [(f"n={n}", [t for t in trials if t.n == n]) for n in sorted({t.n for t in trials})]
    groups += [(f"r={r}", [t for t in trials if t.r == r]) for r in sorted({t.r for t in trials})]
    for label, sel in groups:
        tr = np.array([t.mape for t in sel])
        print(f"  {label:>5} V&F  {summary(np.array([t.vf for t in sel]), tr)}")
        print(f"  {'':>5} CV   {summary(np.array([t.pred for t in sel]), tr)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=4)
    ap.add_argument("--pairs", type=int, nargs="+", default=[5, 10, 20])
    ap.add_argument("--rotations", type=int, nargs="+", default=[4, 8, 12, 24])
    ap.add_argument("--no-rgl", action="store_true")
    ap.add_argument("--no-design", action="store_true", help="grid-rule pairs only")
    args = ap.parse_args(argv)
    print(f"$ {' '.join([sys.executable.rsplit('/', 1)[-1], *sys.argv])}")
    t0 = time.perf_counter()
    calib_names, valid_names = held_out_split(args.per_family)
    tables = default_library()
    held = set(calib_names) | set(valid_names)
    basis = holdout_basis([t for t in tables if t.name not in held], args.per_family,
                          DEFAULT_COMPONENTS)
    print(f"basis K={basis.K} from {len(basis.materials)} materials")
    print(f"calibration: {', '.join(calib_names)}")
    print(f"validation:  {', '.join(valid_names)}")
    layouts: dict[str, PairsFn] = {"grid rule": grid_rule}
    if not args.no_design:
        try:
            layouts["design_pairs"] = designed(basis)
        except ImportError as exc:
            print(f"designed pairs skipped: {exc}")
    calib = run(basis, [t for t in tables if t.name in calib_names], args.pairs, args.rotations,
                layouts)
    module = dict(CV_ERROR_SCALES)
    print("\nfitted s(n) = geometric median of mape / cv_sample_error over the calibration set:")
    for n in args.pairs:
        ratios = np.array([t.mape / t.cv for t in calib if t.n == n])
        print(f"  n={n:>2}: fitted {np.exp(np.median(np.log(ratios))):.3f}, "
              f"module {module.get(n, float('nan')):.3f}")
    report("calibration set (library, held out of the basis)", calib)
    val_tables = [t for t in tables if t.name in valid_names]
    report("validation set (other library materials, held out of the basis)",
           run(basis, val_tables, args.pairs, args.rotations, layouts))
    if not args.no_rgl:
        rgl = rgl_tables()
        if rgl:
            report("validation set: RGL measured materials",
                   run(basis, rgl, args.pairs, args.rotations, layouts))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
