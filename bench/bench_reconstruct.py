"""Benchmark: reconstruction time, closed form vs the iterative (L-BFGS) reference.

Run from the project root::

    .venv/bin/python bench/bench_reconstruct.py [--components 64] [--repeats 5]

Uses the cached default basis (built on first use) and a library material as the specimen,
with the demo's deterministic grid pairs. For each (n, r) it reports the median wall time of

* ``solve``: step 3 alone (the two K x K solves, or the L-BFGS search), all channels, with
  BLAS on one thread as inside :func:`~gonio.brdf.reconstruction.reconstruct.reconstruct`;
* ``total``: the whole :func:`gonio.brdf.reconstruction.reconstruct.reconstruct` call (resampling,
  remap, solve, the full 3 x 72 x 11,664 table, the sample error and the leave-one-pair-out
  estimate);

and the agreement of the two solvers (max coefficient difference relative to the largest
coefficient, and the relative difference of the Eq. 5 objective).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from functools import partial

import numpy as np

from gonio.brdf.materials.library import get_material
from gonio.brdf.reconstruction.basis import default_basis, remap
from gonio.brdf.reconstruction.reconstruct import (
    JOINT_ETA,
    JOINT_LAM,
    _objective,
    joint_prior,
    one_blas_thread,
    reconstruct,
    resample_to_slices,
    solve_closed,
    solve_iterative,
    solve_joint,
)
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.tables import geometry as geo
from gonio.cli.brdf_commands import simple_pairs


def median_time(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def solve_channels(solve: Callable[..., object], Y: list[np.ndarray], Qt: np.ndarray,
                   Qs: np.ndarray) -> list[object]:
    with one_blas_thread():
        return [solve(y, Qt, Qs, 40.0, 0.1) for y in Y]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--components", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--material", default="brushed-metal-003")
    args = ap.parse_args(argv)
    print(f"$ {' '.join([sys.executable.rsplit('/', 1)[-1], *sys.argv])}")
    basis = default_basis(args.components)
    model = get_material(args.material)
    print(f"basis K={basis.K}, specimen {args.material}, median of {args.repeats} runs")
    print(f"{'n':>3} {'r':>3} {'solver':>9} {'solve s':>9} {'total s':>9} "
          f"{'coef diff':>10} {'obj diff':>10}")
    for n, r in ((20, 12), (20, 72), (10, 8)):
        cells, ph = simple_pairs(n)
        alpha = uniform_stage_angles(r)
        vals = simulate_samples(model, cells, ph, alpha, noise=NoiseModel(0.01))
        th, td, pd = cells.T
        Qt = basis.rows_at(th, td, pd)
        fm, mu = basis.blend(basis.f_med, th, td, pd), basis.blend(basis.mu, th, td, pd)
        ci, co = geo.cell_cosines(th, td, pd)
        w = np.maximum(ci * co, basis.eps)
        Y = remap(resample_to_slices(ph, alpha, vals), fm[:, None, None], w[:, None, None])
        Y = Y - mu[:, None, None]
        rows_s = geo.flat_row(np.zeros(648, int), *np.divmod(np.arange(648), 36))
        Qs = basis.Q[rows_s]
        C = [Y[:, :, c] for c in range(3)]
        closed = [solve_closed(y, Qt, Qs, 40.0, 0.1) for y in C]
        iterative = [solve_iterative(y, Qt, Qs, 40.0, 0.1) for y in C]
        diff = max(np.abs(a - b).max() / np.abs(a).max() for a, b in zip(closed, iterative,
                                                                            strict=True))
        obj = max(abs(_objective(b, y, Qt, Qs, 40, 0.1) / _objective(a, y, Qt, Qs, 40, 0.1) - 1)
                  for a, b, y in zip(closed, iterative, C, strict=True))
        for solver in ("closed", "iterative"):
            one = solve_closed if solver == "closed" else solve_iterative
            # The L-BFGS reference takes seconds per run: time it once.
            reps = args.repeats if solver == "closed" else 1
            t_solve = median_time(partial(solve_channels, one, C, Qt, Qs), reps)
            t_total = median_time(
                partial(reconstruct, basis, cells, ph, alpha, vals, solver=solver,
                        method="vf"), reps
            )
            print(f"{n:>3} {r:>3} {'vf-' + solver:>9} {t_solve:>9.4f} {t_total:>9.4f} "
                  f"{diff:>10.2e} {obj:>10.2e}")
        # The default joint fit: one (n r) x (n r) solve for all channels.
        Yr = remap(vals, fm[:, None, None], w[:, None, None]) - mu[:, None, None]
        P = joint_prior(basis, JOINT_LAM / JOINT_ETA)
        phr = ph[:, None] - alpha[None, :]

        def joint_solve(Yr: np.ndarray = Yr, Qt: np.ndarray = Qt, phr: np.ndarray = phr,
                        P: np.ndarray = P) -> object:
            with one_blas_thread():
                return solve_joint(Yr, Qt, phr, P, JOINT_ETA)

        t_solve = median_time(joint_solve, args.repeats)
        t_total = median_time(partial(reconstruct, basis, cells, ph, alpha, vals), args.repeats)
        print(f"{n:>3} {r:>3} {'joint':>9} {t_solve:>9.4f} {t_total:>9.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
