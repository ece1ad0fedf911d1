"""Benchmark: reconstruction quality against n (pairs) x r (rotations) x K (components).

Run from the project root::

    .venv/bin/python bench/bench_quality.py [--per-family 2] [--components 16 32 64 128]

Protocol
--------
* Test materials: the first ``--per-family`` materials of every library family (14 of the 175
  by default). The basis is trained on the *other* library materials, so every test material
  is held out (a leave-subset-out protocol: stricter than leave-one-out, and it needs a single
  basis build instead of one per material).
* The six measured RGL materials in ``../shared/data/rgl`` (read with
  :func:`gonio.brdf.materials.rgl.read_rgl`, needs mitsuba) are evaluated with the same basis;
  skipped when the data or mitsuba are absent.
* Pairs: ``n`` pairs from :func:`gonio.brdf.design.pairs.design_pairs` on the training basis when
  the design module is available (one design per n, shared by all materials), else the demo's
  deterministic grid rule. Rotations: ``r`` uniform stage angles. Noise: 1 % relative, seed 0.
* Reconstruction: closed form, eta = 40, lam = 0.1, the basis truncated to each K.
* Reported: mean log_rmse (lower is better) and mean log_psnr in dB (higher is better) over the
  test materials, and the ratios estimated_error / mape (V&F's self-estimate) and
  predicted_error / mape (gonio's leave-one-pair-out estimate; the calibration study is
  ``bench/bench_error_estimate.py``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from gonio.brdf.materials.library import cache_root, default_library, library_key, library_specs
from gonio.brdf.reconstruction.basis import Basis, build_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable
from gonio.cli.brdf_commands import simple_pairs

#: Per (n, r, K): one (log_rmse, log_psnr, V&F ratio, CV ratio) tuple per test material.
Results = dict[tuple[int, int, int], list[tuple[float, float, float, float]]]

RGL_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "rgl"


def pairs_for(basis: Basis, n: int) -> tuple[np.ndarray, np.ndarray, str]:
    try:
        from gonio.brdf.design.constraints import RigConstraints
        from gonio.brdf.design.pairs import design_pairs

        # Quality depends on the cells only; device collisions are a rig question, so the
        # mounting distance is not constrained here.
        rig = RigConstraints(min_device_distance_deg=0.0)
        d = design_pairs(basis, n, rig, starts=3, descents=4, time_limit_s=30.0)
    except (ImportError, ValueError) as exc:
        cells, ph = simple_pairs(n)
        return cells, ph, f"grid rule (design module unavailable: {exc})"
    return np.asarray(d.cells), np.asarray(d.ph_lab), f"optimized, kappa {d.kappa:.3g}"


def rgl_tables() -> list[BRDFTable]:
    if not RGL_DIR.is_dir():
        print(f"RGL data not found at {RGL_DIR}: skipped")
        return []
    try:
        from gonio.brdf.materials.rgl import read_rgl

        return [read_rgl(p) for p in sorted(RGL_DIR.glob("*.bsdf"))]
    except Exception as exc:  # missing mitsuba or a reader problem: report and go on
        print(f"RGL materials skipped: {exc}")
        return []


def evaluate(
    basis: Basis, tests: list[BRDFTable], ns: list[int], rs: list[int], ks: list[int]
) -> Results:
    designs = {n: pairs_for(basis, n) for n in ns}
    for n, (_, _, how) in designs.items():
        print(f"pairs n={n}: {how}")
    out: Results = defaultdict(list)
    for t in tests:
        for n in ns:
            cells, ph, _ = designs[n]
            for r in rs:
                alpha = uniform_stage_angles(r)
                vals = simulate_samples(t, cells, ph, alpha, noise=NoiseModel(0.01, seed=0))
                for k in ks:
                    rec = reconstruct(basis, cells, ph, alpha, vals, n_components=k)
                    true = max(metrics.mape(rec.table, t), 1e-12)
                    out[(n, r, k)].append(
                        (metrics.log_rmse(rec.table, t), metrics.log_psnr(rec.table, t),
                         rec.estimated_error / true, rec.predicted_error / true)
                    )
    return out


def print_table(title: str, res: Results,
                ns: list[int], rs: list[int], ks: list[int]) -> None:
    print(f"\n{title}")
    head = " ".join(f"{'K=' + str(k):>15}" for k in ks)
    print(f"{'n':>3} {'r':>3} {'n*r':>5} {head}   (log_rmse / log_psnr dB)")
    for n in ns:
        for r in rs:
            cells = []
            for k in ks:
                a = np.array(res[(n, r, k)])
                cells.append(f"{a[:, 0].mean():7.4f}/{a[:, 1].mean():5.1f}")
            print(f"{n:>3} {r:>3} {n * r:>5} {' '.join(f'{c:>15}' for c in cells)}")
    for i, label in ((2, "estimated_error (V&F)"), (3, "predicted_error (CV)")):
        ratios = np.array([v[i] for vals in res.values() for v in vals])
        print(f"{label} / MAPE: median {np.median(ratios):.2f}, "
              f"IQR {np.percentile(ratios, 25):.2f}-{np.percentile(ratios, 75):.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=2)
    ap.add_argument("--components", type=int, nargs="+", default=[16, 32, 64, 128])
    ap.add_argument("--pairs", type=int, nargs="+", default=[5, 10, 20])
    ap.add_argument("--rotations", type=int, nargs="+", default=[4, 8, 12, 24])
    ap.add_argument("--no-rgl", action="store_true")
    args = ap.parse_args(argv)
    print(f"$ {' '.join([sys.executable.rsplit('/', 1)[-1], *sys.argv])}")
    t0 = time.perf_counter()
    per_family: dict[str, int] = defaultdict(int)
    test_names = []
    for s in library_specs():
        if per_family[s.family] < args.per_family:
            per_family[s.family] += 1
            test_names.append(s.name)
    tables = default_library()
    tests = [t for t in tables if t.name in test_names]
    train = [t for t in tables if t.name not in test_names]
    # The training basis depends only on the library and K: keep it next to the library.
    path = cache_root() / "basis" / (
        f"bench-holdout{args.per_family}-K{max(args.components)}-{library_key()[:16]}.npz"
    )
    if path.is_file():
        basis = Basis.load(path)
    else:
        basis = build_basis(train, max(args.components))
        path.parent.mkdir(parents=True, exist_ok=True)
        basis.save(path)
    print(f"basis: K={basis.K} from {len(train)} materials; held out: {', '.join(test_names)}")
    ks = sorted(args.components)
    res = evaluate(basis, tests, args.pairs, args.rotations, ks)
    print_table(f"library materials held out of the basis ({len(tests)})", res, args.pairs,
                args.rotations, ks)
    if not args.no_rgl:
        rgl = rgl_tables()
        if rgl:
            res = evaluate(basis, rgl, args.pairs, args.rotations, ks)
            print_table(f"RGL measured materials ({len(rgl)}): "
                        + ", ".join(t.name for t in rgl), res, args.pairs, args.rotations, ks)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
