"""Benchmark: sampling design (search time, fast update speed, reconstruction quality).

Run from the project root::

    .venv/bin/python bench/bench_design.py [--sections search speed quality] [--per-family 1]

Sections
--------
search
    ``design_pairs`` on the default basis (K = 64) with the paper's settings (h = 7, 10 starts x
    10 descents) and the default rig limits (10 deg between devices) for n = 5, 10, 20: wall
    and CPU time, condition number, closest two devices.
speed
    One neighbourhood evaluation (h = 7, all feasible cells around a dropped row) for
    n = 5, 20, 50 random rows of the default basis: the secular update
    (:func:`condition_numbers_fast`, no screening) against a batched SVD
    (:func:`condition_numbers_svd`, one LAPACK call for all candidates) and a per-candidate
    SVD loop (the straightforward "standard approach"). Median of 30 repeats.
quality
    Leave-subset-out: the first ``--per-family`` materials of every library family are held
    out, the basis (K = 64) is trained on the rest. Geometries: optimized n = 5 and 10, the
    four presets, random placements (n = 5 and 10, median of 5 draws), a 3 x 4 product rig and
    12 independent optimized pairs. r = 8 uniform stage angles, 1 % noise, closed-form
    reconstruction. Reports mean log_rmse and log_psnr over the held-out materials.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict

import numpy as np

from gonio.brdf.design.conditioning import condition_numbers_fast, condition_numbers_svd
from gonio.brdf.design.constraints import RigConstraints, candidate_rows, rows_to_cells
from gonio.brdf.design.pairs import PairDesign, design_pairs, geometry_design
from gonio.brdf.design.placement import place_pairs
from gonio.brdf.design.presets import get_preset, preset_names
from gonio.brdf.design.product import design_product_rig
from gonio.brdf.design.search import neighbourhood
from gonio.brdf.reconstruction.basis import Basis, build_basis, default_basis

# gonio's default rig limits: elevation up to 80 deg, light-sensor separation 10 deg and
# 10 deg between any two mounted devices (the search is collision-aware, so every design
# below can be mounted).
BENCH_CONSTRAINTS = RigConstraints()


def section_search() -> None:
    basis = default_basis()
    print("\n## search: design_pairs, default basis K=64, h=7, 10 starts x 10 descents, "
          "max elevation 80, separation 10, device distance 10 (defaults)")
    print(f"{'n':>3} {'kappa':>10} {'seconds':>8} {'cpu s':>6} {'neighbourhoods':>14} "
          f"{'closest deg':>11}")
    for n in (5, 10, 20):
        t0, c0 = time.perf_counter(), time.process_time()
        d = design_pairs(basis, n, BENCH_CONSTRAINTS, seed=1)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        assert d.search is not None
        print(f"{n:>3} {d.kappa:>10.3f} {dt:>8.1f} {dc:>6.1f} {d.search.neighbourhoods:>14} "
              f"{d.min_distance_deg:>11.1f}", flush=True)


def _median_time(fn, repeats: int = 30) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def section_speed() -> None:
    basis = default_basis()
    cand = candidate_rows(RigConstraints(), basis.valid)
    is_cand = np.zeros(basis.Q.shape[0], dtype=bool)
    is_cand[cand] = True
    rng = np.random.default_rng(0)
    print("\n## speed: one h=7 neighbourhood, median of 30 (ms)")
    print(f"{'n':>3} {'m':>3} {'cands':>5} {'secular':>8} {'svd batch':>9} {'svd loop':>9} "
          f"{'x batch':>7} {'x loop':>7} {'max rel diff':>12}")
    for n in (5, 20, 50):
        rows = rng.choice(cand, n, replace=False)
        m = min(n, basis.K)
        kept = basis.Q[rows[1:], :m]
        near = neighbourhood(int(rows[0]), 7)
        near = near[is_cand[near] & ~np.isin(near, rows[1:])]
        q = basis.Q[near, :m]
        t_fast = _median_time(lambda: condition_numbers_fast(kept, q))  # noqa: B023
        t_batch = _median_time(lambda: condition_numbers_svd(kept, q))  # noqa: B023
        t_loop = _median_time(
            lambda: [np.linalg.svd(np.vstack([kept, r]), compute_uv=False) for r in q],  # noqa: B023
            repeats=10,
        )
        a, b = condition_numbers_fast(kept, q), condition_numbers_svd(kept, q)
        ok = np.isfinite(b)
        diff = float(np.max(np.abs(a[ok] - b[ok]) / b[ok])) if ok.any() else float("nan")
        print(f"{n:>3} {m:>3} {near.size:>5} {t_fast * 1e3:>8.2f} {t_batch * 1e3:>9.2f} "
              f"{t_loop * 1e3:>9.2f} {t_batch / t_fast:>7.1f} {t_loop / t_fast:>7.1f} "
              f"{diff:>12.1e}", flush=True)


def _random_design(basis: Basis, n: int, seed: int) -> PairDesign:
    c = BENCH_CONSTRAINTS
    rows = np.random.default_rng(seed).choice(candidate_rows(c, basis.valid), n, replace=False)
    p = place_pairs(rows_to_cells(rows), c, seed=seed)
    lab = np.deg2rad(p.lab_deg)
    from gonio.brdf.tables import geometry as geo

    wi = geo.spherical_to_direction(lab[:, 0], lab[:, 1])
    wo = geo.spherical_to_direction(lab[:, 2], lab[:, 3])
    return geometry_design(basis, f"random n={n}", wi, wo, np.stack([np.arange(n)] * 2, 1))


def section_quality(per_family: int) -> None:
    from gonio.brdf.materials.library import default_library, library_specs
    from gonio.brdf.reconstruction.reconstruct import reconstruct
    from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
    from gonio.brdf.tables import metrics

    specs = library_specs()
    counts: dict[str, int] = defaultdict(int)
    test_idx = []
    for k, s in enumerate(specs):
        if counts[s.family] < per_family:
            counts[s.family] += 1
            test_idx.append(k)
    tables = default_library()
    tests = [tables[k] for k in test_idx]
    train = [t for k, t in enumerate(tables) if k not in set(test_idx)]
    del tables
    t0 = time.perf_counter()
    basis = build_basis(train, 64)
    del train
    print(f"\n## quality: r=8, 1% noise, basis K=64 from the other materials "
          f"({time.perf_counter() - t0:.0f} s to build)")
    print("held out: " + ", ".join(t.name for t in tests))
    c = BENCH_CONSTRAINTS
    designs: list[PairDesign] = [
        design_pairs(basis, 5, c, seed=1),
        design_pairs(basis, 10, c, seed=1),
        design_pairs(basis, 12, c, seed=1),
        design_product_rig(basis, 3, 4, c, seed=1),
    ]
    for name in preset_names():
        p = get_preset(name)
        wi, wo = p.directions()
        pairs = np.stack([np.arange(p.n_pairs)] * 2, 1)
        designs.append(geometry_design(basis, name, wi, wo, pairs))
    randoms = {n: [_random_design(basis, n, s) for s in range(5)] for n in (5, 10)}
    alpha = uniform_stage_angles(8)

    def score(d: PairDesign) -> tuple[float, float]:
        rm, ps = [], []
        for t in tests:
            vals = simulate_samples(t, d.cells, d.ph_lab, alpha, noise=NoiseModel(0.01, 0.0, 0))
            rec = reconstruct(basis, d.cells, d.ph_lab, alpha, vals, channels=t.channels)
            rm.append(metrics.log_rmse(rec.table, t))
            ps.append(metrics.log_psnr(rec.table, t))
        return float(np.mean(rm)), float(np.mean(ps))

    print(f"{'geometry':<22} {'n':>3} {'kappa':>10} {'log_rmse':>9} {'log_psnr':>9}")
    for d in designs:
        label = f"optimized n={d.n_pairs}" if d.name == "optimized" else d.name
        if d.name == "product":
            label = "product 3x4"
        rm, ps = score(d)
        print(f"{label:<22} {d.n_pairs:>3} {d.kappa:>10.3g} {rm:>9.4f} {ps:>9.2f}", flush=True)
    for n, ds in randoms.items():
        scores = [score(d) for d in ds]
        kap = float(np.median([d.kappa for d in ds]))
        rm = float(np.median([s[0] for s in scores]))
        ps = float(np.median([s[1] for s in scores]))
        print(f"{f'random n={n} (median 5)':<22} {n:>3} {kap:>10.3g} {rm:>9.4f} {ps:>9.2f}",
              flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sections", nargs="+", default=["search", "speed", "quality"],
                    choices=["search", "speed", "quality"])
    ap.add_argument("--per-family", type=int, default=1)
    args = ap.parse_args(argv)
    print("command: " + " ".join([".venv/bin/python", "bench/bench_design.py", *sys.argv[1:]]))
    if "speed" in args.sections:
        section_speed()
    if "search" in args.sections:
        section_search()
    if "quality" in args.sections:
        section_quality(args.per_family)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
