"""Benchmark: does storing the shipped synthetic basis in float32 change reconstructions?

Builds the synthetic basis (K = 96) in float64 from the tabulated library (the library is
tabulated into ``GONIO_CACHE_DIR`` first when it is not there, about two minutes), folds the
shipped measured materials in as ``default_basis()`` does, and compares it with the default
basis derived from the shipped float32 file: the largest relative difference of ``Q``, and for
each material (the 11 measured ones, four library ones) a simulated scan with 1 % noise at the
MA98 preset's pairs over 8 stage angles reconstructed with both bases: the two log_rmse
values and the largest relative difference of the reconstructed tables.

    nice -n 5 .venv/bin/python bench/bench_shipped_precision.py
"""

from __future__ import annotations

import numpy as np

from gonio.brdf.design.presets import get_preset
from gonio.brdf.materials import library, measured
from gonio.brdf.models import analytic
from gonio.brdf.reconstruction import basis as basis_mod
from gonio.brdf.reconstruction import shipped
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import simulate_samples
from gonio.brdf.tables.metrics import log_rmse

LIBRARY_MATERIALS = ("brushed-metal-004", "metal-003", "fabric-010", "paint-007")


def main() -> int:
    syn64 = basis_mod.build_basis(library.default_library(), shipped.SHIPPED_COMPONENTS)
    syn32 = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    if syn32 is None:
        raise SystemExit(f"the shipped basis is stale; run `{shipped.REBUILD_COMMAND}` first")
    k = basis_mod.DEFAULT_COMPONENTS
    extra = measured.measured_tables()
    b64 = basis_mod.fold_in(syn64, extra, basis_mod.MEASURED_WEIGHT, k)
    b32 = basis_mod.fold_in(syn32, extra, basis_mod.MEASURED_WEIGHT, k)
    print(f"default basis Q: largest relative difference "
          f"{np.abs(b32.Q - b64.Q).max() / np.abs(b64.Q).max():.1e}")
    cells, ph = get_preset("MA98").cells()
    angles = np.deg2rad(np.arange(8) * 22.5)
    mats: list[tuple[str, object, object]] = [(t.name, t, t) for t in extra]
    for name in LIBRARY_MATERIALS:
        model = library.get_material(name)
        mats.append((name, model, analytic.tabulate(model)))
    print(f"{'material':28s} {'log_rmse f64':>12s} {'log_rmse f32':>12s} {'difference':>10s} "
          f"{'table rel diff':>14s}")
    e64s, e32s = [], []
    for name, specimen, truth in mats:
        vals = simulate_samples(specimen, cells, ph, angles)  # type: ignore[arg-type]
        r64 = reconstruct(b64, cells, ph, angles, vals).table
        r32 = reconstruct(b32, cells, ph, angles, vals).table
        e64, e32 = log_rmse(r64, truth), log_rmse(r32, truth)  # type: ignore[arg-type]
        rel = np.nanmax(np.abs(r64.values - r32.values)) / np.nanmax(np.abs(r64.values))
        e64s.append(e64)
        e32s.append(e32)
        print(f"{name:28s} {e64:12.6f} {e32:12.6f} {e32 - e64:+10.1e} {rel:14.1e}", flush=True)
    print(f"{'mean':28s} {np.mean(e64s):12.6f} {np.mean(e32s):12.6f} "
          f"{np.mean(e32s) - np.mean(e64s):+10.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
