"""The joint fit's kernel: its prior along ``ph`` and its posterior mean (math.md 6).

Every reading is kept at its own azimuth ``ph = ph_lab - alpha``; the slices are coupled
through the basis' learnt prior along ``ph`` (:attr:`Basis.ph_prior`) with V&F's specular
condition folded into the varying harmonics (:func:`joint_prior`), and one ``(n r) x (n r)``
Cholesky solve gives the coefficients of every slice and the leave-one-pair-out and
leave-one-angle-out predictions (:func:`solve_joint`). :func:`gonio.brdf.reconstruction.
reconstruct.reconstruct` builds on it, and so do the posterior (:mod:`.posterior`) and the
expected-error design (:mod:`gonio.brdf.design.posterior`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.reconstruction.basis import N_HARMONICS, Basis
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import TH0_ROWS

FloatArray = NDArray[np.float64]

#: Noise-to-prior ratio of one reading in the joint fit (the prior sums to the identity over
#: the harmonics, so this is V&F's ``eta`` per reading): V&F's value. Judged by the standard
#: renderings in docs/science.md 7.2.4, where 80 rendered a little closer (HDR-FLIP -0.002)
#: but widened the self-estimate's misses and flagged more scans; kept at 40.
JOINT_ETA = 40.0
#: Weight of Eq. 5's specular (th = 0) condition in the joint fit, in V&F's units.
JOINT_LAM = 0.1
#: ``reconstruct(..., rho="scan")`` adopts the scan's own factor on the prior's varying
#: harmonics when it is below this: a specimen that varies less with the stage angle than the
#: library expects (an isotropic one, most often) is fitted as such. Above it the learnt prior
#: is kept: a larger factor in the fit made anisotropic held-out materials worse
#: (docs/science.md 7.3).
SCAN_RHO_MAX = 1.0

_PRIOR_CACHE: dict[tuple[int, float], tuple[Any, FloatArray]] = {}


def joint_prior(basis: Basis, lam_over_eta: float) -> FloatArray:
    """The prior of the joint fit: per-harmonic covariances ``P'_m`` (37, K, K).

    ``P_m`` is the basis' learnt prior along ``ph`` (:attr:`Basis.ph_prior`; an isotropic
    prior, ``P_0 = I``, for a basis without one). Eq. 5's specular condition penalises
    ``lam ||Qs (c(ph) - cbar)||^2``: only the varying part, so it adds ``lam / eta Qs^T Qs``
    to the precision of every harmonic ``m > 0``: ``P'_m = (P_m^-1 + a H)^-1 =
    (I + a P_m H)^-1 P_m`` (the second form needs no inverse of a singular ``P_m``).
    Cached per basis object.
    """
    import weakref

    key = (id(basis.Q), float(lam_over_eta))
    hit = _PRIOR_CACHE.get(key)
    if hit is not None and hit[0]() is basis.Q:
        return hit[1]
    K = basis.K
    if basis.ph_prior is None:
        P = np.zeros((N_HARMONICS, K, K))
        P[0] = np.eye(K)
    else:
        P = np.array(basis.ph_prior, dtype=float)
    if lam_over_eta > 0:
        Qs = basis.Q[TH0_ROWS]
        H = Qs.T @ Qs
        eye = np.eye(K)
        for m in range(1, N_HARMONICS):
            if np.any(P[m]):
                X = np.linalg.solve(eye + lam_over_eta * P[m] @ H, P[m])
                P[m] = 0.5 * (X + X.T)
    P.setflags(write=False)
    if len(_PRIOR_CACHE) > 16:
        _PRIOR_CACHE.clear()
    _PRIOR_CACHE[key] = (weakref.ref(basis.Q), P)
    return P


@dataclass(frozen=True)
class JointFit:
    """Result of :func:`solve_joint` (remapped, centred values; C channels).

    Attributes
    ----------
    coef : (K, 72, C) coefficients of the grid slices (posterior mean)
    fit : (n, r, C) posterior mean at the readings
    loo : (n, r, C) leave-one-pair-out predictions at the readings (NaN when undefined)
    loo_angle : (n, r, C) leave-one-stage-angle-out predictions: column ``j`` predicted from
        the readings at every other stage angle (NaN when undefined)
    """

    coef: FloatArray
    fit: FloatArray
    loo: FloatArray
    loo_angle: FloatArray


def solve_joint(
    Y: FloatArray, Qt: FloatArray, ph_read: FloatArray, P: FloatArray, eta: float,
    ph_out: FloatArray = geo.PH_GRID,
) -> JointFit:
    """Posterior mean of the coefficients given every reading at its own ``ph`` (math.md 6).

    Model: ``x(row, ph) = Q_row c(ph)``, ``Cov(c(ph), c(ph')) = sum_m P_m cos(m (ph - ph'))``,
    each reading ``y_a = Q_q(a) c(ph_a) + e_a`` with noise variance ``eta``. With
    ``G_ab = sum_m (Qt P_m Qt^T)_{q(a) q(b)} cos(m (ph_a - ph_b)) + eta delta_ab`` (one
    ``(n r) x (n r)`` matrix for all channels), ``beta = G^-1 y`` and
    ``c(ph) = sum_m P_m sum_a Qt_q(a)^T beta_a cos(m (ph - ph_a))``. With ``P_0 = I`` and no
    other harmonic this is V&F's ridge (Eq. 4) over all readings.

    Parameters
    ----------
    Y : (n, r, C) remapped, centred readings
    Qt : (n, K) basis rows at the pairs
    ph_read : (n, r) radians, ``ph`` of each reading (``ph_lab - alpha``)
    P : (M, K, K) per-harmonic prior covariances
    eta : float, > 0
    ph_out : (S,) radians, where to return coefficients (default the 72 grid slices)

    Returns
    -------
    JointFit
        ``loo`` row ``q``: the fit to the other pairs' readings predicting pair ``q``'s, from
        the blocks of ``G^-1`` (``y_I - (G^-1)_II^-1 beta_I``), no refits.
    """
    # scipy loads with the first fit, not with the module: the daemon's start path imports
    # this one (design routes) for its constants, and most daemons and commands never fit.
    import scipy.linalg

    n, r, C = Y.shape
    M = P.shape[0]
    harm = np.arange(M, dtype=float)
    A = np.matmul(np.matmul(Qt[None], P), Qt.T[None])  # (M, n, n)
    # cos(m (a - b)) = Re(e^{-i m a} conj(e^{-i m b})): per pair of pairs (q, p) the block
    # G_qp[j, i] = sum_m Z[q, j, m] A[m, q, p] conj(Z[p, i, m]), one batched product.
    Z = np.exp(-1j * ph_read[:, :, None] * harm[None, None, :])  # (n, r, M)
    left = Z[:, None, :, :] * np.moveaxis(A, 0, -1)[:, :, None, :]  # (n, n, r, M)
    G4 = np.matmul(left, np.conj(Z).transpose(0, 2, 1)[None]).real  # (n, n, r, r)
    G = np.ascontiguousarray(G4.transpose(0, 2, 1, 3)).reshape(n * r, n * r)
    G[np.diag_indices_from(G)] += eta
    y = Y.reshape(n * r, C)
    try:
        cho = scipy.linalg.cho_factor(G)
    except np.linalg.LinAlgError:
        raise ReconstructionError(
            "the joint system is singular; use eta > 0"
        ) from None
    beta = scipy.linalg.cho_solve(cho, y).reshape(n, r, C)
    # Back to coefficients: B_m = sum_a Qt_q(a)^T beta_a e^{-i m ph_a} (cos and -sin parts),
    # c(ph) = Re(sum_m e^{i m ph} P_m B_m).
    U = np.matmul(Z.transpose(0, 2, 1), beta)  # (n, M, C)
    B = np.matmul(Qt.T[None], U.transpose(1, 0, 2))  # (M, K, C)
    PB = np.matmul(P, B)  # (M, K, C)
    E = np.exp(1j * np.asarray(ph_out)[:, None] * harm[None, :])  # (S, M)
    K = Qt.shape[1]
    coef = (E @ PB.reshape(M, K * C)).real.reshape(-1, K, C).transpose(1, 0, 2)  # (K, S, C)
    fit = Y - eta * beta
    loo = np.full_like(Y, np.nan)
    # The inverse from the Cholesky factor (LAPACK potri): a fifth of the cost of solving
    # against the identity at n r = 1440; only its diagonal blocks are used.
    inv, info = scipy.linalg.lapack.dpotri(cho[0], lower=cho[1])
    if info != 0:
        inv = scipy.linalg.cho_solve(cho, np.eye(n * r))
    else:
        inv = np.tril(inv) + np.tril(inv, -1).T if cho[1] else np.triu(inv) + np.triu(inv, 1).T
    Ginv = inv.reshape(n, r, n, r)
    if n > 1:
        ok = True
        for q in range(n):
            try:
                loo[q] = Y[q] - np.linalg.solve(Ginv[q, :, q, :], beta[q])
            except np.linalg.LinAlgError:
                ok = False
                break
        if not ok:
            loo[:] = np.nan
    loo_angle = np.full_like(Y, np.nan)
    if r > 1:
        try:
            for j in range(r):
                loo_angle[:, j] = Y[:, j] - np.linalg.solve(Ginv[:, j, :, j], beta[:, j])
        except np.linalg.LinAlgError:
            loo_angle[:] = np.nan
    return JointFit(coef=coef, fit=fit, loo=loo, loo_angle=loo_angle)
