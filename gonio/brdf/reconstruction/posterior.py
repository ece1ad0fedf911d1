"""The joint fit's posterior: expected error of a scan and where the next stage angle helps most.

The joint fit (:func:`~gonio.brdf.reconstruction.joint.solve_joint`, math.md 6) is the
posterior mean of a
Gaussian process along ``ph``: ``x(row, ph) = Q_row c(ph)`` with
``Cov(c(ph), c(ph')) = sum_m P_m cos(m (ph - ph'))`` and reading noise ``eta``. The same model
gives the posterior *covariance*, and from it two things the mean cannot:

* **the expected error of the whole table** (:attr:`ScanPosterior.expected_log_rmse`): the
  posterior variance of ``x`` at every valid cell of the 72 slices, weighted as ``log_rmse``
  weighs errors (volume weight ``wV`` times the squared derivative of ``ln(1 + f cos ti)``
  with respect to the remapped value ``x``, at the reconstructed ``f``);
* **the value of a new stage angle** (:meth:`ScanPosterior.angle_gains`): reading all ``n``
  pairs at stage angle ``beta`` lowers that weighted variance by
  ``sum_ph tr(W C(ph, R) S_R^-1 C(ph, R)^T)``, with ``C`` the posterior cross-covariance of the
  slice coefficients and the new readings ``R`` and ``S_R`` their posterior covariance plus
  noise. The gain depends on where the readings are and on the weights, not on the values
  still to come, so it can be computed before moving the stage.

Two numbers are taken from the data, so that the variance means something for *this*
material (empirical Bayes): the scale ``s2`` of the whole prior, and a factor ``rho`` on the
varying harmonics (``m > 0``) of the learnt prior, chosen from :data:`RHO_GRID` by marginal
likelihood. An isotropic specimen drives ``rho`` down and with it the value of more rotations;
a strongly anisotropic one drives it up. Both are profiled in closed form / on a grid
(``s2 = y^T G^-1 y / N`` for each ``rho``). With ``bands=True`` the shape of the spectrum
along ``ph`` is taken from the data too: one factor on the low harmonics
(``0 < m <= BAND_SPLIT``, the twofold symmetry of a brushed or woven specimen) and another on
the higher ones (sharp highlights), both from :data:`RHO_GRID`.

Adaptive refinement (:func:`next_angles`) picks candidate angles (the midpoints of the gaps)
greedily by gain, conditioning on the angles already picked, and stops when the best
remaining angle would lower the self-estimated ``log_rmse`` (the posterior's expected error
joined, as variances add, with the part the basis cannot represent, which more angles do not
lower) by less than a threshold (:data:`REFINE_GAIN`, chosen on held-out training materials
with ``bench/bench_adaptive.py``). Its posterior may give each pair an offset that reads the
same at every stage angle (``offset``): what the basis cannot represent of an isotropic
specimen does not average away with more angles, as noise does.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.reconstruction.basis import Basis, BasisError, remap, row_weight
from gonio.brdf.reconstruction.blas import one_blas_thread
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.joint import JOINT_ETA, JOINT_LAM, joint_prior, solve_joint
from gonio.brdf.reconstruction.periodic import arc_angle, arc_gaps
from gonio.brdf.reconstruction.selfcheck import predict_joint_log_rmse
from gonio.brdf.reconstruction.tabulate import expand_table
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import VALID_ROWS

FloatArray = NDArray[np.float64]

#: Factors on the varying (m > 0) harmonics of the learnt prior tried by marginal likelihood.
RHO_GRID: tuple[float, ...] = tuple(float(v) for v in np.geomspace(1 / 64, 16.0, 11))
#: The two-band prior shape (``bands=True``): harmonics ``0 < m <= BAND_SPLIT`` take the low
#: band's factor, ``m > BAND_SPLIT`` the high band's. On the learnt priors only even harmonics
#: carry energy, so the low band is ``m = 2`` (docs/science.md 2.1).
BAND_SPLIT = 2
#: Sizes of the per-pair offset (``offset="scan"``) tried by marginal likelihood, as fractions
#: of the mean isotropic (``m = 0``) prior variance of one reading: 0 (no offset), 1/64 .. 4.
OFFSET_GRID: tuple[float, ...] = (0.0, *(float(v) for v in np.geomspace(1 / 64, 4.0, 5)))
#: Default stopping threshold of adaptive plans: the least drop of the self-estimated
#: ``log_rmse`` one more stage angle must buy, as the engine's refiner calls
#: :func:`next_angles` (the reconstruction's witnesses, ``offset=REFINE_OFFSET``; chosen on
#: the wide held-out panel for scans over half a turn, ``bench/bench_adaptive.py --set wide
#: --span 180``; re-chosen there on 2026-11-27 with the render-weighted design and the local
#: priors, 3e-5 before; docs/science.md 7.3).
REFINE_GAIN = 2e-5
#: The planning posterior's per-pair offset in adaptive plans (:class:`ScanPosterior`'s
#: ``offset``): sized by each scan's marginal likelihood.
REFINE_OFFSET = "scan"
#: The ``log_rmse`` weights read every third slice of the table (they are taken as constant
#: along ``ph``), so a caller that has no table yet expands only those slices.
WEIGHT_SLICE_STEP = 3


@functools.cache
def _volume_weight_rows() -> FloatArray:
    """(p_valid,) volume weight ``wV`` of the valid rows (math.md 10)."""
    out = np.asarray(geo.volume_weight().ravel()[VALID_ROWS], dtype=float)
    out.setflags(write=False)
    return out


@functools.cache
def _cos_ti_rows() -> FloatArray:
    """(p_valid,) ``cos theta_i`` of the valid rows."""
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    out = np.asarray(ci.ravel()[VALID_ROWS], dtype=float)
    out.setflags(write=False)
    return out


def harmonic_scale(n_harmonics: int, low: float, high: float | None = None) -> FloatArray:
    """(M,) factors on the prior's harmonics: 1 for ``m = 0``, ``low`` for
    ``0 < m <= BAND_SPLIT``, ``high`` (default ``low``) above."""
    m = np.arange(n_harmonics)
    return np.where(m == 0, 1.0, np.where(m <= BAND_SPLIT, low, low if high is None else high))


class ScanPosterior:
    """Posterior of the joint fit for one scan (module notes).

    Readings are kept as a grid, every pair at every stage angle, flattened pair-major
    (reading ``(q, j)`` at ``q r + j``, as in
    :func:`gonio.brdf.reconstruction.joint.solve_joint`).
    Every quantity is computed in the space of readings: with ``A_m = Qt P_m Qt^T`` the prior
    covariance of two readings is ``sum_m A_m[q, p] cos(m (ph_a - ph_b))``, and with
    ``B_m = Qt P_m W P_m Qt^T`` the sum over the 72 grid slices of ``tr(W k(ph, a) k(ph, b)^T)``
    (``k`` the covariance of the slice coefficients and a reading) is the same kind of sum with
    ``B_m`` and the weights of the discrete orthogonality of the harmonics on 72 points
    (72 for ``m = 0``, 36 for ``0 < m < 36``; ``m = 36`` alternates in sign, see
    :meth:`_weighted`). Nothing of size ``72 K`` is ever formed.

    Parameters
    ----------
    basis : Basis
    cells : (n, 3) array_like, radians
        ``(th, td, pd)`` of each pair.
    ph_lab : (n,) array_like, radians
    stage_angles : (r,) array_like, radians
    values : (n, r, C) array_like, 1/sr
        The readings (non-negative).
    table : (C, 72, 18, 18, 36) or (C, 24, 18, 18, 36) array_like, optional
        The reconstruction (1/sr), for the ``log_rmse`` weights, or only its slices the
        weights read (every :data:`WEIGHT_SLICE_STEP`-th, ``table[:, ::3]``); default: the
        joint fit of the readings under the learnt prior
        (:func:`gonio.brdf.reconstruction.joint.solve_joint`).
    eta, lam : float, optional
        The joint fit's settings (defaults :data:`JOINT_ETA`, :data:`JOINT_LAM`).
    rho : float or (float, float), optional
        Fix the factor on the varying harmonics instead of choosing it by marginal likelihood;
        a pair fixes the low and the high band's factors (``0 < m <= BAND_SPLIT`` and
        ``m > BAND_SPLIT``).
    bands : bool
        When ``rho`` is not given: choose the two bands' factors separately (every pair of
        :data:`RHO_GRID`) instead of one factor for all varying harmonics.
    offset : float or "scan"
        Variance of a per-pair offset, constant over the stage angle, added to the readings'
        covariance (prior units, like ``eta``): what the basis cannot represent of an
        isotropic specimen reads the same at every stage angle, so more stage angles do not
        average it away as they do the noise. ``"scan"``: chosen with ``rho`` by marginal
        likelihood from :data:`OFFSET_GRID` (fractions of the mean isotropic prior
        variance of one reading). 0 (the default): no offset, the joint fit's own model. The slice
        coefficients' posterior is that of the readings less their offsets (the offsets are
        not part of the table).

    Attributes
    ----------
    s2 : float
        Scale of the prior chosen by marginal likelihood, ``y^T G^-1 y / (N C)`` (remapped
        units squared; ``N`` readings, ``C`` channels).
    rho : float
        Factor on the varying harmonics (``m > 0``) chosen from :data:`RHO_GRID`; with two
        bands, the low band's factor (``0 < m <= BAND_SPLIT``).
    rho_high : float
        The factor on the harmonics ``m > BAND_SPLIT`` (equal to ``rho`` for one factor).
    tau : float
        Variance of the per-pair offset (prior units; 0: none).
    offset_unit : float
        The unit of :data:`OFFSET_GRID`: the mean isotropic prior variance of one reading.
    mahalanobis : float
        Squared Mahalanobis norm under the prior (before the scale ``s2``) of the fitted
        readings, per pair and channel: ``f^T K^-1 f / (n C)`` with ``K`` the prior
        covariance of the readings and ``f = K G^-1 y`` the fit at them (remapped units
        squared). A material far from the training library needs components the prior
        deems unlikely, so the norm is large; it witnesses the error the basis cannot
        represent, which :attr:`expected_log_rmse` cannot see
        (:mod:`gonio.brdf.reconstruction.selfcheck`). Per pair, not per reading: for an
        isotropic specimen the norm of the whole scan hardly changes with the number of
        stage angles (repeated readings of one pair add no new direction).
    """

    def __init__(
        self,
        basis: Basis,
        cells: ArrayLike,
        ph_lab: ArrayLike,
        stage_angles: ArrayLike,
        values: ArrayLike,
        *,
        table: ArrayLike | None = None,
        eta: float | None = None,
        lam: float | None = None,
        rho: float | tuple[float, float] | None = None,
        bands: bool = False,
        offset: float | str = 0.0,
        prior: ArrayLike | None = None,
    ) -> None:
        cells_ = np.asarray(cells, dtype=float)
        self.ph_lab = np.asarray(ph_lab, dtype=float)
        alpha = np.asarray(stage_angles, dtype=float)
        vals = np.asarray(values, dtype=float)
        n = cells_.shape[0]
        if cells_.ndim != 2 or cells_.shape[1] != 3 or self.ph_lab.shape != (n,):
            raise ReconstructionError("cells must be (n, 3) and ph_lab (n,), radians")
        if vals.ndim != 3 or vals.shape[:2] != (n, alpha.size):
            raise ReconstructionError(
                f"values have shape {vals.shape}; expected ({n}, {alpha.size}, channels)")
        if not np.isfinite(vals).all() or (vals < 0).any():
            raise ReconstructionError("values must be finite and non-negative (1/sr)")
        self.eta = float(JOINT_ETA if eta is None else eta)
        lam_ = float(JOINT_LAM if lam is None else lam)
        if not self.eta > 0:
            raise ReconstructionError(f"eta must be > 0, got {self.eta}")
        th, td, pd = cells_.T
        try:
            rows, weights = basis.neighbours(th, td, pd)
        except BasisError as exc:
            raise ReconstructionError(str(exc)) from None
        self.Qt = np.einsum("nj,njk->nk", weights, basis.Q[rows])
        fmed_t = (weights * basis.f_med[rows]).sum(axis=1)[:, None, None]
        mu_t = (weights * basis.mu[rows]).sum(axis=1)[:, None, None]
        ci, co = geo.cell_cosines(th, td, pd)
        w_t = np.maximum(ci * co, basis.eps)[:, None, None]
        y = remap(vals, fmed_t, w_t, basis.eps) - mu_t  # (n, r, C), as the joint fit sees them
        self.n, self.C = vals.shape[0], vals.shape[2]
        self.y = y.reshape(self.n * alpha.size, self.C)
        self.P = (joint_prior(basis, lam_ / self.eta) if prior is None
                  else np.asarray(prior, dtype=float))  # (M, K, K)
        if self.P.shape != (geo.N_PH // 2 + 1, basis.K, basis.K):
            raise ReconstructionError(
                f"prior has shape {self.P.shape}; expected ({geo.N_PH // 2 + 1}, {basis.K}, "
                f"{basis.K})")
        M = self.P.shape[0]
        self.harm = np.arange(M, dtype=float)
        if table is None:
            # The joint fit of these readings under the learnt prior (what reconstruct()
            # computes before it weighs the scan's own anisotropy).
            jf = solve_joint(y, self.Qt, self.ph_lab[:, None] - alpha[None, :], self.P,
                             self.eta)
            table = expand_table(basis, np.moveaxis(jf.coef, -1, 0)[:, :, ::WEIGHT_SLICE_STEP])
        self._set_weights(basis, np.asarray(table))
        self.alpha = alpha.copy()
        low = (self.harm > 0) & (self.harm <= BAND_SPLIT)
        self._G_iso = self._kernel(self._Am, (self.harm == 0).astype(float), alpha, alpha)
        self._G_low = self._kernel(self._Am, low.astype(float), alpha, alpha)
        self._G_high = self._kernel(self._Am, (self.harm > BAND_SPLIT).astype(float), alpha,
                                    alpha)
        self._B = self._same_pair(alpha.size, alpha.size)
        # The offsets' unit: the mean isotropic prior variance of one reading.
        self.offset_unit = float(np.mean(np.diag(self._G_iso)))
        self.tau = 0.0
        if isinstance(offset, str):
            if offset != "scan":
                raise ReconstructionError(f"offset must be a number >= 0 or 'scan', got {offset!r}")
            if rho is not None or bands:
                raise ReconstructionError("offset='scan' is chosen with one rho; give neither "
                                          "rho nor bands")
            self.rho, self.tau = self._choose_rho_offset()
            self.rho_high = self.rho
        else:
            self.tau = float(offset)
            if not self.tau >= 0:
                raise ReconstructionError(f"offset must be >= 0, got {offset}")
            if rho is None:
                self.rho, self.rho_high = (self._choose_bands() if bands
                                           else (self._choose_rho(),) * 2)
            elif isinstance(rho, tuple):
                self.rho, self.rho_high = float(rho[0]), float(rho[1])
            else:
                self.rho = self.rho_high = float(rho)
        self._rho_m = harmonic_scale(M, self.rho, self.rho_high)
        G = self._prior_readings(self.rho, self.rho_high) + self.tau * self._B
        G[np.diag_indices_from(G)] += self.eta
        self._chol = scipy.linalg.cho_factor(G, lower=True)
        beta = scipy.linalg.cho_solve(self._chol, self.y)
        self.s2 = float(np.sum(self.y * beta)) / self.y.size
        # y^T G^-1 y splits into the fit's prior norm and its residual over the noise:
        # with K = G - eta I and the fitted readings f = K beta, f^T K^-1 f = beta^T K beta
        # (with an offset, K holds it too: the norm of the fit with its offsets).
        self.mahalanobis = (float(np.sum(self.y * beta) - self.eta * np.sum(beta**2))
                            / (self.n * self.C))

    # ------------------------------------------------------------------ set-up
    def _set_weights(self, basis: Basis, table: FloatArray) -> None:
        """``W = Q^T diag(wV g^2) Q`` over the valid rows, and ``A_m``, ``B_m``.

        ``g = d ln(1 + f cos ti) / dx = cos ti (f + eps / w) / (1 + f cos ti)`` turns a remapped
        error into a ``log_rmse`` error at the reconstructed ``f``; ``g^2`` is averaged over
        channels and every third slice (the weights along ``ph`` are taken as constant).
        ``table`` holds all 72 slices or only those (``table[:, ::WEIGHT_SLICE_STEP]``).
        """
        n_s = table.shape[1] if table.ndim > 1 else 0
        if n_s == geo.N_PH:
            table = table[:, ::WEIGHT_SLICE_STEP]
        elif n_s != len(range(0, geo.N_PH, WEIGHT_SLICE_STEP)):
            raise ReconstructionError(
                f"table has shape {table.shape}; expected (C, {geo.N_PH}, 18, 18, 36) or its "
                f"every {WEIGHT_SLICE_STEP}rd slice")
        f_all = table.reshape(table.shape[0], -1, geo.N_ROWS)
        ci_v = _cos_ti_rows()
        a = basis.eps / row_weight(basis.eps)[VALID_ROWS]
        # One channel at a time, in place: the (C, 24, 7,861) float64 temporaries of a
        # 31-band table cost more than the rest of the posterior.
        g2 = np.zeros(VALID_ROWS.size)
        g = np.empty((f_all.shape[1], VALID_ROWS.size))
        den = np.empty_like(g)
        for fc in f_all:
            g[...] = np.take(fc, VALID_ROWS, axis=1)
            np.nan_to_num(g, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
            np.maximum(g, 0.0, out=g)
            np.multiply(g, ci_v, out=den)
            den += 1.0
            g += a
            g *= ci_v
            g /= den
            g *= g
            g2 += g.sum(axis=0)
        g2 /= f_all.shape[0] * f_all.shape[1]
        wv = _volume_weight_rows()
        Qv = basis.Q[VALID_ROWS]
        W = Qv.T @ (Qv * (wv * g2)[:, None])
        self.W = W  # (K, K) log_rmse weights of the coefficients
        self.norm = float(geo.N_PH * wv.sum())  # log_rmse's denominator per channel
        PQ = np.matmul(self.P, self.Qt.T[None])  # (M, K, n)
        self._Am = np.matmul(self.Qt[None], PQ)  # (M, n, n)
        self._Bm = np.matmul(PQ.transpose(0, 2, 1), np.matmul(W[None], PQ))  # (M, n, n)
        self._trWP = np.einsum("kl,mlk->m", W, self.P)  # tr(W P_m)

    def _ph(self, alpha: FloatArray) -> FloatArray:
        """(n, r) ``ph`` of every pair at every stage angle."""
        return self.ph_lab[:, None] - np.asarray(alpha, dtype=float)[None, :]

    def _kernel(self, mats: FloatArray, coef: FloatArray, alpha_a: FloatArray,
                alpha_b: FloatArray) -> FloatArray:
        """``sum_m coef_m mats_m[q, p] cos(m (ph_a - ph_b))`` for two reading grids.

        Returns
        -------
        (n ra, n rb) float64, pair-major on both sides.
        """
        n = self.n
        Za = np.exp(-1j * self._ph(alpha_a)[:, :, None] * self.harm)  # (n, ra, M)
        Zb = np.exp(-1j * self._ph(alpha_b)[:, :, None] * self.harm)  # (n, rb, M)
        Mc = np.moveaxis(mats * coef[:, None, None], 0, -1)  # (n, n, M)
        left = Za[:, None, :, :] * Mc[:, :, None, :]  # (n, n, ra, M)
        out = np.matmul(left, np.conj(Zb).transpose(0, 2, 1)[None]).real  # (n, n, ra, rb)
        ra, rb = Za.shape[1], Zb.shape[1]
        return np.ascontiguousarray(out.transpose(0, 2, 1, 3)).reshape(n * ra, n * rb)

    def _cov(self, alpha_a: FloatArray, alpha_b: FloatArray) -> FloatArray:
        """Prior covariance of the slice values at two reading grids (prior units)."""
        return self._kernel(self._Am, self._rho_m, alpha_a, alpha_b)

    def _same_pair(self, ra: int, rb: int) -> FloatArray:
        """(n ra, n rb) ones where two readings (pair-major grids) are of the same pair."""
        return np.asarray(np.kron(np.eye(self.n), np.ones((ra, rb))), dtype=np.float64)

    def _cov_y(self, alpha_a: FloatArray, alpha_b: FloatArray) -> FloatArray:
        """Prior covariance of two reading grids' readings, the pairs' offsets included
        (prior units; noise not included)."""
        out = self._cov(alpha_a, alpha_b)
        if self.tau:
            out = out + self.tau * self._same_pair(np.asarray(alpha_a).size,
                                                   np.asarray(alpha_b).size)
        return out

    def _weighted(self, alpha_a: FloatArray, alpha_b: FloatArray) -> FloatArray:
        """``sum_s tr(W k(ph_s, a) k(ph_s, b)^T)`` over the 72 grid slices, for two grids.

        On 72 equally spaced ``ph`` the harmonics are orthogonal: ``sum_s cos(m ph_s +
        x) cos(m' ph_s + y)`` is ``72 cos x cos y`` for ``m = m' = 0``, ``36 cos(x - y)`` for
        ``m = m'`` in 1..35, 0 for ``m != m'``, and for ``m = m' = 36`` (``cos(36 ph_s) =
        +-1``, ``sin = 0``) ``72 cos x cos y``.
        """
        M = self.harm.size
        coef = self._rho_m**2 * np.where(self.harm == 0, float(geo.N_PH), geo.N_PH / 2.0)
        last = M - 1  # the Nyquist harmonic, handled apart
        coef[last] = 0.0
        out = self._kernel(self._Bm, coef, alpha_a, alpha_b)
        if 2 * last == geo.N_PH and np.any(self._Bm[last]):
            ca = np.cos(last * self._ph(alpha_a)).ravel()
            cb = np.cos(last * self._ph(alpha_b)).ravel()
            na, nb = np.asarray(alpha_a).size, np.asarray(alpha_b).size
            Bl = np.repeat(np.repeat(self._Bm[last], na, axis=0), nb, axis=1)
            out += geo.N_PH * self._rho_m[last] ** 2 * Bl * np.outer(ca, cb)
        return out

    def _prior_readings(self, low: float, high: float) -> FloatArray:
        """Prior covariance of the measured readings with the bands' factors (a new array)."""
        return self._G_iso + low * self._G_low + high * self._G_high

    def log_marginal(self, low: float, high: float | None = None) -> float:
        """Log marginal likelihood of the readings, the prior's scale ``s2`` profiled out.

        ``-N C / 2 ln s2 - C / 2 ln det G`` (constants dropped), ``G`` the readings' prior
        covariance with the low band's factor ``low`` and the high band's ``high`` (default:
        ``low``) plus ``eta I``, ``s2 = y^T G^-1 y / (N C)``. ``-inf`` when ``G`` is singular.
        """
        G = self._prior_readings(low, low if high is None else high)
        G[np.diag_indices_from(G)] += self.eta
        return profiled_log_marginal(G, self.y)

    def log_marginal_isotropic(self, P0: ArrayLike) -> float:
        """:meth:`log_marginal` at the scan's own factors and offset, with the prior's
        isotropic harmonic ``P_0`` replaced by ``P0`` (K, K): how well another isotropic
        prior explains the readings (:mod:`gonio.brdf.reconstruction.localprior`)."""
        A0 = self.Qt @ np.asarray(P0, dtype=float) @ self.Qt.T  # (n, n)
        r = self.alpha.size
        # m = 0 does not vary with ph: every reading of pair q meets every reading of pair p
        # with A0[q, p] (pair-major order).
        G = (np.kron(A0, np.ones((r, r))) + self.rho * self._G_low
             + self.rho_high * self._G_high + self.tau * self._B)
        G[np.diag_indices_from(G)] += self.eta
        return profiled_log_marginal(G, self.y)

    def _choose_rho(self) -> float:
        """The factor of :data:`RHO_GRID` with the largest marginal likelihood."""
        lls = [self.log_marginal(r) for r in RHO_GRID]
        return float(RHO_GRID[int(np.argmax(lls))])

    def _choose_rho_offset(self) -> tuple[float, float]:
        """``(rho, tau)`` of :data:`RHO_GRID` x :data:`OFFSET_GRID` (scaled to the mean
        isotropic prior variance of one reading, :attr:`_G_iso`'s diagonal) with the largest
        marginal likelihood; ``tau`` in prior units.

        One Cholesky factorisation per ``rho``: the offsets' kernel is ``tau U U^T`` with ``U``
        (N, n) the pairs' indicator columns, so with ``A = L L^T`` the prior and noise,
        ``ln det(A + tau U U^T) = ln det A + ln det(I + tau S)`` and ``y^T (A + tau U U^T)^-1
        y = y^T A^-1 y - tau z^T (I + tau S)^-1 z`` with ``S = U^T A^-1 U``, ``z = U^T A^-1 y``
        (Woodbury; n x n per offset). The test compares the choice with scipy's multivariate
        normal on the covariance written out.
        """
        unit = self.offset_unit
        N, C = self.y.shape
        U = self._same_pair(self.alpha.size, 1)  # (N, n): reading a is of pair column q
        best, best_ll = (RHO_GRID[0], 0.0), -np.inf
        for r in RHO_GRID:
            A = self._prior_readings(r, r)
            A[np.diag_indices_from(A)] += self.eta
            try:
                cho = scipy.linalg.cho_factor(A, lower=True)
            except np.linalg.LinAlgError:
                continue
            Ay = scipy.linalg.cho_solve(cho, self.y)  # (N, C)
            AU = scipy.linalg.cho_solve(cho, U)  # (N, n)
            S, z = U.T @ AU, U.T @ Ay  # (n, n), (n, C)
            quad0 = float(np.sum(self.y * Ay))
            logdet0 = 2.0 * float(np.sum(np.log(np.diag(cho[0]))))
            for f in OFFSET_GRID:
                tau = f * unit
                M = np.eye(S.shape[0]) + tau * S
                sign, logdet_m = np.linalg.slogdet(M)
                if sign <= 0:
                    continue
                quad = quad0 - tau * float(np.sum(z * np.linalg.solve(M, z)))
                ll = (-0.5 * N * C * np.log(max(quad / (N * C), 1e-300))
                      - 0.5 * C * (logdet0 + logdet_m))
                if ll > best_ll:
                    best, best_ll = (float(r), tau), ll
        return best

    def _low_band_factor(self) -> FloatArray:
        """``U`` (N, k) with ``U U^T`` the low band's reading kernel (:attr:`_G_low`).

        The band holds harmonics ``0 < m <= BAND_SPLIT``; harmonic ``m``'s kernel is
        ``Re(z_a conj(z_b)) A_m[q(a), q(b)]``, ``z_a = e^{-i m ph_a}``, so with
        ``A_m = L L^T`` it is ``Re(F F^H)``, ``F = diag(z) L[q]``: columns ``Re F`` and
        ``Im F``. Rank at most ``2 n BAND_SPLIT``, whatever the number of stage angles.
        """
        ph = self._ph(self.alpha).ravel()
        q = np.repeat(np.arange(self.n), self.alpha.size)
        cols = []
        for m in range(1, min(BAND_SPLIT, self.harm.size - 1) + 1):
            lam, vec = np.linalg.eigh(self._Am[m])
            keep = lam > 1e-12 * max(float(lam.max()), 0.0)
            if not keep.any():
                continue
            F = np.exp(-1j * m * ph)[:, None] * (vec[:, keep] * np.sqrt(lam[keep]))[q]
            cols += [F.real, F.imag]
        return np.concatenate(cols, axis=1) if cols else np.zeros((ph.size, 0))

    def _choose_bands(self) -> tuple[float, float]:
        """The low and high band's factors with the largest marginal likelihood.

        Every pair of :data:`RHO_GRID`, but one Cholesky factorisation per high-band factor:
        the low band's kernel is ``U U^T`` of low rank (:meth:`_low_band_factor`), so with
        ``A = G_iso + high G_high + eta I = L L^T``, ``W = L^-1 U`` and ``W^T W = V diag(l)
        V^T``, every low-band factor ``r`` has ``ln det G = ln det A + sum ln(1 + r l)`` and
        ``y^T G^-1 y = |L^-1 y|^2 - sum r u^2 / (1 + r l)``, ``u = V^T W^T L^-1 y``
        (Woodbury). Same values as :meth:`log_marginal` (tested), a tenth of the cost.
        """
        N, C = self.y.shape
        U = self._low_band_factor()
        lows = np.asarray(RHO_GRID)
        best, best_ll = (RHO_GRID[0], RHO_GRID[0]), -np.inf
        for high in RHO_GRID:
            A = self._G_iso + high * self._G_high
            A[np.diag_indices_from(A)] += self.eta
            try:
                L = scipy.linalg.cholesky(A, lower=True)
            except np.linalg.LinAlgError:
                continue
            Ly = scipy.linalg.solve_triangular(L, self.y, lower=True)  # (N, C)
            W = scipy.linalg.solve_triangular(L, U, lower=True)  # (N, k)
            ell, V = np.linalg.eigh(W.T @ W)
            ell = np.maximum(ell, 0.0)
            u2 = np.sum((V.T @ (W.T @ Ly)) ** 2, axis=1)  # (k,), summed over channels
            quad = float(np.sum(Ly**2)) - (lows[:, None] * u2 / (1 + lows[:, None] * ell)).sum(1)
            logdet = 2.0 * float(np.sum(np.log(np.diag(L)))) + np.log1p(
                lows[:, None] * ell).sum(1)
            ll = -0.5 * N * C * np.log(np.maximum(quad / (N * C), 1e-300)) - 0.5 * C * logdet
            i = int(np.argmax(ll))
            if ll[i] > best_ll:
                best, best_ll = (float(lows[i]), float(high)), float(ll[i])
        return best

    # ------------------------------------------------------------------ results
    def weighted_variance(self) -> float:
        """``sum_ph tr(W Cov_post(c(ph)))`` in units of the prior (before the scale ``s2``)."""
        prior = self.prior_weighted_variance()
        Gw = self._weighted(self.alpha, self.alpha)
        explained = float(np.sum(scipy.linalg.cho_solve(self._chol, Gw) * np.eye(len(Gw))))
        return max(prior - explained, 0.0)

    def prior_weighted_variance(self) -> float:
        """``sum_ph tr(W Cov_prior(c(ph)))`` in units of the prior: what
        :meth:`weighted_variance` would be with no reading at all."""
        return geo.N_PH * float(np.sum(self._rho_m * self._trWP))

    def uncovered_share(self) -> float:
        """Share of the prior's ``log_rmse``-weighted variance the readings leave (0..1).

        The coverage witness of the self-estimate (:func:`gonio.brdf.reconstruction.selfcheck.
        final_log_rmse`): it depends on where the pairs and stage angles are, on the prior's
        shape (``rho``) and on the ``log_rmse`` weights, not on the readings' scale ``s2``.
        A layout whose pairs all lie in one plane leaves most of the table to the prior's
        correlations (0.1-0.45 for the MA68 preset on held-out materials), a designed layout
        little (about 0.02 for 10 designed pairs at 8 angles): docs/science.md 7.1.1. NaN when
        the prior carries no weighted variance.
        """
        prior = self.prior_weighted_variance()
        if not prior > 0:
            return float("nan")
        return float(min(self.weighted_variance() / prior, 1.0))

    @property
    def expected_log_rmse(self) -> float:
        """Root of the posterior's expected weighted squared log error over the whole table.

        The error the model itself expects (components of the basis only: what the basis
        cannot represent is not in it). Before any reading, a design's counterpart is
        :func:`gonio.brdf.design.posterior.design_expected_log_rmse`.
        """
        return float(np.sqrt(self.s2 * self.weighted_variance() / self.norm))

    def angle_gains(self, stage_angles: ArrayLike) -> FloatArray:
        """Drop of the weighted posterior variance from reading every pair at each angle.

        With the new readings ``R`` and the measured ``A``, the slice coefficients' posterior
        covariance with ``R`` is ``k(ph, A u R) D``, ``D = [-G^-1 cov(A, R); I]``, so the drop
        is ``tr(S_R^-1 D^T Gw D)`` with ``Gw`` from :meth:`_weighted` and
        ``S_R = cov(R, R) - cov(R, A) G^-1 cov(A, R) + eta I``.

        Parameters
        ----------
        stage_angles : (m,) array_like, radians
            Candidate stage angles, each considered on its own.

        Returns
        -------
        (m,) float64
            The drop per candidate, prior units (multiply by ``s2`` for remapped units).
        """
        beta = np.atleast_1d(np.asarray(stage_angles, dtype=float))
        if beta.size == 0:
            return np.zeros(0)
        m, n = beta.size, self.n
        # The readings' covariances (offsets included: a new reading of a pair shares its
        # offset with the pair's earlier ones); the weighted kernels are the coefficients'.
        cAR = self._cov_y(self.alpha, beta)  # (N, n m), pair-major over (q, candidate)
        H = scipy.linalg.cho_solve(self._chol, cAR)  # G^-1 cov(A, R)
        GwAA = self._weighted(self.alpha, self.alpha)
        GwAR = self._weighted(self.alpha, beta)
        gains = np.zeros(m)
        for j in range(m):
            idx = np.arange(n) * m + j
            Hj, cj = H[:, idx], cAR[:, idx]
            GwRR = self._weighted(beta[j:j + 1], beta[j:j + 1])
            S = self._cov_y(beta[j:j + 1], beta[j:j + 1]) - cj.T @ Hj
            S[np.diag_indices_from(S)] += self.eta
            T = GwRR - Hj.T @ GwAR[:, idx]
            T = T + T.T - GwRR + Hj.T @ GwAA @ Hj
            try:
                gains[j] = float(np.trace(scipy.linalg.solve(S, T, assume_a="pos")))
            except np.linalg.LinAlgError:
                gains[j] = 0.0
        return gains

    def log_rmse_drop(self, gain: float) -> float:
        """Drop of :attr:`expected_log_rmse` that a variance ``gain`` buys (log_rmse units)."""
        return self.expected_log_rmse - self.expected_after(gain)

    def expected_after(self, gain: float) -> float:
        """:attr:`expected_log_rmse` once the weighted variance has fallen by ``gain``
        (prior units, as :meth:`angle_gains` gives it)."""
        v = self.weighted_variance()
        return float(np.sqrt(self.s2 * max(v - gain, 0.0) / self.norm))

    def add_angles(self, stage_angles: ArrayLike) -> None:
        """Condition on readings at these angles (values not needed: the variance does not
        depend on them); ``s2`` and ``rho`` stay as estimated."""
        beta = np.atleast_1d(np.asarray(stage_angles, dtype=float))
        self.alpha = np.concatenate([self.alpha, beta])
        G = self._cov_y(self.alpha, self.alpha)
        G[np.diag_indices_from(G)] += self.eta
        self._chol = scipy.linalg.cho_factor(G, lower=True)


#: Where in each gap :func:`candidate_angles` puts candidates, as fractions of the gap.
MIDPOINTS: tuple[float, ...] = (0.5,)
#: The quarter, half and three-quarter points (the rule's earlier candidates, kept for
#: comparison: ``bench/bench_adaptive.py --candidates quarters``).
QUARTERS: tuple[float, ...] = (0.25, 0.5, 0.75)


def profiled_log_marginal(cov: FloatArray, y: FloatArray) -> float:
    """Log marginal likelihood of ``C`` columns of readings sharing one covariance shape.

    Parameters
    ----------
    cov : (N, N) float
        The readings' covariance up to a common scale ``s2`` (prior plus noise).
    y : (N, C) float
        Readings, one column per colour channel.

    Returns
    -------
    float
        ``-N C / 2 ln s2 - C / 2 ln det cov`` with ``s2 = y^T cov^-1 y / (N C)`` (the scale
        profiled out, constants dropped); ``-inf`` when ``cov`` is not positive definite.
    """
    N, C = y.shape
    try:
        cho = scipy.linalg.cho_factor(cov, lower=True)
    except np.linalg.LinAlgError:
        return -np.inf
    s2 = float(np.sum(y * scipy.linalg.cho_solve(cho, y))) / (N * C)
    logdet = 2.0 * float(np.sum(np.log(np.diag(cho[0]))))
    return float(-0.5 * N * C * np.log(max(s2, 1e-300)) - 0.5 * C * logdet)


def candidate_angles(stage_angles_deg: ArrayLike, min_step_deg: float,
                     fractions: Sequence[float] = MIDPOINTS, *, period_deg: float = 360.0,
                     arc_start_deg: float = 0.0) -> FloatArray:
    """Candidate new angles: the midpoints of every gap (or other points of it) in the arc.

    Midpoints by default: fully refined, a scan started at ``r0`` uniform angles then reaches
    the uniform ``2^k r0`` angles (the best spread for a stationary prior along ``ph``), and
    every round is a subset of the dry run's worst case (every gap halved). On the wide
    held-out panel they beat the quarter points (docs/science.md 7.3).

    The gaps are those of the angles within one period (:func:`~gonio.brdf.reconstruction.
    periodic.arc_gaps`): over half a turn (``period_deg = 180``) the angles 0, 45, 90, 135 have
    four gaps of 45 deg, the last one from 135 to 180, and the candidates stay in the arc
    ``[arc_start_deg, arc_start_deg + period_deg)``. The posterior itself needs no period: the
    readings are taken at their true angles, and a specimen read over half a turn is assumed
    twofold symmetric (the learnt prior's harmonics are even, docs/science.md 2.1).

    Parameters
    ----------
    stage_angles_deg : (r,) measured angles, degrees
    min_step_deg : float
        Candidates closer than this to a measured angle are left out.
    fractions : sequence of float in (0, 1)
        Where in each gap (default :data:`MIDPOINTS`; :data:`QUARTERS` for the quarter,
        half and three-quarter points).
    period_deg : float
        The arc the scan covers, degrees: 360 (a full turn, the default) or 180.
    arc_start_deg : float
        Where the arc starts, degrees (the plan's ``start_deg``).

    Returns
    -------
    (m,) float64, degrees in [0, 360), sorted, rounded to 1e-6
    """
    pos, gaps = arc_gaps(stage_angles_deg, period_deg, arc_start_deg)
    out = set()
    for start, gap in zip(pos, gaps, strict=True):
        for frac in fractions:
            step = min(frac, 1 - frac) * gap
            if step >= min_step_deg - 1e-9:
                angle = arc_angle([start + frac * gap], period_deg, arc_start_deg)[0]
                out.add(round(float(angle), 6) % 360.0)
    return np.array(sorted(out))


@dataclass(frozen=True)
class RefinementStep:
    """What :func:`next_angles` decided.

    Attributes
    ----------
    angles_deg : new stage angles, degrees, sorted (empty: stop)
    drops : drop of each pick, in pick order, in the measure the rule used (the posterior's
        expected ``log_rmse``, or the self-estimate's with ``cv_sample_error``)
    expected_log_rmse : the posterior's expected error before the new angles
    rho : the anisotropy factor chosen by marginal likelihood
    reason : ``"threshold"`` (no angle worth its readings), ``"budget"``, ``"min_step"``
        (no candidate left) or ``""`` when angles were planned
    offset : the per-pair offset's variance as a fraction of its unit (:data:`OFFSET_GRID`;
        0: none)
    best_drop : the drop of the best candidate looked at last (the one that stopped the rule,
        when ``reason`` is ``"threshold"``); NaN when none was looked at
    """

    angles_deg: list[float]
    drops: list[float]
    expected_log_rmse: float
    rho: float
    reason: str
    offset: float = 0.0
    best_drop: float = float("nan")


def next_angles(
    basis: Basis,
    cells: ArrayLike,
    ph_lab: ArrayLike,
    stage_angles_deg: Sequence[float] | ArrayLike,
    values: ArrayLike,
    *,
    threshold: float = REFINE_GAIN,
    min_step_deg: float = 1.0,
    budget_angles: int | None = None,
    batch: int | None = None,
    per_gap: int | None = None,
    rel_threshold: float = 0.0,
    fractions: Sequence[float] = MIDPOINTS,
    table: ArrayLike | None = None,
    period_deg: float = 360.0,
    arc_start_deg: float = 0.0,
    cv_sample_error: float | None = None,
    offset: float | str = 0.0,
    mahalanobis: float | None = None,
) -> RefinementStep:
    """Plan the next stage angles where they lower the expected ``log_rmse`` most.

    Greedy: the candidate (:func:`candidate_angles`) with the largest posterior-variance drop
    is picked, the posterior is conditioned on it, and so on while the pick's drop is at least
    ``threshold`` (and at least ``rel_threshold`` times the posterior's expected ``log_rmse``
    left before the pick) and the budget lasts. The drop is the posterior's expected
    ``log_rmse`` drop (:meth:`ScanPosterior.log_rmse_drop`), or with ``cv_sample_error`` the
    self-estimate's.

    Parameters
    ----------
    basis, cells, ph_lab : as for :func:`gonio.brdf.reconstruction.reconstruct.reconstruct`
    stage_angles_deg : (r,) measured angles, degrees
    values : (n, r, C) readings, 1/sr
    threshold : float
        Least drop per new angle (log_rmse units), in the rule's measure (below). The default
        :data:`REFINE_GAIN` was chosen for the adaptive plans' call (the reconstruction's
        ``cv_sample_error`` and ``mahalanobis``, ``offset=REFINE_OFFSET``); a call without
        them measures another drop against the same number.
    min_step_deg : float
        Stage resolution: no angle closer than this to another is planned.
    budget_angles : int, optional
        Most angles to add (None: no limit).
    batch : int, optional
        Most angles to plan in this round (None: as many as pass the threshold).
    per_gap : int, optional
        Most new angles inside each gap between the measured angles (None: no limit). With 1
        a round adds at most one angle per gap, as V&F's midpoints do, so the dry run's bound
        on an adaptive job (every gap halved each round) holds.
    rel_threshold : float
        Least drop per new angle as a fraction of the posterior's expected ``log_rmse`` left
        (0: no such condition, the default; a relative rule was tried on the held-out panel
        and did not pay, docs/science.md 7.3).
    fractions : sequence of float
        Candidate points of each gap (:func:`candidate_angles`; default the midpoints).
    table : optional, the reconstruction of these readings (computed when omitted)
    period_deg, arc_start_deg : float
        The arc the scan covers, degrees (:func:`candidate_angles`): the gaps are those within
        one period, and new angles lie in ``[arc_start_deg, arc_start_deg + period_deg)``
        (modulo 360). Default: a full turn.
    cv_sample_error : float, optional
        The scan's leave-one-pair-out relative error
        (:attr:`gonio.brdf.reconstruction.reconstruct.Reconstruction.cv_sample_error`). When
        given, a pick's drop is that of the self-estimate
        (:func:`gonio.brdf.reconstruction.selfcheck.predict_joint_log_rmse`, with the posterior's
        ``mahalanobis``) rather than of the posterior's expected error alone: what the basis
        cannot represent does not fall with more stage angles, and a large part of it shrinks
        what a new angle buys in the whole error (errors add as variances). The self-estimate's
        form with this posterior's expected error, which with an offset is not the number the
        reconstruction reports. None or not finite (e.g. one pair, no leave-one-pair-out):
        the posterior's expected ``log_rmse`` only.
    offset : float or "scan"
        The planning posterior's per-pair offset (:class:`ScanPosterior`); default none.
    mahalanobis : float, optional
        With ``cv_sample_error``: the self-estimate's Mahalanobis witness, as the
        reconstruction reports it
        (:attr:`gonio.brdf.reconstruction.reconstruct.Reconstruction.mahalanobis`, the joint
        fit's own model, which the self-estimate was calibrated with). Default: the planning
        posterior's, the same number when it has no offset.

    Returns
    -------
    RefinementStep
    """
    a_deg = np.asarray(stage_angles_deg, dtype=float)
    with one_blas_thread():
        post = ScanPosterior(basis, cells, ph_lab, np.deg2rad(a_deg), values, table=table,
                             offset=offset)
        e0 = post.expected_log_rmse
        mahal = post.mahalanobis if mahalanobis is None else float(mahalanobis)
        if cv_sample_error is not None and not np.isfinite(cv_sample_error):
            cv_sample_error = None  # no leave-one-pair-out error: the posterior's own drop
        limit = budget_angles if budget_angles is not None else 10**9
        if batch is not None:
            limit = min(limit, batch)
        picked: list[float] = []
        drops: list[float] = []
        reason = ""
        measured = list(np.mod(a_deg, 360.0))
        # The measured angles' positions in the arc; gap k starts at edges[k].
        edges, _ = arc_gaps(a_deg, period_deg, arc_start_deg)
        used = np.zeros(edges.size, dtype=int)  # picks per original gap
        last_drop = float("nan")
        while True:
            if len(picked) >= limit:
                reason = "budget" if not picked else ""
                break
            cand = candidate_angles(measured, min_step_deg, fractions, period_deg=period_deg,
                                    arc_start_deg=arc_start_deg)
            at = np.mod(cand - arc_start_deg, period_deg)
            gap_of = (np.searchsorted(edges, at, side="right") - 1) % max(edges.size, 1)
            if per_gap is not None and edges.size:
                cand, gap_of = cand[used[gap_of] < per_gap], gap_of[used[gap_of] < per_gap]
            if cand.size == 0:
                reason = "min_step" if not picked else ""
                break
            gains = post.angle_gains(np.deg2rad(cand))
            k = int(np.argmax(gains))
            if cv_sample_error is None:
                drop = post.log_rmse_drop(float(gains[k]))
            else:
                drop = (predict_joint_log_rmse(post.expected_log_rmse, mahal, cv_sample_error)
                        - predict_joint_log_rmse(post.expected_after(float(gains[k])), mahal,
                                                 cv_sample_error))
            last_drop = float(drop)
            if not (drop >= threshold and drop >= rel_threshold * post.expected_log_rmse):
                reason = "threshold" if not picked else ""
                break
            if edges.size:
                used[gap_of[k]] += 1
            picked.append(float(cand[k]))
            drops.append(drop)
            measured.append(float(cand[k]))
            post.add_angles(np.deg2rad([cand[k]]))
    order = np.argsort(picked)
    unit = post.offset_unit
    return RefinementStep([picked[i] for i in order], drops, e0, post.rho, reason,
                          post.tau / unit if unit > 0 else 0.0, last_drop)
