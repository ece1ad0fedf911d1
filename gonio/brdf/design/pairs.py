"""Pair designs: ``n`` independent light/sensor pairs from a basis, and their result type.

:func:`design_pairs` optimizes the pairs' cells (:func:`~gonio.brdf.design.search.optimize_rows`)
and places them in the lab; :func:`geometry_design` evaluates a given geometry (a preset or a
rig config) the same way. Both return a :class:`PairDesign`, as product rigs do
(:mod:`gonio.brdf.design.product`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.conditioning import KappaMethod, condition_number
from gonio.brdf.design.constraints import (
    RigConstraints,
    candidate_rows,
    min_pairwise_distance,
    rows_to_cells,
)
from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.mounting import MountPlanner
from gonio.brdf.design.placement import Placement, place_pairs
from gonio.brdf.design.search import SearchResult, optimize_rows
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

#: What :func:`design_pairs` minimises: the joint fit's expected error on the headline metric
#: (:mod:`gonio.brdf.design.posterior`) or V&F's condition number (:func:`optimize_rows`).
Objective = Literal["posterior", "kappa"]


class BasisLike(Protocol):
    """What a design needs from a basis (:class:`gonio.brdf.reconstruction.basis.Basis` fits)."""

    @property
    def Q(self) -> FloatArray: ...

    @property
    def valid(self) -> NDArray[np.bool_]: ...

    def rows_at(self, th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> FloatArray: ...


@dataclass(frozen=True)
class PairDesign:
    """A rig geometry: which pairs are measured, where their devices sit, how well it conditions.

    Attributes
    ----------
    name : str
        ``optimized``, ``product``, or a preset name.
    cells : (n, 3) array, radians
        ``(th, td, pd)`` of each measured pair.
    ph_lab : (n,) array, radians
        Lab half-vector azimuth of each pair.
    lights_deg, sensors_deg : (L, 2), (S, 2) arrays, degrees
        ``(theta, phi)`` lab directions of the devices.
    pairs : (n, 2) int array
        ``(light index, sensor index)`` of each measured pair, in the order of ``cells``.
    kappa : float
        Condition number of the pairs' basis rows over the first ``min(n, K)`` columns.
    min_distance_deg : float
        Smallest angle between two mounted devices.
    search : SearchResult or None
        Search statistics for optimized pair designs.
    """

    name: str
    cells: FloatArray
    ph_lab: FloatArray
    lights_deg: FloatArray
    sensors_deg: FloatArray
    pairs: NDArray[np.intp]
    kappa: float
    min_distance_deg: float
    search: SearchResult | None = None

    @classmethod
    def independent(cls, name: str, placement: Placement, kappa: float,
                    search: SearchResult | None = None) -> PairDesign:
        """A design of independent pairs (each light with its own sensor) at ``placement``."""
        n = placement.cells.shape[0]
        return cls(
            name=name,
            cells=placement.cells,
            ph_lab=placement.ph_lab,
            lights_deg=placement.lab_deg[:, :2],
            sensors_deg=placement.lab_deg[:, 2:],
            pairs=np.stack([np.arange(n), np.arange(n)], axis=1).astype(np.intp),
            kappa=kappa,
            min_distance_deg=placement.min_distance_deg,
            search=search,
        )

    @property
    def n_pairs(self) -> int:
        return int(self.cells.shape[0])

    @property
    def lab_deg(self) -> FloatArray:
        """(n, 4) ``(theta_i, phi_i, theta_v, phi_v)`` degrees of each pair."""
        return np.concatenate(
            [self.lights_deg[self.pairs[:, 0]], self.sensors_deg[self.pairs[:, 1]]], axis=1
        )


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
    objective: Objective = "kappa",
    rotations: int = 8,
) -> PairDesign:
    """Optimize ``n`` independent light/sensor pairs and place them in the lab.

    ``objective="kappa"`` (the default) is V&F's condition-number search, below.
    ``objective="posterior"`` picks the pairs that minimise the joint fit's expected error
    for a scan of ``rotations`` uniform stage angles
    (:func:`gonio.brdf.design.posterior.posterior_design`; ``basis`` must then be a
    :class:`~gonio.brdf.reconstruction.basis.Basis`; ``h``, ``starts``, ``descents``,
    ``method`` and ``time_limit_s`` do not apply, and the choice does not plan mounts, so
    crowded rigs may fail to place where the search succeeds). On measured materials held out
    of the basis it gave a lower error than the search, on anisotropic ones not
    (``docs/science.md`` 7.2).

    Candidates are the basis's valid cells that ``constraints`` allow
    (:func:`gonio.brdf.design.constraints.candidate_rows`). The search is :func:`optimize_rows` with
    a :class:`~gonio.brdf.design.mounting.MountPlanner`, so every design it visits can be mounted
    with ``min_device_distance_deg`` between any two devices and outside every exclusion. The
    search's placement is then spread by :func:`gonio.brdf.design.placement.place_pairs` (it keeps
    the limit and widens the closest gap where it can).

    Raises
    ------
    DesignError
        For ``n < 1`` or more pairs than feasible cells.
    FeasibilityError
        When no cell is feasible, or ``n`` pairs cannot be mounted under ``constraints``.
    """
    if n < 1:
        raise DesignError(f"the number of pairs must be at least 1, got {n}")
    if objective == "posterior":
        from gonio.brdf.design.posterior import posterior_design  # it builds on this module
        from gonio.brdf.reconstruction.basis import Basis

        if not isinstance(basis, Basis):
            raise DesignError(
                "objective='posterior' needs a gonio Basis (its medians and prior); "
                "pass objective='kappa' for other row sources"
            )
        return posterior_design(basis, n, constraints, rotations=rotations,
                                seed=0 if seed is None else seed)
    if objective != "kappa":
        raise DesignError(f"objective must be 'posterior' or 'kappa', not {objective!r}")
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
    return PairDesign.independent("optimized", placement, result.kappa, search=result)
