"""The posterior rule of adaptive plans: a running job's readings to its next stage angles.

The engine knows devices and steps, not the basis; :class:`PosteriorRefiner` (a
:class:`gonio.plans.rounds.Refiner`) is what the worker hands it (``ScanEngine(refiner=...)``,
for the plan's :class:`gonio.plans.rounds.AdaptiveRounds`) so that
``AdaptivePlan(rule="posterior")`` can ask
:func:`gonio.brdf.reconstruction.posterior.next_angles` where the next angles go, with the drop
of the self-estimated error as its measure (the job's readings are fitted as the job would
finish, and the fit's witnesses passed as ``cv_sample_error`` and ``mahalanobis``) and a
per-pair offset in the planning posterior (``offset="scan"``). It
turns the pairs' lab directions into slice cells once, applies the rig's calibration to the
``raw - dark`` counts (:meth:`gonio.calibration.Calibration.apply`, as the finishing's
samples: the posterior weighs errors at BRDF values in 1/sr), and takes the basis
from its provider on first use (the worker loads it before the job's first reading and hands
it over loaded, so no round waits for a build). A round adds at most one angle per gap, a
midpoint (``per_gap=1``, the default candidates of ``next_angles``) of a gap within the
plan's arc (``arc_deg``: over half a turn the gaps are those modulo 180 and the new angles stay
in the half turn), so the dry run's bound on an adaptive job holds; the plan's
``max_rotations`` reaches the rule as the round's ``budget_angles``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from gonio.calibration import Calibration
from gonio.hal import PairSpec
from gonio.plans.rounds import RoundRequest
from gonio.rigdescription import RigDescription


class PosteriorRefiner:
    """The posterior rule as a :class:`gonio.plans.rounds.Refiner`.

    Parameters
    ----------
    basis_provider : callable returning the reconstruction basis (called once, on first use)
    rig : RigDescription
    pairs : the job's pairs, in the order of the engine's value rows
    calibration : factors applied to ``raw - dark`` (default: none)
    """

    def __init__(self, basis_provider: Callable[[], Any], rig: RigDescription,
                 pairs: Sequence[PairSpec], calibration: Calibration | None = None) -> None:
        from gonio.brdf.reconstruction.reconstruct import pair_cells

        self._basis_provider = basis_provider
        self._basis: Any = None
        self.pairs = list(pairs)
        light, sensor = rig.pair_directions(self.pairs)
        self.cells, self.ph_lab = pair_cells(light, sensor)
        self.calibration = calibration or Calibration()
        self.last: Any = None  # the last RefinementStep, for the job's event log

    def next_angles(self, request: RoundRequest) -> list[float]:
        """New stage angles (degrees, sorted); empty when the rule says stop.

        ``request`` (:class:`gonio.plans.rounds.RoundRequest`): the measured angles, their
        ``raw - dark`` counts ``(n_pairs, r, C)`` with rows in the order of ``pairs``, the
        budget, step and gain of ``next_angles``, and the plan's arc ``(start_deg, span_deg)``
        (new angles are gap midpoints within the span: ``next_angles``' ``arc_start_deg``,
        ``period_deg``).
        """
        from gonio.brdf.reconstruction.posterior import REFINE_OFFSET, next_angles
        from gonio.brdf.reconstruction.reconstruct import reconstruct

        if self._basis is None:
            self._basis = self._basis_provider()
        angles_deg, arc_deg = request.angles_deg, request.arc_deg
        # Small negative noise after the dark is clipped, as the finishing clips its samples.
        v = np.maximum(self.calibration.apply(request.values, self.pairs), 0.0)
        # The fit the job would finish with now: its table is the posterior's mean, and its
        # witnesses (leave-one-pair-out error, Mahalanobis norm) tell the rule how much of the
        # error the basis cannot represent (more angles do not lower that part). The planning
        # posterior also gives each pair an offset that stays the same at every stage angle,
        # sized by the scan (docs/science.md 7.3).
        rec = reconstruct(self._basis, self.cells, self.ph_lab,
                          np.deg2rad(np.asarray(angles_deg, dtype=float)), v,
                          channels=[f"c{k}" for k in range(v.shape[2])],  # any sensor's count
                          # The rule was tuned on the library prior's fits; the local prior is
                          # the finishing fit's choice (docs/science.md 7.2.3).
                          local=None)
        cv = rec.cv_sample_error if np.isfinite(rec.cv_sample_error) else None
        self.last = next_angles(self._basis, self.cells, self.ph_lab, list(angles_deg), v,
                                threshold=request.min_gain,
                                min_step_deg=request.min_step_deg,
                                budget_angles=request.budget_angles, per_gap=1,
                                table=rec.table.values, period_deg=arc_deg[1],
                                arc_start_deg=arc_deg[0], cv_sample_error=cv,
                                mahalanobis=rec.mahalanobis, offset=REFINE_OFFSET)
        return list(self.last.angles_deg)

    def describe(self) -> dict[str, float]:
        """What the last call saw, for the job's ``adaptive_round`` / ``adaptive_done``
        events: the scan's anisotropy factor ``rho``, the per-pair offset (fraction of its
        unit, 0: none), the posterior's expected ``log_rmse`` and the last candidate's drop
        (the one that stopped the rule when nothing was planned); empty before any call."""
        if self.last is None:
            return {}
        out = {"rho": float(self.last.rho), "offset": float(self.last.offset),
               "expected_log_rmse": float(self.last.expected_log_rmse)}
        if np.isfinite(self.last.best_drop):
            out["best_drop"] = float(self.last.best_drop)
        return {k: round(v, 8) for k, v in out.items()}
