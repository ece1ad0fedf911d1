"""Adaptive refinement on the joint fit's posterior, and the posterior's self-estimated error.

Run from the project root (needs mitsuba and ``../shared/data/rgl``, like
``bench/bench_unseen.py``, whose materials, readings and designs it reuses)::

    nice -n 5 .venv/bin/python bench/bench_adaptive.py [--gains 2e-5] [--starts 8 4]
        [--max-rotations 16] [--set panel|wide|unseen|both] [--only measured|aniso]
        [--rel-gains 0.02 ...] [--candidates midpoints|quarters] [--seed 0]
        [--span 180] [--digits 4] [--drop predicted|expected]
        [--offset scan|none]

Sets
----
* ``panel`` (calibration, held-out *training* materials): one synthetic material per library
  family held out of the panel basis of :mod:`gonio.brdf.design.heldout` (built without
  them), read from their tables with 1 % noise.
* ``wide`` (calibration): three synthetic materials per family (21, six of them
  anisotropic: fabric and brushed metal) held out of a basis built without them (cached
  like the panel basis; about a minute to build once). The rule's settings of
  :func:`gonio.brdf.reconstruction.posterior.next_angles` are chosen here (docs/science.md
  7.3): the lowest mean error with at most 60 % of uniform 16's readings.
* ``unseen`` (the benchmark of ``bench_unseen.py``): 11 measured RGL materials, each with a
  basis that leaves it out, and 6 mitsuba anisotropic specimens.

Every scan: pairs designed for n = 10 on the material's own basis (``--design``, default
``design_pairs``' default objective; for 8 angles over ``bench_unseen``'s design arc, half a
turn, whatever ``--span``), start at ``r0``
uniform stage angles over ``--span`` degrees (each of ``--starts``; 180, half a turn, the
plans' default, or 360), refine by :func:`next_angles` within that arc (rounds until it
plans nothing; at most one new angle per gap per round, as the engine runs it) up to
``--max-rotations``; then two reconstructions of everything read: the joint fit with the
learnt prior as it is (``rho=None``: "plain fit"), and the default, which takes the scan's
own ``rho`` when it is below 1 (``rho="scan"``: "scan rho"). Rows: uniform 4, 8 and 16
(plain fit and scan rho) over the same arc, and with ``--span 180`` uniform 8 and 16 over a
full turn too (the reference before plans covered half a turn), each start and threshold.
Columns: mean ``log_rmse`` per group and
overall, mean readings, share of uniform 16's readings.

The self-estimated error (``predicted_log_rmse``) is calibrated by ``calibrate_log_rmse.py``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass

# Run as `python bench/bench_adaptive.py`, so the sibling script is importable.
import bench_unseen as bu
import numpy as np

from gonio.brdf.reconstruction.basis import Basis, default_basis
from gonio.brdf.reconstruction.posterior import MIDPOINTS, QUARTERS, REFINE_GAIN, next_angles
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import uniform_stage_angles
from gonio.brdf.tables import metrics


@dataclass
class Case:
    mat: bu.Material
    basis: Basis
    cells: np.ndarray
    ph: np.ndarray
    seed: int


def panel_cases() -> list[Case]:
    from gonio.brdf.design.heldout import _panel

    pb, synth, _meas = _panel()
    cells, ph = bu.design(pb, 10)
    return [Case(bu.Material(t.name, "panel", t, t, ()), pb, cells, ph, 500 + i)
            for i, t in enumerate(synth)]


#: Synthetic materials per library family held out of the wide panel's basis.
WIDE_PER_FAMILY = 3


def wide_panel_cases() -> list[Case]:
    """The first :data:`WIDE_PER_FAMILY` materials of every library family (21), held out of
    a basis built without them (the measured materials folded in as in the default basis),
    built once and cached like the panel basis. Grouped as "iso" (families whose materials
    do not vary with the stage angle) and "aniso" (fabric, brushed metal)."""
    from gonio.brdf.materials import library, measured
    from gonio.brdf.reconstruction.basis import (
        _FOLD_EXTRA,
        DEFAULT_COMPONENTS,
        MEASURED_WEIGHT,
        build_basis,
        fold_in,
    )

    count: dict[str, int] = {}
    held: list[tuple[str, str]] = []
    for s in library.library_specs():
        if count.get(s.family, 0) < WIDE_PER_FAMILY:
            count[s.family] = count.get(s.family, 0) + 1
            held.append((s.name, s.family))
    names = {n for n, _ in held}
    path = (library.cache_root() / "basis" / f"panel{WIDE_PER_FAMILY}-K"
            f"{DEFAULT_COMPONENTS + _FOLD_EXTRA}-{library.library_key()[:16]}.npz")
    if path.is_file():
        base = Basis.load(path)
    else:
        t0 = time.perf_counter()
        base = build_basis([t for t in library.default_library() if t.name not in names],
                           DEFAULT_COMPONENTS + _FOLD_EXTRA)
        path.parent.mkdir(parents=True, exist_ok=True)
        base.save(path)
        print(f"  wide panel basis built in {time.perf_counter() - t0:.0f} s", flush=True)
    pb = fold_in(base, measured.measured_tables(), MEASURED_WEIGHT, DEFAULT_COMPONENTS)
    cells, ph = bu.design(pb, 10)
    out = []
    for i, (n, fam) in enumerate(held):
        t = library.library_table(n)
        kind = "aniso" if fam in ("fabric", "brushed-metal") else "iso"
        out.append(Case(bu.Material(t.name, kind, t, t, ()), pb, cells, ph, 700 + i))
    return out


def unseen_cases() -> list[Case]:
    mats = bu.measured_materials() + bu.aniso_materials()
    out = []
    for i, m in enumerate(mats):
        b = default_basis(exclude=m.exclude)
        cells, ph = bu.design(b, 10)
        out.append(Case(m, b, cells, ph, 100 + i))
    return out


#: Candidate positions in each gap (``--candidates``; default: next_angles' default).
FRACTIONS: dict[str, tuple[float, ...]] = {"value": MIDPOINTS}

#: Added to every scan's noise seed (``--seed``).
SEED = {"offset": 0}

#: Decimals of the table's mean errors (``--digits``).
DIGITS = {"value": 4}

#: Arc of the scans, degrees (``--span``): the uniform angles cover it, refinement stays in it.
SPAN = {"deg": 180.0}

#: What a pick's drop is measured on (``--drop``): the posterior's expected error or the
#: self-estimate (``next_angles``' ``cv_sample_error``).
DROP = {"of": "predicted"}

#: The planning posterior's per-pair offset (``--offset``): 0 (none) or "scan".
OFFSET: dict[str, float | str] = {"value": "scan"}

Result = tuple[float, int]
"""(log_rmse, readings) of one scan."""


def finals(c: Case, angles_deg: list[float], vals: np.ndarray) -> tuple[Result, Result]:
    """The joint fit with the learnt prior and with the scan's own rho (the default)."""
    alpha = np.deg2rad(angles_deg)
    plain = reconstruct(c.basis, c.cells, c.ph, alpha, vals, rho=None)
    shrunk = reconstruct(c.basis, c.cells, c.ph, alpha, vals)
    n = vals.shape[0] * len(angles_deg)
    return ((metrics.log_rmse(plain.table, c.mat.truth), n),
            (metrics.log_rmse(shrunk.table, c.mat.truth), n))


def uniform(c: Case, r: int, span_deg: float | None = None) -> tuple[Result, Result]:
    """Uniform ``r`` over ``span_deg`` (default: the run's ``--span``)."""
    span = np.deg2rad(SPAN["deg"] if span_deg is None else span_deg)
    angles = list(np.rad2deg(uniform_stage_angles(r, span=span)))
    vals = bu.read(c.mat, c.cells, c.ph, np.deg2rad(angles), c.seed + SEED["offset"])
    return finals(c, angles, vals)


def adaptive(c: Case, gain: float, r0: int, max_r: int,
             rel: float = 0.0) -> tuple[Result, Result]:
    fr = FRACTIONS["value"]
    seed = c.seed + SEED["offset"]
    period = SPAN["deg"]
    angles = list(np.rad2deg(uniform_stage_angles(r0, span=np.deg2rad(period))))
    vals = bu.read(c.mat, c.cells, c.ph, np.deg2rad(angles), seed)
    for rnd in range(8):
        # As the engine plans (gonio/refinement.py): the library prior's fit.
        rec = reconstruct(c.basis, c.cells, c.ph, np.deg2rad(angles), vals, local=None)
        cv = rec.cv_sample_error if DROP["of"] == "predicted" else None
        step = next_angles(c.basis, c.cells, c.ph, angles, vals, threshold=gain,
                           rel_threshold=rel, budget_angles=max_r - len(angles), per_gap=1,
                           fractions=fr, table=rec.table.values, period_deg=period,
                           cv_sample_error=cv, offset=OFFSET["value"],
                           mahalanobis=rec.mahalanobis)
        if not step.angles_deg:
            break
        extra = bu.read(c.mat, c.cells, c.ph, np.deg2rad(step.angles_deg),
                        seed + 1000 * (rnd + 1))
        angles += step.angles_deg
        vals = np.concatenate([vals, extra], axis=1)
    return finals(c, angles, vals)


def table(name: str, cases: list[Case], gains: list[float], starts: list[int],
          max_r: int, rels: list[float] | None = None) -> dict[str, float]:
    rows: dict[str, dict[str, Result]] = {}
    t0 = time.perf_counter()

    def put(row: str, c: Case, both: tuple[Result, Result]) -> None:
        rows.setdefault(f"{row}, plain fit", {})[c.mat.name] = both[0]
        rows.setdefault(f"{row}, scan rho", {})[c.mat.name] = both[1]

    for c in cases:
        for r in (4, 8, 16):
            put(f"uniform {r}", c, uniform(c, r))
        if SPAN["deg"] != 360.0:
            for r in (8, 16):
                put(f"uniform {r} over 360 deg", c, uniform(c, r, 360.0))
        for r0 in starts:
            for g in gains:
                put(f"posterior {r0}->{max_r} gain>={g}", c, adaptive(c, g, r0, max_r))
            for f in rels or []:
                put(f"posterior {r0}->{max_r} drop>={f}*expected", c,
                    adaptive(c, 0.0, r0, max_r, rel=f))
        print(f"  {c.mat.name}: " + "; ".join(
            f"{k} {v[c.mat.name][0]:.4f}/{v[c.mat.name][1]}"
            for k, v in rows.items()) + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    kinds = sorted({c.mat.kind for c in cases})
    print(f"\n{name}, scans over {SPAN['deg']:g} deg:\n| row | "
          + " | ".join(f"{k} ({sum(c.mat.kind == k for c in cases)})"
                     for k in kinds)
          + " | all | readings (mean; per kind) | share of uniform 16 |")
    print("|---" * (len(kinds) + 4) + "|")
    u16 = np.mean([v[1] for v in rows["uniform 16, plain fit"].values()])
    out = {}
    for row, per in rows.items():
        d = DIGITS["value"]
        txt = " | ".join(f"{np.mean([per[c.mat.name][0] for c in cases if c.mat.kind == k]):.{d}f}"
                         for k in kinds)
        allm = float(np.mean([v[0] for v in per.values()]))
        rd = float(np.mean([v[1] for v in per.values()]))
        by_kind = " / ".join(
            f"{np.mean([per[c.mat.name][1] for c in cases if c.mat.kind == k]):.0f}"
            for k in kinds)
        out[row] = allm
        print(f"| {row} | {txt} | {allm:.{d}f} | {rd:.1f} ({by_kind}) | {rd / u16:.0%} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gains", type=float, nargs="*", default=[REFINE_GAIN])
    ap.add_argument("--rel-gains", type=float, nargs="*", default=[],
                    help="relative stopping rule: least drop per angle as a fraction of the "
                         "posterior's expected log_rmse (threshold 0)")
    ap.add_argument("--starts", type=int, nargs="*", default=[8, 4],
                    help="initial uniform stage angles r0 of the adaptive scans")
    ap.add_argument("--max-rotations", type=int, default=16)
    ap.add_argument("--set", choices=["panel", "wide", "unseen", "both"], default="both",
                    help="panel: 7 held-out synthetic materials (one per family); wide: 21 "
                         "(three per family, their own basis); both: panel and unseen")
    ap.add_argument("--design", choices=list(bu.DESIGNS), default=bu.DEFAULT_OBJECTIVE,
                    help="pair design of every scan (bench_unseen.py's --design; default: "
                         "design_pairs' default objective)")
    ap.add_argument("--only", choices=["measured", "aniso"], default=None)
    ap.add_argument("--seed", type=int, default=0,
                    help="added to every scan's noise seed (a second draw of the noise)")
    ap.add_argument("--candidates", choices=["midpoints", "quarters"], default="midpoints",
                    help="candidate angles of the posterior rule: the gaps' midpoints (the "
                         "default of next_angles) or their quarter, half and three-quarter "
                         "points (before this round)")
    ap.add_argument("--digits", type=int, default=4,
                    help="decimals of the table's mean errors (5 to break ties)")
    ap.add_argument("--span", type=float, choices=[180.0, 360.0], default=180.0,
                    help="arc of every scan, degrees: 180 (half a turn, the plans' default) "
                         "or 360 (a full turn, as before)")
    ap.add_argument("--drop", choices=["expected", "predicted"], default="predicted",
                    help="what a pick's drop is measured on: the self-estimate "
                         "predicted_log_rmse, whose part the basis cannot represent does not "
                         "fall with more angles (the engine's, the default since session 7), "
                         "or the posterior's expected error alone (before)")
    ap.add_argument("--offset", choices=["none", "scan"], default="scan",
                    help="planning posterior: a per-pair offset, constant over the stage "
                         "angle, sized by marginal likelihood (scan, the engine's and the "
                         "default since session 7) or none (before)")
    args = ap.parse_args(argv)
    OFFSET["value"] = "scan" if args.offset == "scan" else 0.0
    SPAN["deg"] = args.span
    DROP["of"] = args.drop
    DIGITS["value"] = args.digits
    FRACTIONS["value"] = MIDPOINTS if args.candidates == "midpoints" else QUARTERS
    bu.CHOOSE["objective"] = args.design
    print(f"$ {' '.join(['python', *sys.argv])}")
    SEED["offset"] = args.seed
    if args.set in ("panel", "both"):
        table("panel (calibration)", panel_cases(), args.gains, args.starts,
              args.max_rotations, args.rel_gains)
    if args.set == "wide":
        table("wide panel (calibration)", wide_panel_cases(), args.gains, args.starts,
              args.max_rotations, args.rel_gains)
    if args.set in ("unseen", "both"):
        cases = [c for c in unseen_cases() if args.only in (None, c.mat.kind)]
        table("unseen (benchmark)", cases, args.gains, args.starts, args.max_rotations,
              args.rel_gains)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
