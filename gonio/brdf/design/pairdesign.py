"""What a pair design is: the result type every design path returns, and what it needs.

:class:`PairDesign` is a rig geometry with its quality numbers, made by
:func:`gonio.brdf.design.pairs.design_pairs` (either objective),
:func:`~gonio.brdf.design.pairs.geometry_design` (presets and rig configs) and
:mod:`gonio.brdf.design.product`; :class:`GreedyStats` records what the expected-error choice
did; :class:`BasisLike` is what a design needs from a basis.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal, Protocol, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.advice import AdvisedError
from gonio.brdf.design.placement import Placement
from gonio.brdf.design.search import SearchResult

FloatArray = NDArray[np.float64]

#: What :func:`gonio.brdf.design.pairs.design_pairs` minimises: the joint fit's expected error
#: on the headline metric (:mod:`gonio.brdf.design.posterior`) or V&F's condition number
#: (:func:`gonio.brdf.design.search.optimize_rows`).
Objective = Literal["kappa", "posterior"]
#: Every objective, in the order the CLI and API list them.
OBJECTIVES: tuple[Objective, ...] = get_args(Objective)


class BasisLike(Protocol):
    """What a design needs from a basis (:class:`gonio.brdf.reconstruction.basis.Basis` fits)."""

    @property
    def Q(self) -> FloatArray: ...

    @property
    def valid(self) -> NDArray[np.bool_]: ...

    def rows_at(self, th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> FloatArray: ...


@dataclass(frozen=True)
class GreedyStats:
    """What the expected-error design did (:func:`gonio.brdf.design.posterior.posterior_design`).

    Attributes
    ----------
    candidates : int
        Feasible cells scored at each step.
    evaluations : int
        Candidate scorings over all steps (``n x candidates``).
    mount_checks : int
        Placements tried to keep every choice mountable (0 when devices cannot collide).
    first : int
        Rank of the first pair among the single-pair gains (0: the best; a seed > 0 starts
        from a lesser one, so several seeds give different candidate designs).
    seconds : float
        Wall time of the choice and placement.
    """

    candidates: int
    evaluations: int
    mount_checks: int
    first: int
    seconds: float


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
        Statistics of the condition-number search, for designs it made.
    objective : {"kappa", "posterior"} or None
        The objective that chose the cells (None for presets, rig configs and product rigs).
    expected_log_rmse : float or None
        The joint fit's expected log_rmse for a scan of ``rotations`` uniform stage angles,
        under the basis' learnt prior (:func:`gonio.brdf.design.posterior.design_expected_log_rmse`:
        the error the readings leave inside the basis; what the basis cannot represent is not
        in it). None when the basis is not a gonio ``Basis``.
    rotations : int or None
        Stage angles ``expected_log_rmse`` assumes.
    span_deg : float or None
        The arc (degrees, 180 or 360) those angles cover.
    greedy : GreedyStats or None
        Statistics of the expected-error choice, for designs it made.
    colour_pairs : int
        How many of the pairs (the first ones) sit at colour geometries asked for
        (:mod:`gonio.brdf.design.colourtargets`); 0 when no colour was asked for.
    cell_mix : float
        The share of a second weighting of the grid's cells (the standard renderings' pixel
        counts by default) in the expected-error objective that chose the pairs
        (:func:`gonio.brdf.design.posterior.posterior_design`); 0 for an unweighted design,
        a preset or a design the condition-number search made.
    fallback : str or None
        Why the design was not made by the objective asked for (e.g. the expected-error
        choice could not be mounted on a crowded rig and the condition-number search, which
        plans mounts as it goes, made it instead); None when it was. Settings named in it
        use the core's words (``min_device_distance_deg``); :meth:`fallback_for` words them as
        a caller does.
    fallback_error : AdvisedError or None
        The error that made the fallback, when it was one (its advice is a template of
        settings); not part of the design's value (not compared).
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
    objective: Objective | None = None
    expected_log_rmse: float | None = None
    rotations: int | None = None
    span_deg: float | None = None
    greedy: GreedyStats | None = None
    fallback: str | None = None
    colour_pairs: int = 0
    cell_mix: float = 0.0
    fallback_error: AdvisedError | None = field(default=None, compare=False, repr=False)

    def fallback_for(self, names: Mapping[str, str]) -> str | None:
        """:attr:`fallback` with the settings its advice names worded as in ``names`` (e.g. the
        CLI's flags: ``min_device_distance_deg`` -> ``--min-device-distance``)."""
        if self.fallback is None or self.fallback_error is None:
            return self.fallback
        core = str(self.fallback_error)
        return self.fallback.replace(core, self.fallback_error.advise(names))

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
