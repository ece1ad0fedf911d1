"""Diagnostic: do the training library's metals fall off at grazing angles as mitsuba's do?

Run from the project root (docs/science.md 7.1.1.3, last paragraph)::

    GONIO_CACHE_DIR=<cache> nice -n 10 .venv/bin/python bench/bench_libmetal.py \
        [--rank-flank] [--all-families] [--twins] [NAME ...]

For rough isotropic mitsuba conductors (default :data:`SPECIMENS`: the four rough metals the
MA98 self-estimate misses, and tungsten and copper oxide, which it does not), the truth table
on gonio's grid (rendered and cached as ``bench_selfestimate`` does) is compared with each
member of the default library's ``metal`` family. The members are ranked by :func:`read_error`,
the ``log_rmse`` over the cells with ``theta_d`` below :data:`READ_TD_DEG` (about what MA98's
layout reaches); for the closest :data:`TOP` the table prints :func:`band_bias`, the weighted
mean of ``ln(f_library / f_truth)`` on the lobe's flank (``theta_h`` 10-30 deg) per band of
``theta_d``. A library whose closest metals match below 50 deg and are too high beyond 60 deg
carries the grazing lobe that MA98's reconstructions carry (science.md 7.1.1.3's hypothesis).
``--rank-flank`` ranks instead by how far the flank's level is off below 50 deg (the first
band's bias, in absolute value), ``--all-families`` ranks every member of the default library;
``--twins`` prints instead the library recipe's own GGX at the specimen's alpha and metal
(:data:`TWINS`).
"""

from __future__ import annotations

import sys
from typing import Any

import bench_asymmetric as ba  # sibling benches (the script's folder is on sys.path)
import bench_selfestimate as bs
import numpy as np

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics

#: theta_d (deg) below which a cell counts as read by MA98 when ranking library members.
READ_TD_DEG = 50.0
#: The lobe's flank, theta_h in [lo, hi) deg.
FLANK_TH_DEG = (10.0, 30.0)
#: Bands of theta_d (deg), [lo, hi).
TD_BANDS_DEG: tuple[tuple[float, float], ...] = ((0.0, 50.0), (50.0, 60.0), (60.0, 70.0),
                                                  (70.0, 90.0))
#: Closest library members reported per specimen.
TOP = 3
#: (name, where bench_selfestimate keeps it): the untilted twins of bench_asymmetric.ASYM, or a
#: member of one of bench_selfestimate's FRESH tuples.
SPECIMENS: tuple[tuple[str, str], ...] = (
    ("al-r0.25-t20-untilted", "ASYM"),
    ("cu-r0.30-t30-untilted", "ASYM"),
    ("f6-be-r25", "FRESH_WIDE"),
    ("fc-hgte-r30", "FRESH_COV"),
    ("f5-w-r20", "FRESH_CONFIRM"),
    ("fh-cuo-r35", "FRESH_HIGH"),
)


#: Specimens whose metal the library's recipe also knows: (library metal, mitsuba's alpha), for
#: ``--twins``: the library's own GGX recipe at the specimen's alpha and optical constants.
TWINS: dict[str, tuple[str, float]] = {
    "al-r0.25-t20-untilted": ("aluminium", 0.25),
    "cu-r0.30-t30-untilted": ("copper", 0.30),
}


def _log_values(values: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(ln(1 + f cos ti), finite)`` over the valid cells, shape (C, 72, n_valid)."""
    mask = geo.valid_mask()
    v = np.asarray(values, dtype=float)[:, :, mask]
    ci = metrics.cell_cos_ti()[mask]
    return np.log1p(np.maximum(v, 0.0) * ci), np.isfinite(v)


def read_error(f_lib: Any, f_truth: Any, td_max_deg: float = READ_TD_DEG) -> float:
    """``log_rmse`` of ``f_lib`` against ``f_truth`` over the valid cells with ``theta_d`` below
    ``td_max_deg`` only.

    Parameters
    ----------
    f_lib, f_truth : (C, 72, 18, 18, 36) arrays, 1/sr
    td_max_deg : float, degrees

    Returns
    -------
    float, dimensionless (``log_rmse`` units)
    """
    la, oka = _log_values(f_lib)
    lb, okb = _log_values(f_truth)
    _th, td, _pd = (g[geo.valid_mask()] for g in geo.grid_angles())
    w = geo.volume_weight()[geo.valid_mask()] * (td < np.deg2rad(td_max_deg))
    ok = oka & okb
    ww = np.where(ok, w, 0.0)
    return float(np.sqrt(np.sum(ww * np.where(ok, la - lb, 0.0) ** 2) / np.sum(ww)))


def band_bias(f_lib: Any, f_truth: Any, flank_deg: tuple[float, float] = FLANK_TH_DEG,
              bands_deg: tuple[tuple[float, float], ...] = TD_BANDS_DEG) -> list[float]:
    """Volume-weighted mean of ``ln(f_lib / f_truth)`` on ``flank_deg`` per band of theta_d.

    Over the valid cells with ``theta_h`` in ``[flank_deg[0], flank_deg[1])``, every ``ph`` and
    channel where both values are finite and positive (a zero has no log ratio).

    Parameters
    ----------
    f_lib, f_truth : (C, 72, 18, 18, 36) arrays, 1/sr
    flank_deg : (lo, hi), degrees of theta_h
    bands_deg : ((lo, hi), ...), degrees of theta_d

    Returns
    -------
    list of float, one per band (natural log; NaN for a band with no such cell)
    """
    mask = geo.valid_mask()
    a = np.asarray(f_lib, dtype=float)[:, :, mask]
    b = np.asarray(f_truth, dtype=float)[:, :, mask]
    ok = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
    r = np.log(np.where(ok, a, 1.0) / np.where(ok, b, 1.0))
    th, td, _pd = (g[mask] for g in geo.grid_angles())
    w = geo.volume_weight()[mask]
    on_flank = (th >= np.deg2rad(flank_deg[0])) & (th < np.deg2rad(flank_deg[1]))
    out = []
    for lo, hi in bands_deg:
        sel = on_flank & (td >= np.deg2rad(lo)) & (td < np.deg2rad(hi))
        ww = np.where(ok, w * sel, 0.0)
        out.append(float(np.sum(ww * r) / np.sum(ww)) if np.sum(ww) > 0 else float("nan"))
    return out


def specimen(name: str, where: str) -> Any:
    """The truth table of specimen ``name`` (1/sr, (3, 72, 18, 18, 36)), rendered by mitsuba
    and cached exactly as ``bench_selfestimate`` does (same cache key)."""
    if where == "ASYM":
        entry = [e for e in ba.ASYM if f"{e[0]}-untilted" == name]
        return ba.asym_materials(tilted=False, specs=entry)[0].truth.values
    entry = [e for e in getattr(bs, where) if e[0] == name]
    return bs.fresh_materials(tuple(entry), where)[0][0].truth.values


def _describe(spec: library.MaterialSpec) -> str:
    d = bm.to_dict(spec.model)
    while "model" in d and "alpha_x" not in d:  # through the orientation wrapper
        d = d["model"]
    if "alpha_x" not in d:  # not a bare GGX lobe: say which family and model
        return f"{spec.family}: {d.get('type', '?')}"
    kind = str(d.get("fresnel", {}).get("type", "?")).replace("Fresnel", "")
    return (f"GGX {d.get('alpha_x', float('nan')):.2f}/{d.get('alpha_y', float('nan')):.2f}"
            f", {kind}, {d.get('masking', '?')}")


def _rank_key(rank: str, f_lib: Any, truth: Any) -> float:
    if rank == "read":
        return read_error(f_lib, truth)
    return abs(band_bias(f_lib, truth)[0])  # "flank": the flank's level where MA98 reads


def twins() -> int:
    """Print :func:`band_bias` of the library recipe's isotropic GGX twin of each of
    :data:`TWINS` (both masking forms the metal family draws) against mitsuba's truth."""
    print("| specimen | twin | log_rmse theta_d < 50 | "
          + " | ".join(f"theta_d {lo:g}-{hi:g}" for lo, hi in TD_BANDS_DEG) + " |")
    print("|---" * (3 + len(TD_BANDS_DEG)) + "|")
    where = dict(SPECIMENS)
    for name, (metal, alpha) in TWINS.items():
        truth = specimen(name, where[name])
        eta, k = library._METALS[metal]
        for masking in ("correlated", "separable"):
            model = bm.GGX(alpha, alpha, bm.ConductorFresnel(eta, k), masking, name="twin")
            f = bm.expand_valid(bm.tabulate_valid(model))
            print(f"| {name} | GGX {alpha:.2f} {metal}, {masking} | {read_error(f, truth):.3f} | "
                  + " | ".join(f"{x:+.2f}" for x in band_bias(f, truth)) + " |", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if "--twins" in args:
        return twins()
    rank = "flank" if "--rank-flank" in args else "read"
    pool = "all" if "--all-families" in args else "metal"
    names = [a for a in args if not a.startswith("--")]
    chosen = [s for s in SPECIMENS if not names or s[0] in names]
    specs = [s for s in library.library_specs() if pool == "all" or s.family == "metal"]
    truths = {name: specimen(name, where) for name, where in chosen}
    keys: dict[str, list[float]] = {name: [] for name in truths}
    for s in specs:  # one table in memory at a time (the whole library is about 2 GB)
        f = library.library_table(s.name).values
        for name, truth in truths.items():
            keys[name].append(_rank_key(rank, f, truth))
    bands = " | ".join(f"theta_d {lo:g}-{hi:g}" for lo, hi in TD_BANDS_DEG)
    print(f"ranked by {'|flank bias at theta_d < 50|' if rank == 'flank' else 'read_error'}"
          f" over the {'whole library' if pool == 'all' else 'metal family'}")
    print(f"| specimen | library member | recipe | log_rmse theta_d < {READ_TD_DEG:g} | {bands} |")
    print("|---" * (4 + len(TD_BANDS_DEG)) + "|")
    for name, truth in truths.items():
        for j in np.argsort(keys[name], kind="stable")[:TOP]:
            s = specs[int(j)]
            f = library.library_table(s.name).values
            bias = band_bias(f, truth)
            print(f"| {name} | {s.name} | {_describe(s)} | {read_error(f, truth):.3f} | "
                  + " | ".join(f"{x:+.2f}" for x in bias) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
