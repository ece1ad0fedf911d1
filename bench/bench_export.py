"""Benchmark: the factored fit (paper 000) and the principled fit beside 000's Table 1.

Run from the project root::

    nice -n 5 .venv/bin/python bench/bench_export.py [--no-rgl] [--analytic 6]

Protocol
--------
* Materials: the measured RGL materials in ``../shared/data/rgl`` (tabulated with
  :func:`gonio.brdf.materials.rgl.read_rgl`, mitsuba ``scalar_rgb``; skipped when the data or
  mitsuba are absent) and ``--analytic`` anisotropic library materials (brushed metals, metals,
  fabrics), all on gonio's 5 degree grid.
* Each table is fitted as the daemon fits a reconstruction (:func:`gonio.export.fit_all`:
  factored, 10 rounds; principled). Reported: relMSE, MAPE (%), PSNR (dB) and log_rmse of
  each fitted model's table against the input table, volume-weighted over the valid cells
  (:func:`gonio.brdf.models.factored.fit_metrics`), and the fit times. The measured RGL data are
  unreliable near grazing (see :mod:`gonio.brdf.materials.rgl`), so the metrics are also given over
  the   cells where both light and view are within 80 degrees of the normal and the value is not a
  clamped negative.
* 000's Table 1 is printed beside for scale. It is not like for like: 000 fits other RGL
  materials (brushed_aluminium_1, ...), per wavelength, and measures relMSE / MAPE / PSNR on
  rendered images; gonio measures them on the BRDF table (RGB), where grazing cells of the
  measured data weigh as much as any other.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.models.factored import fit_metrics
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable
from gonio.export import fit_all, provenance, write_export

#: 000 Table 1: average relMSE, MAPE (%), PSNR (dB) over wavelengths, on renderings.
PAPER_TABLE1: list[tuple[str, float, float, float]] = [
    ("brushed_aluminium_1", 0.257639, 23.5623, 44.3065),
    ("copper_sheet", 0.128014, 26.9692, 40.3821),
    ("green_pvc", 0.061847, 22.5857, 43.4143),
    ("metallic_paper_copper", 0.037910, 21.0128, 44.1411),
    ("metallic_paper_gold", 0.044599, 24.1465, 43.5306),
    ("miro_7", 0.033316, 25.6066, 43.5056),
    ("morpho_melenaus", 0.207516, 19.7027, 30.2176),
    ("sari_silk_2color", 0.021250, 1308.11, 39.4889),
    ("darth_vader_pants", 0.52347, 10.9871, 42.2086),
    ("tarkin_tunic", 1.29527, 7.38509, 28.5561),
    ("brushed_steel_satin_pink", 0.106422, 15.963, 35.4093),
]
ANALYTIC = ["brushed-metal-003", "brushed-metal-004", "metal-001", "metal-007",
            "fabric-002", "fabric-005", "brushed-metal-012", "paint-001"]


def paper_table() -> None:
    print("000 Table 1 (their materials, on renderings, per wavelength)")
    print(f"{'material':28s} {'relMSE':>8s} {'MAPE %':>8s} {'PSNR dB':>8s}")
    for name, r, m, p in PAPER_TABLE1:
        print(f"{name:28s} {r:8.4f} {m:8.2f} {p:8.2f}")
    rel = [r for _, r, _, _ in PAPER_TABLE1]
    psnr = [p for _, _, _, p in PAPER_TABLE1]
    print(f"{'range':28s} {min(rel):.3f}-{max(rel):.3f}      {min(psnr):.1f}-{max(psnr):.1f}")
    print()


def rgl_tables() -> list[BRDFTable]:
    from bench_quality import rgl_tables as load

    return load()


def trimmed(table: BRDFTable, max_deg: float = 80.0) -> BRDFTable:
    """The table with NaN where the light or the view is more than ``max_deg`` from the normal
    and where a value is 0 (RGL values that came back negative and were clamped).

    The RGL data are unreliable there (noisy warps, clamped negatives; see
    gonio.brdf.materials.rgl), and a relative metric of a value near 0 explodes; the metrics skip
    NaN cells.
    """
    ci, co = geo.cell_cosines(*geo.grid_angles())
    far = np.minimum(ci, co) < np.cos(np.deg2rad(max_deg))
    v = np.array(table.values, dtype=float)
    v[:, :, far] = np.nan
    v[v <= 0] = np.nan  # clamped negative measurements: unknown, not zero
    return BRDFTable.trusted(v, table.channels, table.name)


def row(name: str, table: BRDFTable) -> float:
    t0 = time.perf_counter()
    fits = fit_all(table)
    total = time.perf_counter() - t0
    f, p = fits.factored.metrics, fits.principled.metrics
    ref80 = trimmed(table)
    f80 = fit_metrics(fits.factored.to_table(), ref80)
    p80 = fit_metrics(bm.tabulate(fits.principled.model(), np.float64), ref80)
    print(f"{name[:26]:26s} {f['rel_mse']:7.3f} {100 * f['mape']:6.1f} {f['psnr']:6.1f} | "
          f"{f80['rel_mse']:7.3f} {100 * f80['mape']:6.1f} {f80['psnr']:6.1f} "
          f"{f['seconds']:5.1f} | {p80['rel_mse']:7.3f} {100 * p80['mape']:6.1f} "
          f"{p80['psnr']:6.1f} {p['log_rmse']:7.4f} {fits.principled.roughness:5.3f} "
          f"{p['seconds']:5.1f}")
    return total


def header(title: str) -> None:
    print(title)
    print(f"{'':26s} {'factored, all cells':>21s} | {'factored, both <= 80 deg':>26s} | "
          f"{'principled, both <= 80 deg; logRMSE all':>44s}")
    print(f"{'material':26s} {'relMSE':>7s} {'MAPE%':>6s} {'PSNR':>6s} | {'relMSE':>7s} "
          f"{'MAPE%':>6s} {'PSNR':>6s} {'fit s':>5s} | {'relMSE':>7s} {'MAPE%':>6s} "
          f"{'PSNR':>6s} {'logRMSE':>7s} {'rough':>5s} {'fit s':>5s}")


def export_times(table: BRDFTable, out: Path) -> None:
    fits = fit_all(table)
    prov = provenance({"job_id": 0, "specimen": table.name}, fits, {})
    print("export times (fits in hand), one material:")
    for fmt in ("factored", "mtlx", "gltf", "merl", "table"):
        t0 = time.perf_counter()
        p = write_export(fits, fmt, out / f"x-{fmt}", prov)
        print(f"  {fmt:9s} {time.perf_counter() - t0:6.2f} s  {p.stat().st_size:>12,} bytes")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-rgl", action="store_true")
    ap.add_argument("--analytic", type=int, default=len(ANALYTIC),
                    help="how many anisotropic library materials")
    args = ap.parse_args()
    paper_table()
    times: list[float] = []
    if not args.no_rgl:
        tables = rgl_tables()
        if tables:
            header("gonio on the measured RGL materials (RGB, on the BRDF table)")
            for t in tables:
                times.append(row(t.name, t))
            print()
    header("gonio on anisotropic analytic library materials")
    last = None
    for name in ANALYTIC[: args.analytic]:
        last = bm.tabulate(library.get_material(name), dtype=np.float64)
        times.append(row(name, last))
    print()
    if times:
        print(f"fit_all (factored + principled) per material: median {np.median(times):.1f} s, "
              f"max {max(times):.1f} s")
    if last is not None:
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            export_times(last, Path(d))


if __name__ == "__main__":
    main()
