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

The rule plans with the basis the job will finish with (the round's ``basis``): after an
auto-arc plan's test calls its specimen not twofold symmetric, finishing reconstructs with the
basis whose prior along ``ph`` holds odd harmonics (:mod:`gonio.finishing`), so the refinement
over the full turn plans with that basis' posterior too (``asymmetric_provider``), not with the
default one, which cannot tell a reading at ``a + 180`` from one at ``a`` (docs/science.md 7.4).
Which basis a round used is in :meth:`PosteriorRefiner.describe`, hence in the job's events.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

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
    asymmetric_provider : callable returning the basis for specimens without twofold symmetry,
        or None when it is not at hand without a build (optional; called once it returns a
        basis, on the first round that asks for it). Without one, or when it returns None or
        raises, such rounds plan with the default basis and :meth:`describe` says why.
    """

    def __init__(self, basis_provider: Callable[[], Any], rig: RigDescription,
                 pairs: Sequence[PairSpec], calibration: Calibration | None = None,
                 asymmetric_provider: Callable[[], Any] | None = None) -> None:
        from gonio.brdf.reconstruction.reconstruct import pair_cells

        light, sensor = rig.pair_directions(list(pairs))
        cells, ph_lab = pair_cells(light, sensor)
        self._setup(basis_provider, cells, ph_lab, list(pairs), calibration or Calibration(),
                    asymmetric_provider)

    @classmethod
    def for_cells(cls, basis_provider: Callable[[], Any], cells: NDArray[np.float64],
                  ph_lab: NDArray[np.float64],
                  asymmetric_provider: Callable[[], Any] | None = None) -> PosteriorRefiner:
        """The same rule on pairs given as slice cells and lab azimuths
        (:func:`gonio.brdf.reconstruction.reconstruct.pair_cells`), readings already in
        1/sr: what a benchmark without a rig description plans with."""
        self = cls.__new__(cls)
        self._setup(basis_provider, cells, ph_lab, [], Calibration(), asymmetric_provider)
        return self

    def _setup(self, basis_provider: Callable[[], Any], cells: NDArray[np.float64],
               ph_lab: NDArray[np.float64], pairs: list[PairSpec], calibration: Calibration,
               asymmetric_provider: Callable[[], Any] | None) -> None:
        self._basis_provider = basis_provider
        self._basis: Any = None
        self._asymmetric_provider = asymmetric_provider
        self._asym: Any = None
        self.pairs = pairs
        self.cells, self.ph_lab = cells, ph_lab
        self.calibration = calibration
        self.last: Any = None  # the last RefinementStep, for the job's event log
        # Which basis the last call planned with ("default" or "asymmetric") and, when a
        # round asked for the asymmetric one and did not get it, why.
        self.basis_used: str | None = None
        self.basis_note: str | None = None

    def _planning_basis(self, wanted: str) -> Any:
        """The basis a round asking for ``wanted`` plans with (sets :attr:`basis_used` and
        :attr:`basis_note`): the asymmetric one when asked for and at hand, else the default
        (finishing's choice, :func:`gonio.finishing._basis_for_test`, in the same order)."""
        if self._basis is None:
            self._basis = self._basis_provider()
        self.basis_used, self.basis_note = "default", None
        if wanted != "asymmetric":
            return self._basis
        if not getattr(self._basis, "half_turn_periodic", True):
            self.basis_note = ("the default basis already holds odd harmonics along the "
                               "specimen's rotation")
            return self._basis
        if self._asym is None and self._asymmetric_provider is not None:
            try:
                self._asym = self._asymmetric_provider()
            except Exception as exc:  # the scan goes on with the default basis' posterior
                self.basis_note = ("the basis for specimens without twofold symmetry could "
                                   f"not be had ({type(exc).__name__}: {exc})")[:300]
                return self._basis
        if self._asym is None:
            self.basis_note = (
                "the basis for specimens without twofold symmetry is not at hand (not built "
                "yet on this install, or none in this process): planned with the default "
                "basis' posterior; finishing builds it" if self._asymmetric_provider is not None
                else "no basis for specimens without twofold symmetry in this process")
            return self._basis
        self.basis_used = "asymmetric"
        return self._asym

    def next_angles(self, request: RoundRequest) -> list[float]:
        """New stage angles (degrees, sorted); empty when the rule says stop.

        ``request`` (:class:`gonio.plans.rounds.RoundRequest`): the measured angles, their
        ``raw - dark`` counts ``(n_pairs, r, C)`` with rows in the order of ``pairs``, the
        budget, step and gain of ``next_angles``, and the plan's arc ``(start_deg, span_deg)``
        (new angles are gap midpoints within the span: ``next_angles``' ``arc_start_deg``,
        ``period_deg``) and the basis the job will finish with (``basis``: the asymmetric
        one after an auto-arc test called the specimen not twofold symmetric).
        """
        from gonio.brdf.reconstruction.posterior import REFINE_OFFSET, next_angles
        from gonio.brdf.reconstruction.reconstruct import reconstruct

        basis = self._planning_basis(request.basis)
        angles_deg, arc_deg = request.angles_deg, request.arc_deg
        # Small negative noise after the dark is clipped, as the finishing clips its samples.
        v = np.maximum(self.calibration.apply(request.values, self.pairs), 0.0)
        # The fit the job would finish with now: its table is the posterior's mean, and its
        # witnesses (leave-one-pair-out error, Mahalanobis norm) tell the rule how much of the
        # error the basis cannot represent (more angles do not lower that part). The planning
        # posterior also gives each pair an offset that stays the same at every stage angle,
        # sized by the scan (docs/science.md 7.3).
        rec = reconstruct(basis, self.cells, self.ph_lab,
                          np.deg2rad(np.asarray(angles_deg, dtype=float)), v,
                          channels=[f"c{k}" for k in range(v.shape[2])],  # any sensor's count
                          # The rule was tuned on the library prior's fits; the local prior is
                          # the finishing fit's choice (docs/science.md 7.2.3).
                          local=None)
        cv = rec.cv_sample_error if np.isfinite(rec.cv_sample_error) else None
        self.last = next_angles(basis, self.cells, self.ph_lab, list(angles_deg), v,
                                threshold=request.min_gain,
                                min_step_deg=request.min_step_deg,
                                budget_angles=request.budget_angles, per_gap=1,
                                table=rec.table.values, period_deg=arc_deg[1],
                                arc_start_deg=arc_deg[0], cv_sample_error=cv,
                                mahalanobis=rec.mahalanobis, offset=REFINE_OFFSET)
        return list(self.last.angles_deg)

    def describe(self) -> dict[str, Any]:
        """What the last call saw, for the job's ``adaptive_round`` / ``adaptive_done``
        events: the basis it planned with (``basis``: ``"default"`` or ``"asymmetric"``, and
        ``basis_note`` when a round asked for the asymmetric one and planned with the default),
        the scan's anisotropy factor ``rho``, the per-pair offset (fraction of its unit, 0:
        none), the posterior's expected ``log_rmse`` and the last candidate's drop (the one
        that stopped the rule when nothing was planned); empty before any call."""
        if self.last is None:
            return {}
        out = {"rho": float(self.last.rho), "offset": float(self.last.offset),
               "expected_log_rmse": float(self.last.expected_log_rmse)}
        if np.isfinite(self.last.best_drop):
            out["best_drop"] = float(self.last.best_drop)
        said: dict[str, Any] = {"basis": self.basis_used}
        if self.basis_note is not None:
            said["basis_note"] = self.basis_note
        return {**said, **{k: round(v, 8) for k, v in out.items()}}
