"""Reconstruction of a full anisotropic BRDF from sparse rotation-stage samples (MATH.md 5).

Input: ``n`` fixed light/sensor pairs, each one cell ``(th, td, pd)`` of the isotropic slice
with its lab half-vector azimuth ``ph_lab``, read at ``r`` stage angles. Pair ``q`` at stage
angle ``alpha`` sees slice ``ph = ph_lab[q] - alpha``.

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
5. The mean relative error at the measured samples, times 0.8, estimates the error over the
   whole BRDF (V&F Sec. 5).
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
from scipy.interpolate import PchipInterpolator

from gonio.brdf import geometry as geo
from gonio.brdf.basis import Basis, BasisError, inverse_remap, remap, row_weight
from gonio.brdf.table import BRDFTable

FloatArray = NDArray[np.float64]
Solver = Literal["closed", "iterative"]

#: V&F Sec. 5: the whole-BRDF error is about 0.8 x the mean relative error at the samples.
ERROR_SCALE = 0.8
#: Samples darker than this fraction of the mean sample value are compared against that floor
#: in the relative sample error, so near-black readings cannot dominate the mean.
REL_ERROR_FLOOR = 0.01


class ReconstructionError(ValueError):
    """Reconstruction inputs are unusable; the message says what and what to do."""


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
    settings : dict
        Solver settings and sizes (K, n, r, eta, lam, solver, seconds).
    """

    table: BRDFTable
    coefficients: FloatArray
    rel_sample_error: float
    estimated_error: float
    settings: dict[str, Any] = field(default_factory=dict)


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
def _periodic_pchip(
    x: FloatArray, y: FloatArray, xq: FloatArray
) -> FloatArray:
    """Periodic (2 pi) PCHIP of ``y`` (r, ...) sampled at sorted ``x`` (r,), evaluated at ``xq``."""
    if x.size == 1:
        return np.broadcast_to(y[0], (*xq.shape, *y.shape[1:])).copy()
    # Padding with whole shifted copies makes the slopes at the ends see their wrapped
    # neighbours, which is what a periodic interpolant needs.
    xp = np.concatenate([x - 2 * np.pi, x, x + 2 * np.pi])
    yp = np.concatenate([y, y, y], axis=0)
    return np.asarray(PchipInterpolator(xp, yp, axis=0)(np.mod(xq, 2 * np.pi)))


def resample_to_slices(
    ph_lab: FloatArray, stage_angles: FloatArray, values: FloatArray
) -> FloatArray:
    """Resample each pair's rotation readings onto the 72 grid ``ph`` (MATH 5 step 1).

    Parameters
    ----------
    ph_lab : (n,) radians
    stage_angles : (r,) radians, distinct modulo 2 pi
    values : (n, r, C)

    Returns
    -------
    (n, 72, C)
        Value of slice ``PH_GRID[k]`` at each pair. The stage angle that puts slice ``ph``
        under pair ``q`` is ``ph_lab[q] - ph``, so interpolation runs over stage angle.
    """
    a = np.mod(stage_angles, 2 * np.pi)
    order = np.argsort(a)
    a = a[order]
    out = np.empty((values.shape[0], geo.N_PH, values.shape[2]))
    for q in range(values.shape[0]):
        out[q] = _periodic_pchip(a, values[q, order], ph_lab[q] - geo.PH_GRID)
    return out


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


# ---------------------------------------------------------------------------- validation
def _check_inputs(
    basis: Basis,
    cells: FloatArray,
    ph_lab: FloatArray,
    stage_angles: FloatArray,
    values: FloatArray,
    channels: Sequence[str],
) -> None:
    if basis.Q.shape[0] != geo.N_ROWS or not np.array_equal(
        basis.valid, geo.valid_mask().ravel()
    ):
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
    eta: float = 40.0,
    lam: float = 0.1,
    n_components: int | None = None,
    solver: Solver = "closed",
    name: str = "reconstruction",
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
    eta, lam : float
        Regularisation weights of Eq. 5 (V&F defaults 40 and 0.1).
    n_components : int, optional
        Use only the first K components (default: all of ``basis``).
    solver : {"closed", "iterative"}
        Closed-form minimiser (default) or the L-BFGS reference.
    name : str
        Name of the output table.

    Returns
    -------
    Reconstruction
    """
    t0 = time.perf_counter()
    cells_ = np.asarray(cells, dtype=float)
    ph_ = np.asarray(ph_lab, dtype=float)
    alpha = np.asarray(stage_angles, dtype=float)
    vals = np.asarray(values, dtype=float)
    channels = tuple(str(c) for c in channels)
    _check_inputs(basis, cells_, ph_, alpha, vals, channels)
    if solver not in ("closed", "iterative"):
        raise ReconstructionError(f"solver must be 'closed' or 'iterative', not {solver!r}")
    if not (eta >= 0 and lam >= 0):
        raise ReconstructionError(f"eta and lam must be >= 0, got eta={eta}, lam={lam}")
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
    fmed_t = (weights * basis.f_med[rows]).sum(axis=1)
    mu_t = (weights * basis.mu[rows]).sum(axis=1)
    ci, co = geo.cell_cosines(th, td, pd)
    w_t = np.maximum(ci * co, basis.eps)  # the exact weight of each pair, not a blend

    # Steps 1-2: slices, then the remap (n, 72, C).
    slices = resample_to_slices(ph_, alpha, vals)
    Y = remap(slices, fmed_t[:, None, None], w_t[:, None, None], basis.eps) - mu_t[:, None, None]

    # Step 3.
    i_th0 = np.zeros(geo.N_TD * geo.N_PD, dtype=np.intp)
    td_idx, pd_idx = np.meshgrid(np.arange(geo.N_TD), np.arange(geo.N_PD), indexing="ij")
    rows_s = geo.flat_row(i_th0, td_idx.ravel(), pd_idx.ravel())
    Qs = basis.Q[rows_s[basis.valid[rows_s]]]
    if solver == "closed":
        coef = np.moveaxis(solve_closed(Y, Qt, Qs, eta, lam), -1, 0)  # (C, K, 72)
    else:
        coef = np.stack(
            [solve_iterative(Y[:, :, c], Qt, Qs, eta, lam) for c in range(len(channels))]
        )

    # Step 4: the full table.
    valid = basis.valid
    w_all = row_weight(basis.eps)[valid]
    Qv = basis.Q[valid]
    out = np.full((len(channels), geo.N_PH, geo.N_ROWS), np.nan)
    for c in range(len(channels)):
        X = (Qv @ coef[c]).T + basis.mu[valid]  # (72, p_valid)
        out[c][:, valid] = np.maximum(inverse_remap(X, basis.f_med[valid], w_all, basis.eps), 0.0)
    table = BRDFTable(
        out.reshape(len(channels), *geo.TABLE_SHAPE), channels, name, None,
        {"reconstruction": {"K": basis.K, "n": int(cells_.shape[0]), "r": int(alpha.size),
                            "eta": eta, "lam": lam, "solver": solver,
                            "basis_materials": len(basis.materials)}},
    )

    # Step 5: the reconstruction at the pairs themselves, back at the sampled stage angles.
    fit = np.stack([Qt @ coef[c] for c in range(len(channels))], axis=-1) + mu_t[:, None, None]
    fit_a = np.maximum(inverse_remap(fit, fmed_t[:, None, None], w_t[:, None, None], basis.eps), 0)
    at_samples = np.empty_like(vals)
    for q in range(vals.shape[0]):
        at_samples[q] = _periodic_pchip(geo.PH_GRID, fit_a[q], ph_[q] - alpha)
    rel = _relative_sample_error(at_samples, vals)
    seconds = time.perf_counter() - t0
    return Reconstruction(
        table=table,
        coefficients=coef,
        rel_sample_error=rel,
        estimated_error=ERROR_SCALE * rel,
        settings={
            "K": basis.K, "n": int(cells_.shape[0]), "r": int(alpha.size), "eta": float(eta),
            "lam": float(lam), "solver": solver, "channels": list(channels),
            "seconds": round(seconds, 4),
        },
    )


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
