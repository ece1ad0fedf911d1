"""Benchmark: time and peak memory of building the default basis.

Run from the project root::

    .venv/bin/python bench/bench_basis.py [--components 64] [--materials 150]
    /usr/bin/time -v .venv/bin/python bench/bench_basis.py   # process peak RSS as well

Builds (or reuses from the cache) the synthetic library first and reports that separately;
the basis timing covers :func:`gonio.brdf.reconstruction.basis.build_basis` only. Peak memory is
tracked with tracemalloc (NumPy reports its buffers to it), relative to the tables already in
memory, and the process peak RSS is printed from ``resource``.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import tracemalloc

from gonio.brdf.materials.library import default_library
from gonio.brdf.reconstruction.basis import build_basis


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--components", type=int, nargs="+", default=[64])
    ap.add_argument("--materials", type=int, default=150,
                    help="use the first N library materials (default 150, as V&F)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    tables = default_library()[: args.materials]
    t_lib = time.perf_counter() - t0
    gb = sum(t.values.nbytes for t in tables) / 1e9
    print(f"$ {' '.join([sys.executable.rsplit('/', 1)[-1], *sys.argv])}")
    print(f"library: {len(tables)} materials, {gb:.2f} GB of tables, load/build {t_lib:.1f} s")
    print(f"{'K':>5} {'build s':>9} {'peak extra GB':>14}")
    for k in args.components:
        tracemalloc.start()
        t0 = time.perf_counter()
        basis = build_basis(tables, k)
        dt = time.perf_counter() - t0
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        print(f"{k:>5} {dt:>9.1f} {peak / 1e9:>14.2f}")
        del basis
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # KiB -> GB on Linux
    print(f"process peak RSS {rss:.2f} GB (tables + build)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
