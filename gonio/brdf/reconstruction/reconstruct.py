"""Reconstruction of a full anisotropic BRDF from sparse rotation-stage samples (math.md 5-6).

Input: ``n`` fixed light/sensor pairs, each one cell ``(th, td, pd)`` of the isotropic slice
with its lab half-vector azimuth ``ph_lab``, read at ``r`` stage angles. Pair ``q`` at stage
angle ``alpha`` sees slice ``ph = ph_lab[q] - alpha``.

Two methods. The default, ``method="joint"`` (math.md 6, :func:`solve_joint`), keeps every
reading at its own ``ph`` and couples the slices through a prior along ``ph`` learnt from the
training library (:attr:`Basis.ph_prior`): one ``(n r) x (n r)`` solve for all channels, with
Eq. 5's specular condition in the prior of the varying part. ``method="vf"`` is V&F's path,
steps 1-5 below, kept for comparison.

1. Each pair's ``r`` values are resampled onto the 72 grid ``ph`` by periodic PCHIP (the samples
   are padded with copies shifted by +-2 pi, since scipy's periodic extrapolation only wraps
   the query point).
2. The ``n x 72`` values are remapped with the basis' ``f_med``, ``w`` and ``mu`` at the pairs.
3. Per channel, the coefficients ``C (K x 72)`` minimise V&F Eq. 5::

       E(C) = ||Y~ - Q~ C||^2 + eta ||C||^2 + lam ||Qs C M||^2,   M = I - J/72

   with ``Q~`` the basis rows at the pairs and ``Qs`` the valid ``th = 0`` rows. Because every
   column uses the same rows and ``M`` removes the column mean, the minimiser has a closed
   form: with ``Y~ = ybar 1^T + Yp``,
   ``(Q~^T Q~ + eta I) cbar = Q~^T ybar`` and ``(Q~^T Q~ + eta I + lam Qs^T Qs) Cp = Q~^T Yp``,
   ``C = cbar 1^T + Cp`` (``solver="closed"``, the default). ``solver="iterative"`` runs the
   paper's quasi-Newton search (L-BFGS from the Eq. 4 solution) as a reference.
4. ``X = Q C + mu`` is mapped back to BRDF values and clamped at 0.
5. Self-estimated error. V&F Sec. 5 scale the mean relative error at the measured samples by
   0.8 (``rel_sample_error``, ``estimated_error``). With K > n the regularised fit nearly
   interpolates the samples, so that number says little about the error elsewhere. gonio
   therefore also runs leave-one-pair-out cross-validation: each pair is predicted from a
   refit without it (exact, from the hat-matrix diagonals of the two ridge systems, no
   refits), and the mean relative error of those predictions at the pair's samples
   (``cv_sample_error``) times a factor calibrated per number of pairs
   (:func:`cv_error_scale`) is the reported estimate of the whole-BRDF MAPE
   (``predicted_error``).

The pieces live in modules of their own, below this one: the joint fit's prior and solve
(:mod:`.joint`), its posterior and the scan's own anisotropy (:mod:`.posterior`), the
mirror-symmetry option (:mod:`.mirror`), the self-estimate (:mod:`.selfcheck`) and step 4, the
table from the coefficients (:mod:`.tabulate`). This module checks the inputs, runs V&F's path
and puts the result together.

Speed: the table of step 4 (C x 72 x 11,664 values) dominates the call, so it is computed at
the valid rows only (:func:`.tabulate.expand_table`) and handed to :meth:`BRDFTable.trusted`
without a re-validation pass, once per call: the scan's posterior, which chooses the prior
factor before the final fit, reads only every third slice of the first fit's table, so only
those are expanded for it (a spectral sensor's 31 bands made the two full expansions of
earlier versions most of the call). All channels share one factorisation of the joint system.
BLAS runs on one thread during the call
(:func:`.blas.one_blas_thread`): the products are small, and on a shared machine OpenBLAS'
spinning worker threads cost far more than they save.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.highlightread import HighlightRead, highlight_read
from gonio.brdf.reconstruction.basis import (
    Basis,
    BasisError,
    inverse_remap,
    remap,
)
from gonio.brdf.reconstruction.blas import one_blas_thread
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.joint import (
    JOINT_ETA,
    JOINT_LAM,
    SCAN_RHO_MAX,
    joint_prior,
    solve_joint,
)
from gonio.brdf.reconstruction.localprior import choose_local_prior, local_prior_skipped
from gonio.brdf.reconstruction.mirror import MirrorModel, mirror_cells
from gonio.brdf.reconstruction.periodic import arc_gaps, periodic_pchip_rows
from gonio.brdf.reconstruction.posterior import (
    WEIGHT_SLICE_STEP,
    ScanPosterior,
    harmonic_scale,
)
from gonio.brdf.reconstruction.selfcheck import (
    BasisMisfit,
    basis_misfit,
    final_log_rmse,
    predict_joint_log_rmse,
    predict_vf_log_rmse,
    upper_log_rmse,
    widen_log_rmse,
)
from gonio.brdf.reconstruction.tabulate import expand_table
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.bounds import peak_excess_log_rmse
from gonio.brdf.tables.table import TH0_ROWS, VALID_MASK, BRDFTable

FloatArray = NDArray[np.float64]
Solver = Literal["closed", "iterative"]
Method = Literal["joint", "vf"]
#: ``reconstruct``'s ``rho``: a factor on the prior's varying harmonics, a pair of factors
#: (harmonics ``0 < m <= BAND_SPLIT`` and above), ``"scan"``, ``"scan-bands"`` or None.
Rho = float | tuple[float, float] | Literal["scan", "scan-bands"] | None

#: V&F Sec. 5: the whole-BRDF error is about 0.8 x the mean relative error at the samples.
ERROR_SCALE = 0.8
#: Samples darker than this fraction of the mean sample value are compared against that floor
#: in the relative sample error, so near-black readings cannot dominate the mean.
REL_ERROR_FLOOR = 0.01
#: ``predicted_error = s(n) * cv_sample_error`` with ``s`` from these ``(n_pairs, s)`` points,
#: interpolated linearly in ``log n`` and held constant outside them (:func:`cv_error_scale`).
#: The whole-BRDF MAPE differs from the leave-one-pair-out error at the samples because most of
#: the BRDF (grazing cells above all) is far from every pair, and by how much depends on how
#: densely the pairs cover the domain. Each ``s`` is the geometric median of
#: ``MAPE / cv_sample_error`` over 14 library materials held out of the basis, pooled over
#: two pair layouts (the demo's grid rule and ``design_pairs``), 1 % noise, r = 4-24
#: (``bench/bench_error_estimate.py``; validation in ``docs/science.md``: expect the truth
#: within a factor of 2 in about 40 % of scans, and far above the estimate for materials the
#: basis cannot represent).
CV_ERROR_SCALES: tuple[tuple[int, float], ...] = ((5, 0.325), (10, 0.757), (20, 1.239))

@dataclass(frozen=True)
class Reconstruction:
    """Result of :func:`reconstruct`.

    Parameters
    ----------
    table : BRDFTable
        The reconstructed BRDF, (C, 72, 18, 18, 36), 1/sr.
    coefficients : (C, K, 72) float64
        Basis coefficients per channel and ``ph`` slice.
    rel_sample_error : float
        Mean relative error of the reconstruction at the measured samples (a fraction).
    estimated_error : float
        ``0.8 * rel_sample_error``: V&F's estimate of the mean relative error over the BRDF.
        Kept for comparison; it underestimates the whole-BRDF error many times over when
        K > n (``docs/science.md``). Prefer ``predicted_error``.
    settings : dict
        Solver settings and sizes (K, n, r, eta, lam, solver, seconds).
    cv_sample_error : float
        Leave-one-pair-out error: mean relative error at each pair's samples of the
        reconstruction fitted without that pair (a fraction). NaN when it is undefined (a
        pair that the others cannot predict at all, e.g. ``eta = 0`` with ``n <= K``).
    predicted_error : float
        ``cv_error_scale(n) * cv_sample_error``: the calibrated estimate of the volume-weighted
        MAPE over the whole BRDF (a fraction).
    cv_log_error : float
        Leave-one-pair-out error in the units of ``log_rmse``: root mean square over the
        readings of ``ln(1 + f_loo cos ti) - ln(1 + f cos ti)``. NaN when undefined.
    cv_log_under : float
        The part of ``cv_log_error`` where a reading is above what the other pairs predict:
        root mean square over the readings of ``max(0, ln(1 + f cos ti) - ln(1 + f_loo cos
        ti))`` (same units; at most ``cv_log_error``). A pair far brighter than the rest of
        the scan predicts, e.g. one reading a mirror peak the others never see, shows here;
        ``cv_sample_error``, a relative error, cannot exceed 1 for such a pair. NaN when
        undefined. A witness of the self-estimate since 2026-11-28 (its under-prediction
        term, :func:`gonio.brdf.reconstruction.selfcheck.under_term`; docs/science.md 7.1.1).
    predicted_log_rmse : float
        The estimated ``metrics.log_rmse`` of the whole reconstruction against the true
        BRDF, calibrated on materials held out of the basis; the number to report. Joint
        fit: :func:`gonio.brdf.reconstruction.selfcheck.predict_joint_log_rmse` through the final
        mapping :func:`gonio.brdf.reconstruction.selfcheck.final_log_rmse` (a coverage term;
        a highlight term of ``highlight_excess``; an under-prediction term of
        ``cv_log_under``; its own factor and a floor at the misfit
        when the readings show structure the basis cannot hold, ``misfit``); V&F path:
        :func:`gonio.brdf.reconstruction.selfcheck.predict_vf_log_rmse`, widened by such a misfit.
    angle_log_errors : (r,) float64 or None
        Joint fit only: per stage angle (in the order given), the RMS log error (units of
        ``log_rmse``) of that angle's readings predicted from all the other angles. Where it
        is large the material changes faster along ``ph`` than the scan resolves: the basis
        of adaptive refinement (:func:`refine_angles`).
    pair_log_errors : (n,) float64 or None
        Per pair, the RMS log error of its readings predicted without it (the terms of
        ``cv_log_error``); a pair far above the others sits where the basis extrapolates.
    expected_log_rmse : float
        Joint fit only (else NaN): the error the fit's own posterior expects over the whole
        table, weighted as ``log_rmse`` weighs errors
        (:attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.expected_log_rmse`); one
        input of ``predicted_log_rmse`` (:mod:`gonio.brdf.reconstruction.selfcheck`). It cannot
        see what the basis cannot represent.
    mahalanobis : float
        Joint fit only (else NaN): squared Mahalanobis norm of the fitted readings under the
        fit's prior, per pair and channel
        (:attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.mahalanobis`). Large when the
        material sits far from the training library; the witness of what the basis cannot
        represent in ``predicted_log_rmse``.
    misfit : BasisMisfit or None
        How far the fit misses its own readings against their noise, and whether that misfit
        stays across the stage angles
        (:func:`gonio.brdf.reconstruction.selfcheck.basis_misfit`). When it is flagged
        (``misfit.flagged``) the basis cannot hold the material and ``predicted_log_rmse`` is
        never below the misfit
        (:func:`gonio.brdf.reconstruction.selfcheck.final_log_rmse`);
        ``misfit.message(...)`` says why.
    predicted_log_rmse_unwidened : float
        The calibrated model's estimate before the final mapping
        (:func:`gonio.brdf.reconstruction.selfcheck.predict_joint_log_rmse` or, on V&F's path,
        :func:`gonio.brdf.reconstruction.selfcheck.predict_vf_log_rmse`).
    uncovered_share : float
        Joint fit only (else NaN): the share of the prior's ``log_rmse``-weighted variance
        the readings leave (0..1; :meth:`gonio.brdf.reconstruction.posterior.ScanPosterior.
        uncovered_share`), the coverage witness of ``predicted_log_rmse``.
    predicted_log_rmse_upper : float
        Joint fit only (else NaN): the upper end of the self-estimate's interval
        (:func:`gonio.brdf.reconstruction.selfcheck.upper_log_rmse`, ``log_rmse`` units): the
        true error of a held-out material was below it on 98 % of the calibration scans;
        ``predicted_log_rmse`` stays the central value.
    peak_excess_log_rmse : float
        The error the table carries above the physical peak bound, ``PEAK_RATIO_LIMIT`` times
        the largest projected reading ``f cos ti cos to``, over each cell's ``cos ti cos to``
        (:func:`gonio.brdf.tables.bounds.peak_excess_log_rmse`,
        ``log_rmse`` units; 0 when nothing is above it, NaN without a positive reading). A
        lower bound of the true error for any material within that bound (an assumption a
        polished specimen no pair reads near its mirror direction can break: docs/science.md
        7.5), so ``predicted_log_rmse`` is never below it.
    highlight_excess : float
        The table's largest projected value ``f cos ti cos to`` at ``td`` up to 45 degrees over
        the largest projected reading (:func:`gonio.brdf.highlightread.highlight_read`,
        dimensionless; NaN without a positive reading). On the joint fit
        ``predicted_log_rmse`` carries a term that grows with its logarithm
        (:func:`gonio.brdf.reconstruction.selfcheck.highlight_term`, docs/science.md 7.1.1).
    highlight : HighlightRead or None
        The whole :func:`gonio.brdf.highlightread.highlight_read` of ``table`` and the
        readings (where the table peaks, how near the nearest reading comes, ``excess``):
        ``gonio/finishing.py`` reports it as it is rather than computing it again. None on
        a Reconstruction made by hand.
    """

    table: BRDFTable
    coefficients: FloatArray
    rel_sample_error: float
    estimated_error: float
    settings: dict[str, Any] = field(default_factory=dict)
    cv_sample_error: float = float("nan")
    predicted_error: float = float("nan")
    cv_log_error: float = float("nan")
    cv_log_under: float = float("nan")
    predicted_log_rmse: float = float("nan")
    angle_log_errors: FloatArray | None = None
    pair_log_errors: FloatArray | None = None
    expected_log_rmse: float = float("nan")
    mahalanobis: float = float("nan")
    misfit: BasisMisfit | None = None
    predicted_log_rmse_unwidened: float = float("nan")
    uncovered_share: float = float("nan")
    predicted_log_rmse_upper: float = float("nan")
    peak_excess_log_rmse: float = float("nan")
    highlight_excess: float = float("nan")
    highlight: HighlightRead | None = None

    @property
    def misfit_warning(self) -> str | None:
        """Why ``predicted_log_rmse`` was widened (None when it was not): the readings carry
        structure the basis cannot hold (:class:`gonio.brdf.reconstruction.selfcheck.BasisMisfit`,
        :meth:`~gonio.brdf.reconstruction.selfcheck.BasisMisfit.message`)."""
        if self.misfit is None:
            return None
        floored = bool(np.isfinite(self.peak_excess_log_rmse) and self.peak_excess_log_rmse > 0
                       and self.predicted_log_rmse == self.peak_excess_log_rmse)
        return self.misfit.message(self.predicted_log_rmse_unwidened, self.predicted_log_rmse,
                                   floored)


# ---------------------------------------------------------------------------- geometry helper
def pair_cells(light_dirs: ArrayLike, sensor_dirs: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Slice cells and lab half-vector azimuths of fixed light/sensor pairs.

    Parameters
    ----------
    light_dirs, sensor_dirs : (n, 3) array_like
        Lab-frame unit vectors toward the light and the sensor at stage angle 0.

    Returns
    -------
    cells : (n, 3) float64, radians
        ``(th, td, pd)`` of each pair.
    ph_lab : (n,) float64, radians in [0, 2 pi)
        Half-vector azimuth of each pair in the lab frame.
    """
    li = np.asarray(light_dirs, dtype=float)
    so = np.asarray(sensor_dirs, dtype=float)
    if li.ndim != 2 or li.shape[1] != 3 or li.shape != so.shape:
        raise ReconstructionError(
            f"light and sensor directions must both be (n, 3) arrays; got {li.shape} and "
            f"{so.shape}"
        )
    norms = np.concatenate([np.linalg.norm(li, axis=1), np.linalg.norm(so, axis=1)])
    if not np.isfinite(norms).all() or np.abs(norms - 1.0).max(initial=0.0) > 1e-6:
        raise ReconstructionError("light and sensor directions must be finite unit vectors")
    if (li[:, 2] <= 0).any() or (so[:, 2] <= 0).any():
        raise ReconstructionError(
            "every light and sensor must be above the specimen (positive z component)"
        )
    th, ph, td, pd = geo.directions_to_half_diff(li, so)
    return np.stack([th, td, pd], axis=1), np.asarray(ph, dtype=float)


# ---------------------------------------------------------------------------- step 1
def resample_to_slices(
    ph_lab: FloatArray, stage_angles: FloatArray, values: FloatArray,
    period: float = 2 * np.pi,
) -> FloatArray:
    """Resample each pair's rotation readings onto the 72 grid ``ph`` (math.md 5 step 1).

    Parameters
    ----------
    ph_lab : (n,) radians
    stage_angles : (r,) radians, distinct modulo ``period``
    values : (n, r, C)
    period : float, radians
        The readings' period along the rotation: a full turn, or half a turn for a specimen
        that reads the same turned by half a turn (:func:`half_turn_scan`).

    Returns
    -------
    (n, 72, C)
        Value of slice ``PH_GRID[k]`` at each pair. The stage angle that puts slice ``ph``
        under pair ``q`` is ``ph_lab[q] - ph``, so interpolation runs over stage angle.
    """
    a = np.mod(stage_angles, period)
    order = np.argsort(a)
    return periodic_pchip_rows(
        a[order], values[:, order], np.asarray(ph_lab)[:, None] - geo.PH_GRID[None, :],
        period=period,
    )


def half_turn_scan(stage_angles: ArrayLike) -> bool:
    """Whether the stage angles leave a gap of more than half a turn (a half-turn scan).

    Parameters
    ----------
    stage_angles : (r,) radians

    Returns
    -------
    bool
        True when every angle lies within one half turn, e.g. ``k pi / r``: interpolation along
        the rotation then has to use the half-turn period, or it would bridge the unseen half.
    """
    a = np.asarray(stage_angles, dtype=float)
    if a.size < 2:
        return False
    _, gaps = arc_gaps(np.rad2deg(a))
    return bool(gaps.max() > 180.0 + 1e-7)


def slices_at_stage_angles(
    ph_lab: FloatArray, stage_angles: FloatArray, slices: FloatArray
) -> FloatArray:
    """Inverse of :func:`resample_to_slices`: slice values back at the sampled stage angles.

    Parameters
    ----------
    ph_lab : (n,) radians
    stage_angles : (r,) radians
    slices : (n, 72, C) values of each pair on the 72 grid slices

    Returns
    -------
    (n, r, C)
        Periodic PCHIP over the slices at ``ph = ph_lab[q] - stage_angles``.
    """
    return periodic_pchip_rows(
        geo.PH_GRID, slices, np.asarray(ph_lab)[:, None] - np.asarray(stage_angles)[None, :]
    )


# ---------------------------------------------------------------------------- step 3
def _objective(
    C: FloatArray, Y: FloatArray, Qt: FloatArray, Qs: FloatArray, eta: float, lam: float
) -> float:
    """V&F Eq. 5 for one channel; ``C`` (K, 72), ``Y`` (n, 72)."""
    QsC = Qs @ C
    return float(
        np.sum((Y - Qt @ C) ** 2)
        + eta * np.sum(C**2)
        + lam * np.sum((QsC - QsC.mean(axis=1, keepdims=True)) ** 2)
    )


def solve_closed(
    Y: FloatArray, Qt: FloatArray, Qs: FloatArray, eta: float, lam: float
) -> FloatArray:
    """Exact minimiser of Eq. 5 by the mean/remainder split (module notes).

    Parameters
    ----------
    Y : (n, S, ...) remapped samples on S slices (extra trailing axes are channels)
    Qt : (n, K) basis rows at the pairs
    Qs : (s, K) basis rows constrained to agree across slices
    eta, lam : float

    Returns
    -------
    (K, S, ...) coefficients
    """
    K = Qt.shape[1]
    G = Qt.T @ Qt
    rhs = np.tensordot(Qt.T, Y, axes=1)  # (K, S, ...)
    rbar = rhs.mean(axis=1, keepdims=True)
    A1 = G + eta * np.eye(K)
    A2 = A1 + lam * (Qs.T @ Qs)
    flat = (rhs - rbar).reshape(K, -1)
    try:
        cbar = scipy.linalg.solve(A1, rbar.reshape(K, -1), assume_a="pos")
        Cp = scipy.linalg.solve(A2, flat, assume_a="pos")
    except np.linalg.LinAlgError:
        raise ReconstructionError(
            f"the normal equations are singular ({Qt.shape[0]} pairs for K = {K} components "
            "with eta = 0); use eta > 0, fewer components or more pairs"
        ) from None
    return np.asarray(cbar.reshape(rbar.shape) + Cp.reshape(rhs.shape))


def solve_iterative(
    Y: FloatArray, Qt: FloatArray, Qs: FloatArray, eta: float, lam: float
) -> FloatArray:
    """Minimise Eq. 5 for one channel by L-BFGS from the Eq. 4 solution (V&F's procedure).

    Parameters
    ----------
    Y : (n, S), Qt : (n, K), Qs : (s, K), eta, lam : float

    Returns
    -------
    (K, S) coefficients
    """
    K, S = Qt.shape[1], Y.shape[1]
    G = Qt.T @ Qt
    H = Qs.T @ Qs
    QtY = Qt.T @ Y
    C0 = scipy.linalg.solve(G + eta * np.eye(K), QtY, assume_a="pos")
    const = float(np.sum(Y**2))

    def fun(c: FloatArray) -> tuple[float, FloatArray]:
        C = c.reshape(K, S)
        GC = G @ C
        HC = H @ C
        HCM = HC - HC.mean(axis=1, keepdims=True)
        # Expanded quadratic form: cheaper than forming the residuals, same value.
        f = const - 2 * np.sum(QtY * C) + np.sum(GC * C) + eta * np.sum(C * C) + lam * np.sum(
            HCM * C
        )
        g = 2 * (GC - QtY + eta * C + lam * HCM)
        return float(f), g.ravel()

    res = scipy.optimize.minimize(
        fun, C0.ravel(), jac=True, method="L-BFGS-B",
        options={"maxiter": 20000, "maxcor": 30, "ftol": 1e-16, "gtol": 1e-11},
    )
    return np.asarray(res.x.reshape(K, S))


# ---------------------------------------------------------------------------- step 5
def loo_predictions(
    Y: FloatArray, Qt: FloatArray, Qs: FloatArray, eta: float, lam: float
) -> FloatArray:
    """Leave-one-pair-out predictions of the Eq. 5 fit (exact, without refitting).

    Both halves of the closed form (module notes) are ridge problems ``(Q~^T Q~ + R) c =
    Q~^T y`` over the same pair rows with a data-independent ``R`` (``eta I``, and
    ``eta I + lam Qs^T Qs``). Dropping row ``q`` of such a problem changes its prediction at
    ``q`` from ``y^_q`` to ``y_q - (y_q - y^_q) / (1 - h_q)``, with ``h_q`` the ``q``-th
    diagonal entry of the hat matrix ``Q~ (Q~^T Q~ + R)^-1 Q~^T`` (Sherman-Morrison). The
    mean/remainder split of ``Y~`` is row by row, so a pair's absence leaves the other rows'
    split unchanged and the two corrections simply add.

    Parameters
    ----------
    Y : (n, S, ...) remapped samples on S slices (trailing axes are channels)
    Qt : (n, K) basis rows at the pairs
    Qs : (s, K) basis rows constrained to agree across slices
    eta, lam : float

    Returns
    -------
    (n, S, ...)
        Row ``q``: the remapped values at pair ``q`` predicted by the fit to the other
        ``n - 1`` pairs. All NaN when some pair cannot be left out (``h_q = 1``: the others
        leave its coefficients undetermined, e.g. ``eta = 0`` with ``n <= K``).
    """
    n, K = Qt.shape
    A1 = Qt.T @ Qt + eta * np.eye(K)
    A2 = A1 + lam * (Qs.T @ Qs)
    ybar = Y.mean(axis=1)  # (n, ...)
    Yp = Y - ybar[:, None]
    trailing = (1,) * (Y.ndim - 1)
    loo = Y.copy()
    for A, data, shape in ((A1, ybar, (n, *trailing[1:])), (A2, Yp, (n, *trailing))):
        try:
            cho = scipy.linalg.cho_factor(A)
        except np.linalg.LinAlgError:
            return np.full_like(Y, np.nan)
        h = np.einsum("nk,kn->n", Qt, scipy.linalg.cho_solve(cho, Qt.T))
        if (1.0 - h).min() <= 1e-10:
            return np.full_like(Y, np.nan)
        coef = scipy.linalg.cho_solve(cho, np.tensordot(Qt.T, data, axes=1).reshape(K, -1))
        resid = data - (Qt @ coef).reshape(data.shape)
        corr = resid / (1.0 - h).reshape(shape)
        loo -= corr[:, None] if data.ndim < Y.ndim else corr
    return loo



# ---------------------------------------------------------------------------- validation
def _check_inputs(
    basis: Basis,
    cells: FloatArray,
    ph_lab: FloatArray,
    stage_angles: FloatArray,
    values: FloatArray,
    channels: Sequence[str],
) -> None:
    if basis.Q.shape[0] != geo.N_ROWS or not np.array_equal(basis.valid, VALID_MASK.ravel()):
        raise ReconstructionError(
            "the basis was built on another grid than this gonio's; rebuild it with "
            "`gonio basis build`"
        )
    if cells.ndim != 2 or cells.shape[1] != 3:
        raise ReconstructionError(
            f"cells must be an (n, 3) array of (th, td, pd) in radians, got shape {cells.shape}"
        )
    n = cells.shape[0]
    if n == 0:
        raise ReconstructionError("no light/sensor pairs given: need at least one pair")
    if stage_angles.ndim != 1 or stage_angles.size == 0:
        raise ReconstructionError(
            f"stage_angles must be a non-empty 1-D array of radians, got shape "
            f"{stage_angles.shape}"
        )
    r = stage_angles.size
    if ph_lab.shape != (n,):
        raise ReconstructionError(f"ph_lab has shape {ph_lab.shape}; expected ({n},), one per pair")
    if values.shape != (n, r, len(channels)):
        raise ReconstructionError(
            f"values have shape {values.shape}; expected (pairs, rotations, channels) = "
            f"({n}, {r}, {len(channels)})"
        )
    for nm, arr in (("cells", cells), ("ph_lab", ph_lab), ("stage_angles", stage_angles)):
        if not np.isfinite(arr).all():
            raise ReconstructionError(f"{nm} contain NaN or infinite angles")
    if np.isnan(values).any():
        q, j, _ = np.argwhere(np.isnan(values))[0]
        raise ReconstructionError(
            f"samples contain NaN (first at pair {q}, rotation {j}); re-measure or drop them"
        )
    if not np.isfinite(values).all():
        raise ReconstructionError("samples contain infinite values")
    if (values < 0).any():
        raise ReconstructionError(
            f"samples contain negative BRDF values (min {values.min():.3g} 1/sr); "
            "check the dark subtraction, or clamp small negative noise to 0 before reconstructing"
        )
    a = np.sort(np.mod(stage_angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * np.pi]]))
    if r > 1 and gaps.min() < 1e-9:
        k = int(np.argmin(gaps))
        raise ReconstructionError(
            f"duplicate stage angle {np.rad2deg(a[k]):.4g} deg (angles must be distinct "
            "modulo 360 deg); average repeated readings before reconstructing"
        )


# ---------------------------------------------------------------------------- main entry
def reconstruct(
    basis: Basis,
    cells: ArrayLike,
    ph_lab: ArrayLike,
    stage_angles: ArrayLike,
    values: ArrayLike,
    *,
    channels: Sequence[str] = ("R", "G", "B"),
    eta: float | None = None,
    lam: float | None = None,
    n_components: int | None = None,
    solver: Solver = "closed",
    name: str = "reconstruction",
    method: Method = "joint",
    rho: Rho = "scan",
    symmetry: Literal["scan"] | None = None,
    local: Literal["scan"] | None = "scan",
) -> Reconstruction:
    """Reconstruct the full anisotropic BRDF from ``n`` pairs read at ``r`` stage angles.

    Parameters
    ----------
    basis : Basis
    cells : (n, 3) array_like, radians
        ``(th, td, pd)`` of each pair (see :func:`pair_cells`); off-grid cells use trilinear
        blends of the basis rows.
    ph_lab : (n,) array_like, radians
        Lab half-vector azimuth of each pair at stage angle 0.
    stage_angles : (r,) array_like, radians
        Any order, irregular spacing allowed, distinct modulo 2 pi.
    values : (n, r, C) array_like, 1/sr
        Measured BRDF values, non-negative, no NaN.
    channels : sequence of str, length C
    eta, lam : float, optional
        Regularisation weights of Eq. 5: noise-to-prior ratio and the specular (th = 0)
        condition. Defaults: V&F's 40 and 0.1 for ``method="vf"``, :data:`JOINT_ETA` and
        :data:`JOINT_LAM` for the joint fit.
    n_components : int, optional
        Use only the first K components (default: all of ``basis``).
    solver : {"closed", "iterative"}
        For ``method="vf"``: closed-form minimiser (default) or the L-BFGS reference.
    name : str
        Name of the output table.
    method : {"joint", "vf"}
        ``"joint"`` (default): every reading at its own ``ph`` with the learnt prior along
        ``ph`` (math.md 6, :func:`solve_joint`). ``"vf"``: V&F's path, per-pair periodic PCHIP
        onto the 72 slices, then Eq. 5 (steps 1-3 of the module notes).
    rho : float or "scan" or None
        Joint fit only: a factor on the varying (``m > 0``) harmonics of the prior along
        ``ph``. ``"scan"`` (default): the scan's own factor, chosen by marginal likelihood
        (:attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.rho`), when it is below
        :data:`SCAN_RHO_MAX`: the readings then say the specimen varies less with the stage
        angle than the library's prior expects, and the fit believes them (docs/science.md
        7.3). ``"scan-bands"``: two factors chosen by marginal likelihood, one on the low
        harmonics ``0 < m <= BAND_SPLIT`` (:data:`gonio.brdf.reconstruction.posterior.BAND_SPLIT`)
        and one on the higher ones, used as chosen (docs/science.md 2.1: the spectrum's
        shape). ``None``: the learnt prior as it is; a number: that factor; a pair
        ``(low, high)``: those two factors.
    symmetry : {"scan", None}
        Joint fit only. ``"scan"``: the scan decides by marginal likelihood whether the
        specimen is mirror-symmetric about an axis in its plane, about which axis and how
        strictly (:mod:`gonio.brdf.reconstruction.mirror`); when it is, every reading also
        counts at its mirror cell and azimuth. The leave-one-out and sample errors stay
        those of the fit without the symmetry. ``settings["mirror_axis_deg"]`` (None: no
        symmetry) and ``settings["mirror_slack"]`` say what was chosen. None (default): no
        symmetry assumed.
    local : {"scan", None}
        Joint fit only. ``"scan"`` (default): when the basis holds local priors (the
        measured and user tables folded into it, :attr:`Basis.local_priors`), lean the
        prior's isotropic part on the one the readings favour by marginal likelihood, if any
        does (:mod:`gonio.brdf.reconstruction.localprior`), at least half of the pairs
        read out of the plane of incidence (instrument geometries keep the library's prior)
        and the basis is not the asymmetric default basis (the one a specimen found without
        twofold symmetry is fitted with: the folded-in tables, isotropic measured ones, are
        the least like it);
        ``settings["local_prior"]`` names it (None: the library's prior) and
        ``settings["local_prior_gain"]`` gives its log marginal likelihood gain. None: the
        library's prior only.

    Returns
    -------
    Reconstruction
    """
    with one_blas_thread():
        return _reconstruct(
            basis, cells, ph_lab, stage_angles, values, channels=channels, eta=eta, lam=lam,
            n_components=n_components, solver=solver, name=name, method=method, rho=rho,
            symmetry=symmetry, local=local,
        )


def _reconstruct(
    basis: Basis,
    cells: ArrayLike,
    ph_lab: ArrayLike,
    stage_angles: ArrayLike,
    values: ArrayLike,
    *,
    channels: Sequence[str],
    eta: float | None,
    lam: float | None,
    n_components: int | None,
    solver: Solver,
    name: str,
    method: Method,
    rho: Rho = "scan",
    symmetry: Literal["scan"] | None = None,
    local: Literal["scan"] | None = "scan",
) -> Reconstruction:
    """:func:`reconstruct` without the BLAS thread limit (same parameters)."""
    t0 = time.perf_counter()
    cells_ = np.asarray(cells, dtype=float)
    ph_ = np.asarray(ph_lab, dtype=float)
    alpha = np.asarray(stage_angles, dtype=float)
    vals = np.asarray(values, dtype=float)
    channels = tuple(str(c) for c in channels)
    _check_inputs(basis, cells_, ph_, alpha, vals, channels)
    if solver not in ("closed", "iterative"):
        raise ReconstructionError(f"solver must be 'closed' or 'iterative', not {solver!r}")
    if method not in ("joint", "vf"):
        raise ReconstructionError(f"method must be 'joint' or 'vf', not {method!r}")
    if eta is None:
        eta = JOINT_ETA if method == "joint" else 40.0
    if lam is None:
        lam = JOINT_LAM if method == "joint" else 0.1
    if method == "joint" and not eta > 0:
        raise ReconstructionError(f"the joint fit needs eta > 0 (reading noise), got {eta}")
    if not (eta >= 0 and lam >= 0):
        raise ReconstructionError(f"eta and lam must be >= 0, got eta={eta}, lam={lam}")
    factors = (rho if isinstance(rho, tuple) else (rho, rho)
               if isinstance(rho, int | float) else ())
    if rho not in (None, "scan", "scan-bands") and not (
            len(factors) == 2 and all(isinstance(f, int | float) and np.isfinite(f) and f > 0
                                      for f in factors)):
        raise ReconstructionError(
            f"rho must be a finite number > 0, a pair of them, 'scan', 'scan-bands' or None, "
            f"got {rho!r}")
    if symmetry not in (None, "scan"):
        raise ReconstructionError(f"symmetry must be 'scan' or None, got {symmetry!r}")
    if local not in (None, "scan"):
        raise ReconstructionError(f"local must be 'scan' or None, got {local!r}")
    if n_components is not None:
        try:
            basis = basis.truncated(int(n_components))
        except BasisError as exc:
            raise ReconstructionError(str(exc)) from None
    th, td, pd = cells_.T
    try:
        rows, weights = basis.neighbours(th, td, pd)
    except BasisError as exc:
        raise ReconstructionError(str(exc)) from None
    Qt = np.einsum("nj,njk->nk", weights, basis.Q[rows])
    fmed_t = (weights * basis.f_med[rows]).sum(axis=1)[:, None, None]
    mu_t = (weights * basis.mu[rows]).sum(axis=1)[:, None, None]
    ci, co = geo.cell_cosines(th, td, pd)
    w_t = np.maximum(ci * co, basis.eps)[:, None, None]  # each pair's exact weight, not a blend

    n_ch = len(channels)
    prior_rho = (1.0, 1.0)  # factors on the low / high varying harmonics
    if method == "joint":
        Yr = remap(vals, fmed_t, w_t, basis.eps) - mu_t  # (n, r, C), each reading where taken
        P = joint_prior(basis, lam / eta)

        def joint(factor: tuple[float, float]
                  ) -> tuple[FloatArray, FloatArray, bool, FloatArray | None]:
            """The joint fit with the prior's low / high varying harmonics scaled by
            ``factor``."""

            Pf = P * harmonic_scale(P.shape[0], *factor)[:, None, None]
            jf = solve_joint(Yr, Qt, ph_[:, None] - alpha[None, :], Pf, eta)
            has = bool(np.isfinite(jf.loo).all())
            remapped = np.concatenate([jf.fit, jf.loo], axis=2) if has else jf.fit
            remapped = np.minimum(remapped + mu_t, 300.0)
            at = np.maximum(inverse_remap(remapped, fmed_t, w_t, basis.eps), 0.0)
            if not np.isfinite(jf.loo_angle).all():
                return np.moveaxis(jf.coef, -1, 0), at, has, None
            la = np.maximum(inverse_remap(np.minimum(jf.loo_angle + mu_t, 300.0), fmed_t, w_t,
                                          basis.eps), 0.0)
            d = np.log1p(la * ci[:, None, None]) - np.log1p(vals * ci[:, None, None])
            return np.moveaxis(jf.coef, -1, 0), at, has, np.sqrt(np.mean(d**2, axis=(0, 2)))

        if factors:
            prior_rho = (float(factors[0]), float(factors[1]))
        coef, at_samples, has_cv, angle_err = joint(prior_rho)  # coef (C, K, 72)
        solver_name = "joint"
    else:
        coef, at_samples, has_cv = _vf_path(
            basis, Qt, fmed_t, mu_t, w_t, ph_, alpha, vals, eta, lam, solver, n_ch
        )
        solver_name = solver
        angle_err = None

    mirror_settings: dict[str, Any] = {}
    local_settings: dict[str, Any] = {"local_prior": None} if method == "joint" else {}

    def as_table(coef: FloatArray, factor: tuple[float, float]) -> BRDFTable:
        settings = {"K": basis.K, "n": int(cells_.shape[0]), "r": int(alpha.size),
                    "eta": eta, "lam": lam, "method": method, "solver": solver_name,
                    "basis_materials": len(basis.materials)}
        if method == "joint":
            settings.update(_rho_settings(factor))
            settings.update(mirror_settings)
            settings.update(local_settings)
        return BRDFTable.trusted(expand_table(basis, coef), channels, name, None,
                                 {"reconstruction": settings})

    post: ScanPosterior | None = None
    estimate_post: ScanPosterior | None = None
    if method == "joint" and has_cv:
        # The joint posterior (reconstruction.posterior): the self-estimate's expected error,
        # and the scan's own rho. Its weights read only every third slice of the fit's table,
        # so only those are expanded here; the whole table is expanded once, at the end, from
        # the coefficients finally chosen (with many channels the expansion is most of the
        # call's time).

        by_scan = rho in ("scan", "scan-bands")
        weight_table = expand_table(basis, coef[:, :, ::WEIGHT_SLICE_STEP])
        post = ScanPosterior(basis, cells_, ph_, alpha, vals, table=weight_table,
                             eta=eta, lam=lam, rho=None if by_scan else prior_rho,
                             bands=rho == "scan-bands")
        # The self-estimate's posterior terms (expected error, Mahalanobis norm, coverage)
        # stay the library prior's: its calibration (selfcheck) was made on them, and a local
        # prior the readings favour can still be the wrong material where no pair looks; its
        # leave-one-pair-out error and misfit are the final fit's (docs/science.md 7.2.3).
        estimate_post = post
        why_not = local_prior_skipped(basis, cells_) if local == "scan" else "not asked"
        local_pick = choose_local_prior(post, basis) if why_not is None else None
        if why_not is None:
            why_not = ("leaned" if local_pick is not None
                       else "no folded-in table favoured by strong evidence")
        local_settings["local_prior_note"] = why_not
        if local_pick is not None:
            # The readings favour leaning on a folded-in material: the posterior (and the
            # scan's anisotropy factors) again under that prior, then the fit below.
            P = local_pick.prior
            post = ScanPosterior(basis, cells_, ph_, alpha, vals, table=weight_table,
                                 eta=eta, lam=lam, rho=None if by_scan else prior_rho,
                                 bands=rho == "scan-bands", prior=P)
            local_settings.update(local_prior=local_pick.name,
                                  local_prior_gain=round(local_pick.gain, 3))
        chosen = (post.rho, post.rho_high)
        refit = local_pick is not None
        if (rho == "scan" and post.rho < SCAN_RHO_MAX) or (
                rho == "scan-bands" and chosen != prior_rho):
            # Refit under the scan's factors. The posterior already assumed them; its weights
            # come from the first table, which the refit changes little (and a second
            # posterior would cost as much as the fit).
            prior_rho = chosen
            refit = True
        if refit:
            coef, at_samples, has_cv, angle_err = joint(prior_rho)
    if method == "joint" and symmetry == "scan":

        mth, mtd, mpd = mirror_cells(cells_).T
        try:
            mrows, mweights = basis.neighbours(mth, mtd, mpd)
        except BasisError as exc:
            raise ReconstructionError(str(exc)) from None
        Qm = np.einsum("nj,njk->nk", mweights, basis.Q[mrows])
        fmed_m = (mweights * basis.f_med[mrows]).sum(axis=1)[:, None, None]
        mu_m = (mweights * basis.mu[mrows]).sum(axis=1)[:, None, None]
        Ym = remap(vals, fmed_m, w_t, basis.eps) - mu_m  # same value, the mirror row's remap
        Pf = P * harmonic_scale(P.shape[0], *prior_rho)[:, None, None]
        model = MirrorModel(Yr, Ym, Qt, Qm, ph_[:, None] - alpha[None, :], Pf, eta)
        pick = model.choose()
        mirror_settings = {"mirror_axis_deg": None if pick.axis is None else round(
            float(np.rad2deg(pick.axis)), 6), "mirror_slack": pick.slack}
        if pick.axis is not None:
            coef = np.moveaxis(model.coefficients(pick.axis, pick.slack, geo.PH_GRID), -1, 0)
    table = as_table(coef, prior_rho)
    rel = _relative_sample_error(at_samples[..., :n_ch], vals)
    cv = _relative_sample_error(at_samples[..., n_ch:], vals) if has_cv else float("nan")
    pair_err = _pair_log_errors(at_samples[..., n_ch:], vals, ci) if has_cv else None
    cv_log = float(np.sqrt(np.mean(pair_err**2))) if pair_err is not None else float("nan")
    cv_under = (_log_under(at_samples[..., n_ch:], vals, ci) if has_cv else float("nan"))
    misfit = basis_misfit(_log_residuals(at_samples[..., :n_ch], vals, ci), vals, ci)
    n = int(cells_.shape[0])
    # How far the table's projected peak lies above the brightest projected reading (as
    # finishing reports it): a witness of the estimate on the joint path.
    highlight = highlight_read(table, cells_, ph_, alpha, np.maximum(vals, 0.0))
    # The joint fit's calibrated estimate and its interval; V&F's path has neither.
    joint_estimate = estimate_post is not None and np.isfinite(cv)
    if joint_estimate:
        assert estimate_post is not None  # for the type checker: joint_estimate says so
        expected, mahal = estimate_post.expected_log_rmse, estimate_post.mahalanobis
        predicted = predict_joint_log_rmse(expected, mahal, cv)
        uncovered = estimate_post.uncovered_share()
        # The calibrated final mapping: a coverage term for the error where no pair looks,
        # and, when the basis cannot hold the readings (residuals well above the noise that
        # stay across the angles), a floor at the error the readings themselves show; and a
        # highlight term when the table peaks far above every reading (science.md 7.1.1).
        widened = final_log_rmse(predicted, uncovered, misfit,
                                 highlight_excess=highlight.excess, cv_log_under=cv_under)
    else:
        expected = mahal = uncovered = float("nan")
        predicted = predict_vf_log_rmse(cv, n, int(alpha.size))
        # V&F's path: never below the error the readings themselves show.
        widened = widen_log_rmse(predicted, misfit)
    # Never below the error the table carries above the physical peak bound: a lower bound of
    # the true error for any material within it (gonio.brdf.tables.bounds; science.md 7.5).
    excess = peak_excess_log_rmse(table, vals, cells_)
    if np.isfinite(excess) and np.isfinite(widened) and excess > widened:
        widened = excess
    upper = (upper_log_rmse(widened, misfit) if joint_estimate
             else float("nan"))  # the interval was calibrated on the joint fit only
    seconds = time.perf_counter() - t0
    return Reconstruction(
        table=table,
        coefficients=coef,
        rel_sample_error=rel,
        estimated_error=ERROR_SCALE * rel,
        settings={
            "K": basis.K, "n": n, "r": int(alpha.size), "eta": float(eta),
            "lam": float(lam), "method": method, "solver": solver_name,
            "channels": list(channels), "seconds": round(seconds, 4),
            **(_rho_settings(prior_rho) if method == "joint" else {}),
            **mirror_settings,
            **local_settings,
        },
        cv_sample_error=cv,
        predicted_error=cv_error_scale(n) * cv,
        cv_log_error=cv_log,
        cv_log_under=cv_under,
        predicted_log_rmse=widened,
        predicted_log_rmse_unwidened=predicted,
        expected_log_rmse=expected,
        mahalanobis=mahal,
        angle_log_errors=angle_err,
        pair_log_errors=pair_err,
        misfit=misfit,
        uncovered_share=uncovered,
        predicted_log_rmse_upper=upper,
        peak_excess_log_rmse=float(excess),
        highlight_excess=float(highlight.excess),
        highlight=highlight,
    )


def _rho_settings(factor: tuple[float, float]) -> dict[str, float]:
    """``prior_rho`` (the factor on the varying harmonics; with two bands the low band's)
    and, when the bands differ, ``prior_rho_high``."""
    out = {"prior_rho": factor[0]}
    if factor[1] != factor[0]:
        out["prior_rho_high"] = factor[1]
    return out


def _vf_path(
    basis: Basis, Qt: FloatArray, fmed_t: FloatArray, mu_t: FloatArray, w_t: FloatArray,
    ph_: FloatArray, alpha: FloatArray, vals: FloatArray, eta: float, lam: float,
    solver: Solver, n_ch: int,
) -> tuple[FloatArray, FloatArray, bool]:
    """V&F's steps 1-3 and the fit/leave-one-pair-out values back at the readings.

    Returns
    -------
    coef : (C, K, 72)
    at_samples : (n, r, C) or (n, r, 2 C)
        The fit at the readings, then (when defined) the leave-one-pair-out predictions.
    has_cv : bool
    """
    # Steps 1-2: slices, then the remap (n, 72, C). A half-turn scan of a specimen the prior
    # says reads the same turned by half a turn is interpolated with that period.
    period = 2 * np.pi
    if half_turn_scan(alpha):
        if not basis.half_turn_periodic:
            raise ReconstructionError(
                "the stage angles cover only half a turn, and this basis' prior varies over a "
                "full turn (a material without twofold symmetry is in its training set), so V&F's "
                "interpolation along the rotation cannot fill the other half; use the joint fit "
                "(method='joint') or scan a full turn (span 360 degrees)")
        period = np.pi
    Y = remap(resample_to_slices(ph_, alpha, vals, period), fmed_t, w_t, basis.eps) - mu_t

    # Step 3.
    Qs = basis.Q[TH0_ROWS]
    if solver == "closed":
        coef = np.moveaxis(solve_closed(Y, Qt, Qs, eta, lam), -1, 0)  # (C, K, 72)
    else:
        coef = np.stack(
            [solve_iterative(Y[:, :, c], Qt, Qs, eta, lam) for c in range(n_ch)]
        )

    # Step 5: the fit and the leave-one-pair-out predictions at the pairs, taken back to BRDF
    # values at the sampled stage angles in one interpolation (channels side by side).
    fit = np.einsum("nk,cks->nsc", Qt, coef)
    loo = loo_predictions(Y, Qt, Qs, eta, lam)
    has_cv = bool(np.isfinite(loo).all())
    remapped = np.concatenate([fit, loo], axis=2) if has_cv else fit
    # A wild left-out prediction must give a huge error, not an overflow: e^300 is far beyond
    # any reading yet leaves room for the remap's factors.
    remapped = np.minimum(remapped + mu_t, 300.0)
    both = np.maximum(inverse_remap(remapped, fmed_t, w_t, basis.eps), 0.0)
    return coef, slices_at_stage_angles(ph_, alpha, both), has_cv


def refine_angles(
    stage_angles_deg: ArrayLike,
    angle_log_errors: ArrayLike,
    threshold: float,
    min_step_deg: float,
    budget_angles: int | None,
    everywhere: bool = False,
) -> list[float]:
    """New stage angles for adaptive refinement from the joint fit (math.md 9, gonio's variant).

    V&F refine where per-pair PCHIP mispredicts a reading. Here the prediction is the joint
    fit's: each stage angle's readings predicted from every other angle of every pair
    (:attr:`Reconstruction.angle_log_errors`, log_rmse units). Where that error exceeds
    ``threshold`` the two midpoints to the neighbouring angles are planned, worst first.

    Parameters
    ----------
    stage_angles_deg : (r,) measured angles, degrees
    angle_log_errors : (r,) leave-one-angle-out log errors, same order
    threshold : float
        In log_rmse units (0.02 is about 2 % of a bright value).
    min_step_deg : float
        Midpoints closer than this to a measured angle are not planned.
    budget_angles : int or None
        How many angles may be added.
    everywhere : bool
        When any angle exceeds ``threshold``, plan the midpoints of *every* gap (worst-error
        gaps first within the budget): anisotropy shows along the whole ``ph`` circle, so a
        material that needs more rotations needs them all round.

    Returns
    -------
    list of float
        New angles in [0, 360), sorted.
    """
    a = np.mod(np.asarray(stage_angles_deg, dtype=float), 360.0)
    err = np.asarray(angle_log_errors, dtype=float)
    if a.size < 2 or err.shape != a.shape:
        return []
    order = np.argsort(a)
    a, err = a[order], err[order]
    r = a.size
    chosen: dict[float, float] = {}
    if everywhere and err.max() > threshold:
        err = err + threshold  # every angle now counts as exceeding it
    for j in np.argsort(-err):
        if not err[j] > threshold:
            break
        for gap_to in (1, -1):
            nb = (j + gap_to) % r
            gap = (a[nb] - a[j]) % 360.0 if gap_to == 1 else (a[j] - a[nb]) % 360.0
            if gap / 2.0 < min_step_deg:
                continue
            mid = round(float((a[j] + gap_to * gap / 2.0) % 360.0), 6)
            chosen.setdefault(mid, float(err[j]))
    ranked = sorted(chosen, key=lambda k: -chosen[k])
    if budget_angles is not None:
        ranked = ranked[: max(int(budget_angles), 0)]
    return sorted(ranked)


def _pair_log_errors(pred: FloatArray, measured: FloatArray, cos_i: FloatArray) -> FloatArray:
    """(n,) RMS over each pair's readings of ``ln(1 + pred cos ti) - ln(1 + measured cos ti)``."""
    d = _log_residuals(pred, measured, cos_i)
    return np.asarray(np.sqrt(np.mean(d**2, axis=(1, 2))))


def _log_under(pred: FloatArray, measured: FloatArray, cos_i: FloatArray) -> float:
    """RMS over every reading of ``max(0, ln(1 + measured cos ti) - ln(1 + pred cos ti))``:
    how far the readings lie above ``pred`` (:attr:`Reconstruction.cv_log_under`)."""
    d = np.maximum(-_log_residuals(pred, measured, cos_i), 0.0)
    return float(np.sqrt(np.mean(d**2)))


def _log_residuals(pred: FloatArray, measured: FloatArray, cos_i: FloatArray) -> FloatArray:
    """(n, r, C) ``ln(1 + pred cos ti) - ln(1 + measured cos ti)`` per reading."""
    ci = np.asarray(cos_i, dtype=float)[:, None, None]
    return np.asarray(np.log1p(np.maximum(pred, 0.0) * ci) - np.log1p(measured * ci))


def cv_error_scale(n_pairs: int) -> float:
    """Calibrated factor from ``cv_sample_error`` to the whole-BRDF MAPE for ``n_pairs`` pairs.

    Linear in ``log n`` between the points of :data:`CV_ERROR_SCALES` (in ``log s``),
    constant outside them.
    """
    ns = np.log([p for p, _ in CV_ERROR_SCALES])
    ss = np.log([s for _, s in CV_ERROR_SCALES])
    return float(np.exp(np.interp(np.log(max(n_pairs, 1)), ns, ss)))


def _relative_sample_error(fit: FloatArray, measured: FloatArray) -> float:
    """Mean of ``|fit - measured| / max(measured, floor)`` over all samples (a fraction).

    ``floor`` is :data:`REL_ERROR_FLOOR` times the mean measured value (per channel), so
    readings near zero do not dominate; all-zero data give 0 error when the fit is zero too.
    """
    floor = REL_ERROR_FLOOR * measured.mean(axis=(0, 1), keepdims=True)
    denom = np.maximum(measured, floor)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(denom > 0, np.abs(fit - measured) / np.where(denom > 0, denom, 1.0), 0.0)
    return float(rel.mean())
