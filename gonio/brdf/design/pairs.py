"""Pair designs: ``n`` independent light/sensor pairs from a basis.

:func:`design_pairs` chooses the pairs' cells by one of two objectives and places them in the
lab: V&F's condition number (:func:`~gonio.brdf.design.search.optimize_rows`) or the joint
fit's expected error (:func:`gonio.brdf.design.posterior.posterior_design`);
:data:`DEFAULT_OBJECTIVE` is the one used when none is asked for. :func:`geometry_design`
evaluates a given geometry (a preset or a rig config) the same way. All return a
:class:`~gonio.brdf.design.pairdesign.PairDesign`, as product rigs do
(:mod:`gonio.brdf.design.product`).

Every optimized design reports the objective that made it, ``kappa`` of its rows and, for a
gonio :class:`~gonio.brdf.reconstruction.basis.Basis`, the joint fit's expected log_rmse
(:func:`gonio.brdf.design.posterior.design_expected_log_rmse`), whichever objective chose it; only
the statistics of the search that actually ran (:class:`SearchResult` or
:class:`~gonio.brdf.design.pairdesign.GreedyStats`).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.colourtargets import ColourTargets
from gonio.brdf.design.conditioning import KappaMethod, condition_number
from gonio.brdf.design.constraints import (
    RigConstraints,
    candidate_rows,
    min_pairwise_distance,
    rows_to_cells,
)
from gonio.brdf.design.errors import DesignError, DesignTimeout, FeasibilityError
from gonio.brdf.design.mounting import MountPlanner
from gonio.brdf.design.pairdesign import OBJECTIVES, BasisLike, Objective, PairDesign
from gonio.brdf.design.placement import place_pairs
from gonio.brdf.design.posterior import (
    design_expected_log_rmse,
    posterior_design,
    prior_model,
)
from gonio.brdf.design.renderweight import DEFAULT_CELL_MIX, render_weight
from gonio.brdf.design.search import optimize_rows
from gonio.brdf.reconstruction.basis import Basis
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, SPANS_DEG
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

log = logging.getLogger(__name__)

#: The objective :func:`design_pairs` uses when none is given (and so ``gonio design``, the
#: API and every caller of ``design_pairs(basis, n, constraints)``). The test suite passes
#: with either value; which one is the default is decided by ``bench/bench_unseen.py``
#: (``docs/science.md`` 7.2.1).
DEFAULT_OBJECTIVE: Objective = "posterior"


def _device_degrees(dirs: FloatArray) -> FloatArray:
    theta, phi = geo.direction_to_spherical(dirs)
    out = np.rad2deg(np.stack([theta, phi], axis=-1)).reshape(-1, 2)
    out[:, 1] = np.where(out[:, 1] > 360.0 - 1e-9, 0.0, out[:, 1])
    return out


def geometry_design(
    basis: BasisLike, name: str, lights: ArrayLike, sensors: ArrayLike, pairs: ArrayLike
) -> PairDesign:
    """Evaluate a given geometry (preset or rig config) the same way as an optimized one.

    Parameters
    ----------
    basis : BasisLike
    name : str
    lights : (L, 3) array_like
        Light directions (lab, unit vectors).
    sensors : (S, 3) array_like
        Sensor directions.
    pairs : (n, 2) array_like of int
        ``(light, sensor)`` indices of the measured pairs.
    """
    li = np.asarray(lights, dtype=float).reshape(-1, 3)
    se = np.asarray(sensors, dtype=float).reshape(-1, 3)
    pr = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    if pr.shape[0] == 0:
        raise DesignError("a geometry needs at least one pair")
    th, ph, td, pd = geo.directions_to_half_diff(li[pr[:, 0]], se[pr[:, 1]])
    rows = basis.rows_at(th, td, pd)
    return PairDesign(
        name=name,
        cells=np.stack([th, td, pd], axis=1),
        ph_lab=ph,
        lights_deg=_device_degrees(li),
        sensors_deg=_device_degrees(se),
        pairs=pr,
        kappa=condition_number(rows),
        min_distance_deg=float(np.rad2deg(min_pairwise_distance(np.concatenate([li, se])))),
    )


def design_pairs(
    basis: BasisLike,
    n: int,
    constraints: RigConstraints,
    *,
    h: int = 7,
    starts: int = 10,
    descents: int = 10,
    seed: int | None = 0,
    method: KappaMethod = "fast",
    time_limit_s: float | None = None,
    objective: Objective | None = None,
    rotations: int = 8,
    span_deg: float = DEFAULT_SPAN_DEG,
    colour: ColourTargets | None = None,
    cell_weight: ArrayLike | None = None,
    cell_mix: float | None = None,
) -> PairDesign:
    """Choose ``n`` independent light/sensor pairs and place them in the lab.

    ``objective`` (default :data:`DEFAULT_OBJECTIVE`, read at call time):

    * ``"kappa"``: V&F's condition-number search (:func:`optimize_rows`) with a
      :class:`~gonio.brdf.design.mounting.MountPlanner`, so every design it visits can be
      mounted with ``min_device_distance_deg`` between any two devices and outside every
      exclusion; its placement is then spread by
      :func:`gonio.brdf.design.placement.place_pairs` (it keeps the limit and widens the
      closest gap where it can). ``h``, ``starts``, ``descents``, ``method`` and
      ``time_limit_s`` are its settings.
    * ``"posterior"``: the pairs that minimise the joint fit's expected error for a scan of
      ``rotations`` uniform stage angles over ``span_deg`` (180 or 360 degrees; default
      :data:`~gonio.brdf.reconstruction.samples.DEFAULT_SPAN_DEG`)
      (:func:`gonio.brdf.design.posterior.posterior_design`), each greedy step restricted to
      cells that still mount beside the pairs chosen so far; ``seed`` picks which first pair
      the greedy starts from (0: the best); ``time_limit_s`` bounds its mount checks' CPU time. It
      needs a gonio :class:`~gonio.brdf.reconstruction.basis.Basis` (its medians and prior).

    ``colour``: geometries a colour lab will read (:mod:`gonio.brdf.design.colourtargets`);
    only the expected-error design takes them (their direct pairs and weighted error), so
    asking for colour with ``objective="kappa"`` is an error, and a colour design that cannot
    be mounted or runs out of time raises instead of falling back to the condition-number
    search, which would drop the colour geometries.

    ``cell_weight``, ``cell_mix``: the expected-error design's second weighting of the grid's
    cells and its share (:func:`gonio.brdf.design.posterior.posterior_design`,
    docs/science.md 7.2.2). By default (``cell_mix=None``) the expected-error design mixes in
    the pixel counts of the standard renderings
    (:func:`gonio.brdf.design.renderweight.render_weight`, or ``cell_weight`` when given) at
    :data:`~gonio.brdf.design.renderweight.DEFAULT_CELL_MIX`, so the pairs also read the
    cells a picture of the specimen looks at; a colour design, which weighs its own
    geometries, and the condition-number search take no weighting by default, and a default
    weighted choice that cannot be mounted falls back like the unweighted one. An explicit
    ``cell_mix=0`` is the unweighted design; an explicit ``cell_mix > 0``, like ``colour``, is
    taken by the expected-error design only (with ``objective="kappa"`` it is an error, and
    it never falls back).

    Either way the condition-number search's ability to plan mounts is kept: when the
    expected-error choice cannot be mounted (a crowded rig, :class:`FeasibilityError`), runs
    past ``time_limit_s`` (the CPU time of its mount checks; the search then has
    ``time_limit_s`` of its own), or when it is only the default and
    ``basis`` is not a gonio ``Basis``, the search makes the design instead, the reason logged
    and kept in :attr:`PairDesign.fallback`. Candidates are
    the basis's valid cells that ``constraints`` allow
    (:func:`gonio.brdf.design.constraints.candidate_rows`).

    Returns
    -------
    PairDesign
        ``name="optimized"``, ``objective`` the one that chose the cells, ``kappa`` of its
        rows, ``expected_log_rmse`` at ``rotations`` (for a gonio ``Basis``), and the
        statistics of the search that ran (``search`` or ``greedy``).

    Raises
    ------
    DesignError
        For ``n < 1``, more pairs than feasible cells, an unknown objective,
        ``objective="posterior"`` (or ``colour``) asked for with a basis that is not a gonio
        ``Basis``, ``colour`` with ``objective="kappa"``, or fewer pairs than ``colour``'s
        direct pairs.
    FeasibilityError
        When no cell is feasible, or ``n`` pairs cannot be mounted under ``constraints``.
    """
    asked = DEFAULT_OBJECTIVE if objective is None else objective
    if asked not in OBJECTIVES:
        raise DesignError(f"objective must be one of {', '.join(OBJECTIVES)}, not {asked!r}")
    if n < 1:
        raise DesignError(f"the number of pairs must be at least 1, got {n}")
    if rotations < 1:
        raise DesignError(f"a scan needs at least one stage angle, got rotations={rotations}")
    if span_deg not in SPANS_DEG:
        raise DesignError(f"span_deg must be 180 or 360 (half or a full turn), got {span_deg:g}")
    if cell_mix and asked != "posterior":
        raise DesignError(
            "a cell weighting (cell_mix > 0) is taken by the expected-error design only; use "
            "objective='posterior' (the default) or cell_mix=0")
    # The default weighting (cell_mix=None) goes with the default's fallbacks below; only an
    # explicit cell_mix > 0 takes the strict path that raises instead.
    cells_asked: dict[str, Any] = ({"cell_weight": cell_weight, "cell_mix": cell_mix}
                                   if cell_mix else {})
    cells_default: dict[str, Any] = (
        {"cell_weight": render_weight() if cell_weight is None else cell_weight,
         "cell_mix": DEFAULT_CELL_MIX}
        if cell_mix is None and colour is None and asked == "posterior"
        and isinstance(basis, Basis) else {})
    if colour is not None:
        if asked != "posterior":
            raise DesignError(
                "colour geometries are taken by the expected-error design only; use "
                "objective='posterior' (the default) or leave the colour out")
        if not isinstance(basis, Basis):
            raise DesignError("a colour design needs a gonio Basis (its medians and prior)")
        return posterior_design(basis, n, constraints, rotations=rotations, span_deg=span_deg,
                                seed=0 if seed is None else seed, time_limit_s=time_limit_s,
                                colour=colour, **cells_asked)
    if cells_asked:
        # Like colour: the condition-number search cannot take the weighting, so its fallbacks
        # would drop it silently; the weighted design fails instead.
        if not isinstance(basis, Basis):
            raise DesignError("a cell weighting (cell_mix > 0) needs a gonio Basis (its medians "
                              "and prior)")
        try:
            return posterior_design(basis, n, constraints, rotations=rotations,
                                    span_deg=span_deg, seed=0 if seed is None else seed,
                                    time_limit_s=time_limit_s, **cells_asked)
        except FeasibilityError as exc:
            # Say the way out the default has: its choice falls back to the search that plans
            # mounts, an explicit weighting does not.
            raise FeasibilityError(
                exc.problem, (exc.advice + ", " if exc.advice else "")
                + "or leave {cell_mix} out (the default weighting falls back to the "
                "condition-number search, which plans mounts as it goes)",
                {**exc.words, "cell_mix": "the cell weighting (cell_mix; the API's render_mix)"}
            ) from exc
    fallback = None
    fallback_error: FeasibilityError | None = None
    if asked == "posterior":
        if isinstance(basis, Basis):
            try:
                return posterior_design(basis, n, constraints, rotations=rotations,
                                        span_deg=span_deg, seed=0 if seed is None else seed,
                                        time_limit_s=time_limit_s, **cells_default)
            except FeasibilityError as exc:
                fallback_error = exc
                fallback = (f"the expected-error choice could not be mounted ({exc}); the "
                            "condition-number search, which plans mounts as it goes, made "
                            "the design")
            except DesignTimeout as exc:
                fallback = (f"{exc}; the condition-number search made the design within a "
                            "time limit of its own (raise the time limit or ask for fewer "
                            "pairs to get the expected-error design)")
        elif objective is None:
            fallback = ("the expected-error design needs a gonio Basis (its medians and "
                        "prior); the condition-number search made the design")
        else:
            raise DesignError(
                "objective='posterior' needs a gonio Basis (its medians and prior); "
                "pass objective='kappa' for other row sources"
            )
    design = _kappa_design(basis, n, constraints, h=h, starts=starts, descents=descents,
                           seed=seed, method=method, time_limit_s=time_limit_s)
    if fallback is not None:
        # Said once the fallback has made the design: said before it, "the condition-number
        # search made the design" stood above that search's own failure.
        log.warning("design of %d pairs: %s", n, fallback)
    return replace(with_expected_error(basis, design, rotations, span_deg), fallback=fallback,
                   fallback_error=fallback_error)


def with_expected_error(basis: BasisLike, design: PairDesign, rotations: int,
                        span_deg: float = DEFAULT_SPAN_DEG) -> PairDesign:
    """``design`` with the joint fit's expected log_rmse for ``rotations`` uniform stage angles
    over ``span_deg`` (180 or 360 degrees).

    For any geometry (an optimized design, a preset, a product rig): the expected error of its
    cells' basis rows (:func:`gonio.brdf.design.posterior.design_expected_log_rmse`; off-grid cells
    read the basis's interpolated rows). ``design`` unchanged when ``basis`` is not a gonio
    :class:`~gonio.brdf.reconstruction.basis.Basis` (no prior to take the expectation under).
    """
    if not isinstance(basis, Basis):
        return design
    rows = basis.rows_at(design.cells[:, 0], design.cells[:, 1], design.cells[:, 2])
    model = prior_model(basis, rotations, span_deg=span_deg)
    return replace(design, expected_log_rmse=design_expected_log_rmse(model, rows),
                   rotations=int(rotations), span_deg=float(span_deg))


def _kappa_design(
    basis: BasisLike, n: int, constraints: RigConstraints, *, h: int, starts: int,
    descents: int, seed: int | None, method: KappaMethod, time_limit_s: float | None,
) -> PairDesign:
    """V&F's condition-number search, collision-aware, then spread by ``place_pairs``."""
    cand = candidate_rows(constraints, basis.valid)
    # The planner's azimuth grid is place_pairs' default, so the search's placement carries
    # over exactly. Without a device-distance limit nothing can collide (every candidate cell
    # has an allowed azimuth), and place_pairs alone spreads the devices.
    planner = MountPlanner(constraints, ph_step_deg=1.0)
    result = optimize_rows(
        basis.Q, cand, n, h=h, starts=starts, descents=descents, seed=seed, method=method,
        time_limit_s=time_limit_s, mounts=planner if planner.collisions_possible else None,
    )
    placement = place_pairs(
        rows_to_cells(result.rows), constraints, ph_step_deg=1.0,
        seed=0 if seed is None else seed, initial_ph=result.ph_lab,
    )
    return replace(PairDesign.independent("optimized", placement, result.kappa, search=result),
                   objective="kappa")
