"""The specimen's mirror symmetry, chosen per scan: the joint fit's ``symmetry="scan"``.

Most anisotropic surfaces (brushed and rolled metals, woven fabrics, every microfacet model
with two roughnesses) are symmetric about their tangent axes: reflected in the plane through
the normal and an axis at azimuth ``ph0``, the BRDF does not change. In the coordinates of the
tables (``th, ph, td, pd``) the reflection maps ``ph -> 2 ph0 - ph`` and ``pd -> -pd``, and
reciprocity (``pd -> pd + pi``) brings that back into the table: the value at
``(th, td, pd, ph)`` is the value at ``(th, td, pi - pd, 2 ph0 - ph)``. So every reading is
also a reading of the *mirror cell* at the *mirror azimuth*: the scan holds twice as many
distinct views as it has readings, if the specimen is symmetric and the axis is known.

The joint fit is a Gaussian process along ``ph`` (:func:`~gonio.brdf.reconstruction.
joint.solve_joint`). With ``x`` the remapped value at a reading and ``x'`` the one at its
mirror (same BRDF value, remapped with the mirror row's constants, so ``x' - x = delta``, a
known offset per pair), symmetry is the linear condition ``x' - x = delta`` for every reading,
held with a variance ``slack`` (the basis cannot follow a symmetric material exactly either).
Conditioning the process on the readings and on these conditions is one Gaussian solve of
twice the size; the marginal likelihood of the *readings* under the conditioned prior,
``p(y | x' - x = delta)``, is comparable with the plain fit's ``p(y)``, so the scan itself
decides (empirical Bayes) whether it is symmetric, about which axis (5 degree grid, then 1
degree steps around the best) and how strictly (:data:`MIRROR_SLACKS`). A material that is not
symmetric (the real measured tables of ``../shared/data/rgl`` are not, by 0.04-0.14 in
log_rmse between a table and its mirror) keeps the plain fit. docs/science.md 2.1 and 7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.reconstruction.posterior import profiled_log_marginal

FloatArray = NDArray[np.float64]

#: Candidate axes ``ph0`` (degrees) of the first pass; the best is refined in 1 degree steps.
MIRROR_AXES_DEG: tuple[float, ...] = tuple(float(a) for a in np.arange(0.0, 180.0, 5.0))
#: Variances of the symmetry conditions tried, in units of the reading noise ``eta``.
MIRROR_SLACKS: tuple[float, ...] = (0.25, 1.0, 4.0, 16.0, 64.0)


def mirror_cells(cells: ArrayLike) -> FloatArray:
    """Cells ``(th, td, pi - pd mod pi)``: where a mirror-symmetric specimen repeats a pair.

    Parameters
    ----------
    cells : (n, 3) radians

    Returns
    -------
    (n, 3) float64, radians
    """
    c = np.array(cells, dtype=float)
    c[:, 2] = np.mod(np.pi - c[:, 2], np.pi)
    return c


@dataclass(frozen=True)
class MirrorChoice:
    """What the scan said about its symmetry.

    Attributes
    ----------
    axis : float or None
        The axis ``ph0`` (radians, in [0, pi)) of the chosen symmetry; None: no symmetry (the
        plain fit has the larger marginal likelihood).
    slack : float
        Variance of the symmetry conditions, units of ``eta`` (NaN without symmetry).
    log_marginal, plain_log_marginal : float
        Log marginal likelihood of the readings (scale profiled, constants dropped) with the
        chosen symmetry and without any.
    """

    axis: float | None
    slack: float
    log_marginal: float
    plain_log_marginal: float


class MirrorModel:
    """The joint fit's Gaussian process with the readings and their mirror images.

    Parameters
    ----------
    Y, Ym : (n, r, C)
        Remapped, centred readings at the pairs' cells and the same values remapped at the
        mirror cells.
    Qt, Qm : (n, K)
        Basis rows at the pairs' cells and at their mirror cells.
    ph_read : (n, r) radians
        ``ph`` of each reading.
    P : (M, K, K)
        The prior's per-harmonic covariances (as the fit uses them).
    eta : float
        Reading noise (prior units).
    """

    def __init__(self, Y: FloatArray, Ym: FloatArray, Qt: FloatArray, Qm: FloatArray,
                 ph_read: FloatArray, P: FloatArray, eta: float) -> None:
        n, r, C = Y.shape
        self.n, self.r, self.C, self.N = n, r, C, n * r
        self.eta = float(eta)
        self.y = Y.reshape(self.N, C)
        self.delta = (Ym - Y).reshape(self.N, C)
        self.Qt, self.Qm, self.ph = Qt, Qm, ph_read
        # Only the harmonics the prior holds (the learnt priors: even ones).
        self.harm = np.flatnonzero([np.any(p) for p in P])
        self.P = P[self.harm]
        q = np.repeat(np.arange(n), r)
        Z = np.exp(-1j * ph_read.reshape(-1)[:, None] * self.harm[None, :])  # (N, M')

        def rows(QA: FloatArray, QB: FloatArray) -> FloatArray:
            return np.matmul(np.matmul(QA[None], self.P), QB.T[None])[:, q][:, :, q]  # (M', N, N)

        cosd = (Z[:, None, :] * np.conj(Z)[None, :, :]).real  # cos(m (ph_a - ph_b)), (N, N, M')
        self.G_rr = np.einsum("abm,mab->ab", cosd, rows(Qt, Qt))
        # Mirror azimuths 2 ph0 - ph: their differences are the readings' negated, so the
        # mirror-mirror block does not depend on the axis.
        self.G_vv = np.einsum("abm,mab->ab", cosd, rows(Qm, Qm))
        # cov(x_a, x'_b) = sum_m A_m cos(m (ph_a + ph_b - 2 ph0)) = Re(sum_m W_m e^{2 i m ph0}).
        self.W = Z[:, None, :] * Z[None, :, :] * np.moveaxis(rows(Qt, Qm), 0, -1)  # (N, N, M')
        G = self.G_rr.copy()
        G[np.diag_indices_from(G)] += self.eta
        self._plain = profiled_log_marginal(G, self.y)

    def cross(self, axis: float) -> FloatArray:
        """(N, N) ``cov(x_a, x'_b)`` for the axis ``ph0`` (radians)."""
        return np.asarray((self.W @ np.exp(2j * self.harm * axis)).real)

    def _joint(self, axis: float, slack: float) -> tuple[FloatArray, FloatArray]:
        """Covariance of ``[y; x' - x]`` (2N, 2N) and the observation ``[y; delta]``."""
        X = self.cross(axis)
        N = self.N
        cov = np.empty((2 * N, 2 * N))
        cov[:N, :N] = self.G_rr
        cov[:N, N:] = X - self.G_rr
        cov[N:, :N] = cov[:N, N:].T
        cov[N:, N:] = self.G_vv - X - X.T + self.G_rr
        cov[np.diag_indices(2 * N)] += np.concatenate(
            [np.full(N, self.eta), np.full(N, slack * self.eta)])
        return cov, np.concatenate([self.y, self.delta])

    def log_marginal(self, axis: float | None, slack: float = 1.0) -> float:
        """``ln p(y | x' - x = delta)`` (scale profiled, constants dropped); ``axis=None``: the
        plain ``ln p(y)``.

        ``p(y | z) = p(y, z) / p(z)``: with the scale ``s2`` common to both, the quadratic
        form is ``obs^T cov^-1 obs - delta^T cov_zz^-1 delta`` and the log determinant
        ``ln det cov - ln det cov_zz``.
        """
        if axis is None:
            return self._plain
        cov, obs = self._joint(axis, slack)
        N = self.N
        try:
            cf = scipy.linalg.cho_factor(cov, lower=True)
            cz = scipy.linalg.cho_factor(cov[N:, N:], lower=True)
        except np.linalg.LinAlgError:
            return -np.inf
        quad = (float(np.sum(obs * scipy.linalg.cho_solve(cf, obs)))
                - float(np.sum(self.delta * scipy.linalg.cho_solve(cz, self.delta))))
        logdet = 2.0 * (float(np.sum(np.log(np.diag(cf[0]))))
                        - float(np.sum(np.log(np.diag(cz[0])))))
        return float(-0.5 * N * self.C * np.log(max(quad / (N * self.C), 1e-300))
                     - 0.5 * self.C * logdet)

    def choose(self) -> MirrorChoice:
        """The symmetry (or none) with the largest marginal likelihood (module notes)."""
        best_ll = self._plain
        best: tuple[float | None, float] = (None, float("nan"))
        for a in np.deg2rad(MIRROR_AXES_DEG):
            for s in MIRROR_SLACKS:
                ll = self.log_marginal(float(a), s)
                if ll > best_ll:
                    best_ll, best = ll, (float(a), s)
        centre = best[0]
        if centre is not None:
            for d in (-4.0, -3.0, -2.0, -1.0, 1.0, 2.0, 3.0, 4.0):
                a = float(np.mod(centre + np.deg2rad(d), np.pi))
                for s in MIRROR_SLACKS:
                    ll = self.log_marginal(a, s)
                    if ll > best_ll:
                        best_ll, best = ll, (a, s)
        return MirrorChoice(best[0], best[1], best_ll, self._plain)

    def coefficients(self, axis: float, slack: float, ph_out: FloatArray) -> FloatArray:
        """Posterior mean of the coefficients given the readings and the symmetry.

        Returns
        -------
        (K, S, C)
            At the azimuths ``ph_out`` (S,).
        """
        cov, obs = self._joint(axis, slack)
        sol = scipy.linalg.cho_solve(scipy.linalg.cho_factor(cov, lower=True), obs)
        N = self.N
        b_real, b_mirror = sol[:N] - sol[N:], sol[N:]  # T^T sol, T = [[I, 0], [-I, I]]
        # c(ph) = sum_a k(ph, x_a) b_a + k(ph, x'_a) b'_a, k(ph, x_a) = sum_m P_m Q_q^T
        # cos(m (ph - ph_a)); the mirror azimuth is 2 ph0 - ph_a.
        Z = np.exp(-1j * self.ph[:, :, None] * self.harm)  # (n, r, M')
        Zm = np.exp(-2j * self.harm * axis) * np.conj(Z)
        C = self.C
        U = np.matmul(Z.transpose(0, 2, 1), b_real.reshape(self.n, self.r, C))  # (n, M', C)
        Um = np.matmul(Zm.transpose(0, 2, 1), b_mirror.reshape(self.n, self.r, C))
        B = (np.matmul(self.Qt.T[None], U.transpose(1, 0, 2))
             + np.matmul(self.Qm.T[None], Um.transpose(1, 0, 2)))  # (M', K, C)
        PB = np.matmul(self.P, B)
        E = np.exp(1j * np.asarray(ph_out)[:, None] * self.harm[None, :])  # (S, M')
        K = self.Qt.shape[1]
        return np.asarray((E @ PB.reshape(len(self.harm), K * C)).real
                          .reshape(-1, K, C).transpose(1, 0, 2))
