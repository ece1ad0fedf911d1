"""Benchmark: the self-estimate on the product's own path, the default simulated rig (issue 23
item 4).

Run from the project root (needs mitsuba: ``pip install 'gonio[rgl]'``)::

    nice -n 5 .venv/bin/python bench/bench_sim_rig_estimate.py [--set fresh|fresh-inplane]

What the issue checked: a held-out material written as a gonio ``.npz`` table and scanned with
``gonio scan --sim --material TABLE.npz --rotations 8`` on the default simulated rig (3 lights x
4 sensors, readings through the wire protocols, calibrated on the simulated white reference).
Here each of ``bench_selfestimate.py``'s fresh mitsuba specimens (:data:`FRESH`, and
:data:`FRESH_INPLANE`, written down before any scan of them) is scanned that way, in-process,
and the result's ``predicted_log_rmse`` is set beside the true ``log_rmse`` of its table
against the specimen's table (mitsuba on gonio's grid: the same table the simulated rig reads,
so the readings carry no lookup error of their own). Printed per specimen: the true error, the
estimate and its ratio, the upper end of its interval, the error above the physical peak bound
(``peak_excess_log_rmse``, under which the estimate never goes: docs/science.md 7.5),
whether the result is outside physical bounds, and the floor's premise: the truth's own peak
over the largest reading, both projected (``f cos ti cos to``, as the bound compares them; the
floor is a lower bound of the error only while that stays within ``PEAK_RATIO_LIMIT``) and the
floor a perfect table, the truth itself, would get; then the
share within x2, the scans more than 2x too low, those above the upper end and the specimens
that break the premise. Results: docs/science.md 7.5. About 8 s a specimen.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

import bench_selfestimate as bs  # sibling bench (the script's folder is on sys.path)
import numpy as np

from gonio.brdf.tables import metrics
from gonio.brdf.tables.bounds import PEAK_RATIO_LIMIT, bounds_check, peak_excess_log_rmse
from gonio.cli import main as gonio_main
from gonio.results import read_result

SETS = {"fresh": bs.FRESH, "fresh-inplane": bs.FRESH_INPLANE}


def scan_one(m: object, table_path: Path, work: Path) -> tuple[Path, int, str]:
    """``gonio scan --sim`` of one table at 8 rotations; returns the result, exit code and
    printout."""
    out = work / f"{table_path.stem}.h5"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        code = gonio_main(["scan", "--sim", "--material", str(table_path), "--rotations", "8",
                           "--no-progress", "--no-export-fits", "--specimen", table_path.stem,
                           "--data-dir", str(work / "data"), "-o", str(out)])
    return out, code, buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--set", choices=sorted(SETS), nargs="*", default=sorted(SETS),
                    help="which fresh sets (default: both)")
    args = ap.parse_args(argv)
    print(f"$ {' '.join(['python', *sys.argv])}")
    t0 = time.perf_counter()
    for name in args.set:
        print(f"\n#### {name}\n")
        print("| specimen | true log_rmse | predicted | ratio | upper | above the peak bound | "
              "outside physical bounds | truth's peak / largest reading | the floor of the "
              "truth itself |")
        print("|---|---|---|---|---|---|---|---|---|")
        ratios, above, premise_broken = [], 0, 0
        with tempfile.TemporaryDirectory(prefix="gonio-sim-rig-") as tmp:
            work = Path(tmp)
            for m, _kind in bs.fresh_materials(SETS[name], name):
                path = work / f"{m.name}.npz"
                m.truth.save(path)
                out, code, text = scan_one(m, path, work)
                if code != 0:
                    raise SystemExit(f"gonio scan failed on {m.name} (exit {code}):\n{text}")
                res = read_result(out)
                true = metrics.log_rmse(res.table, m.truth)
                met = res.metrics
                p, up = float(met["predicted_log_rmse"]), float(met["predicted_log_rmse_upper"])
                q = p / true
                ratios.append(q)
                above += int(true > up)
                # The floor's premise: the truth within PEAK_RATIO_LIMIT x the largest reading,
                # both projected (f cos ti cos to), as the bound compares them.
                grid = res.samples.to_samples()
                readings = np.asarray(grid.values, dtype=float)
                truth_ratio = bounds_check(m.truth, readings, cells=grid.cells,
                                           calibrated=False).peak_ratio
                truth_floor = peak_excess_log_rmse(m.truth, readings, grid.cells)
                premise_broken += int(truth_ratio > PEAK_RATIO_LIMIT)
                print(f"| {m.name} | {true:.4f} | {p:.4f} | x{q:.2f} | {up:.4f} | "
                      f"{float(met.get('peak_excess_log_rmse') or 0.0):.4f} | "
                      f"{'yes' if met.get('physical_bounds') else ''} | {truth_ratio:.3g} | "
                      f"{truth_floor:.4f} |", flush=True)
        r = np.asarray(ratios)
        print(f"\n{name}: within x2 {int(np.sum((r >= 0.5) & (r <= 2)))} of {r.size}, more than "
              f"2x low {int(np.sum(r < 0.5))}, true above the upper end {above}; the truth "
              f"itself above the peak bound on {premise_broken} (the floor's premise broken)")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
