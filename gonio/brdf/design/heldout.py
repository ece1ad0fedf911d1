"""Expected reconstruction error of a scan geometry on materials held out of the basis.

The condition number of a design is a property of the basis alone; what a lab cares about is
the error on a material the basis has not seen. :func:`heldout_log_rmse` simulates the scan
(1 % noise, ``r`` uniform stage angles, the default joint reconstruction) on a fixed panel:

* the shipped measured materials, each reconstructed with a basis that leaves it out
  (``default_basis(exclude=[it])``, a fold-in of seconds, cached);
* one synthetic material of each library family, held out of a *panel basis* (the synthetic
  library without those seven, built once and cached; the measured materials folded in as in
  the default basis).

:func:`choose_design` runs the condition-number search from several seeds and keeps the
candidate with the lowest expected error. The panel is part of the training data of the
default basis, so the numbers are estimates for "a material like these", not guarantees.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.pairs import PairDesign
from gonio.brdf.reconstruction.basis import (
    _FOLD_EXTRA,
    DEFAULT_COMPONENTS,
    MEASURED_WEIGHT,
    Basis,
    build_basis,
    default_basis,
    fold_in,
)
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import (
    DEFAULT_SPAN_DEG,
    NoiseModel,
    simulate_samples,
    span_periods,
    uniform_stage_angles,
)
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]

HELDOUT_NOISE = 0.01
"""Relative reading noise of the simulated scans (1 %): one of the assumptions a design's
expected error states (``gonio design``, the rig config's ``[design]`` table)."""


@dataclass(frozen=True)
class ExpectedError:
    """Mean ``log_rmse`` of a geometry over the held-out panel."""

    log_rmse: float
    measured: float
    synthetic: float
    per_material: dict[str, float]


def _synthetic_panel_names() -> list[str]:
    from gonio.brdf.materials.library import library_specs

    seen: set[str] = set()
    names = []
    for s in library_specs():
        if s.family not in seen:
            seen.add(s.family)
            names.append(s.name)
    return names


def panel_basis_path() -> Path:
    """Cache file of the held-out panel's synthetic basis (the training library without the
    panel's synthetic materials), under the library's cache root."""
    from gonio.brdf.materials import library

    return (library.cache_root() / "basis"
            / f"panel-K{DEFAULT_COMPONENTS + _FOLD_EXTRA}-{library.library_key()[:16]}.npz")


def panel_is_cached() -> bool:
    """Whether the panel's basis is cached: when it is not, the first
    :func:`heldout_log_rmse` tabulates the training library and builds it (about half a minute
    and 3.5 GB of memory on a 2-core machine, once)."""
    return panel_basis_path().is_file()


@functools.cache
def _panel() -> tuple[Basis, list[BRDFTable], list[tuple[BRDFTable, Basis]]]:
    """(panel basis, held-out synthetic tables, [(measured table, basis without it)])."""
    from gonio.brdf.materials import library, measured

    held = _synthetic_panel_names()
    path = panel_basis_path()
    if path.is_file():
        base = Basis.load(path)
    else:
        tables = library.default_library()
        base = build_basis([t for t in tables if t.name not in held],
                           DEFAULT_COMPONENTS + _FOLD_EXTRA)
        path.parent.mkdir(parents=True, exist_ok=True)
        base.save(path)
    synth = [library.library_table(n) for n in held]
    panel_basis = fold_in(base, measured.measured_tables(), MEASURED_WEIGHT, DEFAULT_COMPONENTS)
    meas = [(t, default_basis(exclude=[t.name])) for t in measured.measured_tables()]
    return panel_basis, synth, meas


def heldout_log_rmse(cells: ArrayLike, ph_lab: ArrayLike, rotations: int = 8,
                      seed: int = 0, span_deg: float = DEFAULT_SPAN_DEG) -> ExpectedError:
    """Mean log_rmse of the default reconstruction over the held-out panel (module notes).

    Parameters
    ----------
    cells : (n, 3) radians
    ph_lab : (n,) radians
    rotations : int
        Uniform stage angles of the simulated scans.
    seed : int
        Noise seed (:data:`HELDOUT_NOISE` relative noise).
    span_deg : {180, 360}
        The arc those angles cover.
    """
    span_periods(span_deg)  # a clear error for any other arc, before the panel is built
    panel_basis, synth, meas = _panel()
    alpha = uniform_stage_angles(int(rotations), span=np.deg2rad(span_deg))
    c = np.asarray(cells, dtype=float)
    p = np.asarray(ph_lab, dtype=float)
    per: dict[str, float] = {}
    groups: dict[str, list[float]] = {"measured": [], "synthetic": []}
    runs = [(t, panel_basis, "synthetic") for t in synth] + [(t, b, "measured")
                                                              for t, b in meas]
    for k, (t, b, kind) in enumerate(runs):
        vals = simulate_samples(t, c, p, alpha, noise=NoiseModel(HELDOUT_NOISE, seed=seed + k))
        rec = reconstruct(b, c, p, alpha, vals)
        e = metrics.log_rmse(rec.table, t)
        per[t.name] = e
        groups[kind].append(e)
    return ExpectedError(
        log_rmse=float(np.mean(list(per.values()))),
        measured=float(np.mean(groups["measured"])),
        synthetic=float(np.mean(groups["synthetic"])),
        per_material=per,
    )


def choose_design(
    make: Callable[[int], PairDesign], seeds: Sequence[int], rotations: int = 8,
    span_deg: float = DEFAULT_SPAN_DEG,
) -> tuple[PairDesign, ExpectedError, list[tuple[int, float, float]]]:
    """Run ``make(seed)`` for every seed and keep the design with the lowest expected error.

    Parameters
    ----------
    make : callable ``seed -> PairDesign`` (e.g. :func:`gonio.brdf.design.pairs.design_pairs` with
        its other arguments bound)
    seeds : the candidates' seeds
    rotations : stage angles of the simulated scans
    span_deg : the arc they cover (180 or 360 degrees)

    Returns
    -------
    best design, its :class:`ExpectedError`, and ``(seed, kappa, expected log_rmse)`` of
    every candidate.
    """
    best: PairDesign | None = None
    best_err: ExpectedError | None = None
    table = []
    for s in seeds:
        d = make(s)
        err = heldout_log_rmse(d.cells, d.ph_lab, rotations, span_deg=span_deg)
        table.append((int(s), float(d.kappa), err.log_rmse))
        if best_err is None or err.log_rmse < best_err.log_rmse:
            best, best_err = d, err
    assert best is not None and best_err is not None
    return best, best_err, table
