"""Design objective: the condition number of selected basis rows and its fast update (math.md 8).

A design is a set of ``n`` rows of the basis matrix ``Q`` (one row per grid cell
``(th, td, pd)``). Reconstruction solves for the basis coefficients from those rows, so the
design is judged by the condition number ``kappa`` of the selected rows restricted to the first
``m = min(n, K)`` columns: a square block when ``n <= K`` (as NJR15 and V&F do), a tall
``n x K`` block otherwise.

The search (:mod:`gonio.brdf.design.search`) tries one row swap at a time. Each trial is a
rank-one update of the Gram matrix of the kept rows, so its extreme eigenvalues are roots of
the secular equation (V&F App. B, Golub 1973). :func:`condition_numbers_fast` solves it for all
candidates of a neighbourhood at once; :func:`condition_numbers_svd` is the plain-SVD reference
it is tested against.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.errors import DesignError

FloatArray = NDArray[np.float64]
KappaMethod = Literal["fast", "svd"]

# A block whose smallest singular value is below this fraction of its largest is numerically
# singular: singular values that small carry no correct digits, so both the fast update and
# the SVD reference report kappa = inf there instead of two different huge numbers.
SINGULAR_RTOL = 1e-13
# Stop when a step moves the iterate by less than this (relative): both iterations converge
# quadratically, so the value after such a step is already accurate to round-off (about
# 1e-14 measured against the 1e-13 setting), and one confirming iteration is saved.
_NEWTON_RTOL = 1e-9
_MAX_ITER = 200


def block_width(n: int, n_components: int) -> int:
    """Columns of ``Q`` the objective uses for ``n`` rows: ``min(n, K)``."""
    return min(int(n), int(n_components))


def kappa_from_extremes(lo: FloatArray, hi: FloatArray) -> FloatArray:
    """``sqrt(hi / lo)`` from extreme Gram eigenvalues, inf where numerically singular."""
    lo = np.maximum(lo, 0.0)
    singular = (lo <= hi * SINGULAR_RTOL**2) | (hi <= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.sqrt(hi / np.where(singular, 1.0, lo))
    return np.where(singular, np.inf, kappa)


def condition_number(rows: ArrayLike) -> float:
    """Condition number of selected basis rows over their first ``min(n, K)`` columns.

    Parameters
    ----------
    rows : (n, K) array_like
        The selected rows of ``Q``.

    Returns
    -------
    float
        ``sigma_max / sigma_min`` of the ``n x min(n, K)`` block; ``inf`` when it is
        numerically singular (``sigma_min <= 1e-13 sigma_max``).
    """
    a = np.asarray(rows, dtype=float)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise DesignError(f"need a non-empty (n, K) matrix of rows, got shape {a.shape}")
    m = block_width(a.shape[0], a.shape[1])
    s = np.linalg.svd(a[:, :m], compute_uv=False)
    return float(kappa_from_extremes(np.array(s[-1] ** 2), np.array(s[0] ** 2)))


def condition_numbers_svd(kept: ArrayLike, candidates: ArrayLike) -> FloatArray:
    """Reference: ``kappa`` of ``kept`` plus each candidate row, by a full SVD per candidate.

    Parameters
    ----------
    kept : (n - 1, m) array_like
        Rows that stay, already cut to the ``m`` objective columns.
    candidates : (c, m) array_like
        Rows to try, one at a time, as the ``n``-th row.

    Returns
    -------
    (c,) array
        Condition numbers (``inf`` where singular).
    """
    k = np.asarray(kept, dtype=float)
    q = np.asarray(candidates, dtype=float)
    blocks = np.concatenate([np.broadcast_to(k, (q.shape[0], *k.shape)), q[:, None, :]], axis=1)
    s = np.asarray(np.linalg.svd(blocks, compute_uv=False), dtype=float)
    return kappa_from_extremes(s[:, -1] ** 2, s[:, 0] ** 2)


@dataclass(frozen=True)
class GramSpectrum:
    """Eigen-decomposition of the Gram matrix ``kept^T kept`` of the kept rows.

    Attributes
    ----------
    d : (m,) array
        Eigenvalues in ascending order (exact zeros for the null space when fewer than ``m``
        rows are kept: they come from squared singular values, not from ``eigh`` of the Gram,
        so small eigenvalues keep their relative accuracy).
    V : (m, m) array
        Orthonormal eigenvectors as columns, in the order of ``d``.
    """

    d: FloatArray
    V: FloatArray


def gram_spectrum(kept: ArrayLike, width: int) -> GramSpectrum:
    """Spectrum of ``kept^T kept`` for ``kept`` of shape ``(p, width)`` (``p`` may be 0)."""
    k = np.asarray(kept, dtype=float).reshape(-1, width)
    if k.shape[0] == 0:
        return GramSpectrum(np.zeros(width), np.eye(width))
    _, s, vt = np.linalg.svd(k, full_matrices=True)
    d = np.zeros(width)
    d[: s.size] = s**2
    # svd sorts descending; the secular solver wants ascending.
    return GramSpectrum(d[::-1].copy(), vt[::-1].T.copy())


def secular_extremes(
    d: FloatArray, z: FloatArray, rho: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Smallest and largest eigenvalues of ``diag(d) + rho z z^T`` for many ``(z, rho)``.

    The roots of ``1 + rho sum_j z_j^2 / (d_j - x) = 0`` bracketed by ``[d_1, d_2]`` and
    ``[d_m, d_m + rho]`` (V&F App. B). Both are found with a safeguarded Newton iteration on a
    form of the equation that is convex in the unknown shift ``tau``, so Newton steps taken from
    the right of a root approach it monotonically and quadratically; bisection takes over only
    when a step would leave the bracket. The shift from the pole ``d_1`` (or ``d_m``) is the
    unknown, so a tiny smallest eigenvalue keeps full relative accuracy (it matters: kappa
    depends on it), which 30 plain bisections (V&F) would not give.

    Parameters
    ----------
    d : (m,) array
        Eigenvalues of the unmodified matrix, ascending, ``d_1 >= 0``.
    z : (c, m) array
        Unit update directions in the eigenbasis of ``d``, one per candidate.
    rho : (c,) array
        Update weights ``|q|^2 >= 0``.

    Returns
    -------
    lo, hi : (c,) arrays
        Smallest and largest eigenvalue of each updated matrix.
    """
    m = d.size
    if m == 1:
        return d[0] + rho * z[:, 0] ** 2, d[0] + rho * z[:, 0] ** 2
    z2 = z**2
    return _smallest_root(d, z2, rho), _largest_root(d, z2, rho)


def _smallest_root(d: FloatArray, z2: FloatArray, rho: FloatArray) -> FloatArray:
    # Unknown: tau = x - d_1 in (0, delta_2), delta_j = d_j - d_1. The equation is
    #   1 - c0 / tau + phi(tau) = 0,  c0 = rho z_1^2,
    #   phi(tau) = rho sum_{j>1} z_j^2 / (delta_j - tau).
    # Bunch, Nielsen & Sorensen (1978): keep the d_1 pole exact and model phi by
    # a + b / (delta_2 - tau), matching its value and slope at the current tau; the model
    # equation is a quadratic whose root in (0, delta_2) is the next iterate. Convergence is
    # quadratic and does not stall when the root sits close to either pole.
    delta = d[1:] - d[0]
    d2 = delta[0]
    tau = np.zeros(rho.shape)
    c0 = rho * z2[:, 0]
    # d2 = 0: d_1 repeats; c0 = 0: the update misses its eigenvector. Either way d_1 stays.
    live = c0 > 0.0
    if d2 <= 0.0 or not live.any():
        return d[0] + tau
    # Working arrays hold only the candidates still iterating: converged ones are dropped, so
    # a few slow candidates do not make every iteration cost a whole neighbourhood.
    idx = np.flatnonzero(live)
    c0, w = c0[idx], rho[idx, None] * z2[idx, 1:]
    lo = np.zeros(c0.shape)
    hi = np.minimum(d2, c0)  # c0 / tau = 1 + phi(tau) >= 1 bounds tau by c0
    # Start at the smallest eigenvalue of the leading 2 x 2 block: by interlacing it lies at
    # or right of the root, and it is exact when only two poles matter.
    w2 = w[:, 0]
    a, b2 = c0, d2 + w2
    t = 0.5 * (a + b2) - np.hypot(0.5 * (a - b2), np.sqrt(c0 * w2))
    # It can land on an end of the bracket (e.g. on the pole d_2 when z_2 = 0); start inside.
    t = np.where((t > 0.0) & (t < hi), t, 0.5 * hi)
    for _ in range(_MAX_ITER):
        inv = 1.0 / (delta - t[:, None])
        winv = w * inv
        phi = winv.sum(axis=1)
        dphi = (winv * inv).sum(axis=1)
        g = d2 - t
        b = dphi * g * g
        A = 1.0 + phi - b / g
        B = A * d2 + c0 + b
        C = c0 * d2
        new = 2.0 * C / (B + np.sqrt(np.maximum(B * B - 4.0 * A * C, 0.0)))
        # f = 1 + phi - c0 / t increases on the bracket: its sign moves one end (t = 0 is the
        # pole at -inf, so it only ever raises lo there).
        f = 1.0 + phi - c0 / np.maximum(t, 1e-300)
        hi = np.where(f > 0.0, np.minimum(hi, t), hi)
        lo = np.where(f < 0.0, np.maximum(lo, t), lo)
        done = np.abs(new - t) <= _NEWTON_RTOL * new
        inside = (new >= lo) & (new <= hi)
        t = np.where(inside | done, new, 0.5 * (lo + hi))
        if done.any():
            tau[idx[done]] = t[done]
            going = ~done
            if not going.any():
                break
            idx, c0, w, t, lo, hi = idx[going], c0[going], w[going], t[going], lo[going], hi[going]
    else:
        tau[idx] = t
    return d[0] + tau


def _largest_root(d: FloatArray, z2: FloatArray, rho: FloatArray) -> FloatArray:
    # tau = x - d_m solves G(tau) = tau - rho sum_j z_j^2 tau / (gamma_j + tau) = 0 with
    # gamma_j = d_m - d_j >= 0 (G is f times tau). G is convex with G(0) <= 0 <= G(rho), so
    # Newton from the right descends monotonically onto the largest root, started at rho.
    gamma = d[-1] - d
    live = rho > 0.0
    tau = np.zeros(rho.shape)
    if not live.any():
        return d[-1] + tau
    idx = np.flatnonzero(live)  # candidates still iterating, as in _smallest_root
    w = rho[idx, None] * z2[idx]
    wg = w * gamma
    # Start at the root of a lower bound of G: every pole but d_m moved onto the closest one
    # (gamma_j >= gamma_{m-1} for j < m). That root lies right of the true one, so Newton still
    # descends monotonically, and it is exact when d has two distinct values: a much closer
    # start than tau = rho.
    g1 = gamma[-2]
    wm = w[:, -1]
    r = rho[idx]
    t = 0.5 * ((r - g1) + np.sqrt((g1 - r) ** 2 + 4.0 * wm * g1))
    t = np.minimum(np.maximum(t, 0.0), r)
    # A zero upper bound pins the root at tau = 0 (lambda_max = d_m); Newton would divide by
    # gamma_m + 0 = 0 there.
    going = t > 0.0
    idx, w, wg, t = idx[going], w[going], wg[going], t[going]
    if idx.size == 0:
        return d[-1] + tau
    for _ in range(_MAX_ITER):
        inv = 1.0 / (gamma + t[:, None])
        G = t - t * (w * inv).sum(axis=1)
        dG = 1.0 - (wg * inv * inv).sum(axis=1)
        step = np.divide(G, dG, out=np.zeros_like(G), where=dG > 0.0)
        new = np.clip(t - step, 0.0, t)
        done = (t - new <= _NEWTON_RTOL * (d[-1] + t)) | (G <= 0.0)
        t = np.where(G <= 0.0, t, new)
        if done.any():
            tau[idx[done]] = t[done]
            going = ~done
            if not going.any():
                break
            idx, w, wg, t = idx[going], w[going], wg[going], t[going]
    else:
        tau[idx] = t
    return d[-1] + tau


def condition_numbers_fast(
    kept: ArrayLike, candidates: ArrayLike, cutoff: float = np.inf
) -> FloatArray:
    """``kappa`` of ``kept`` plus each candidate row, by the rank-one secular update.

    Same contract as :func:`condition_numbers_svd`: the kept rows' Gram matrix is decomposed
    once, then each candidate costs one projection and a few vectorized iterations.

    Parameters
    ----------
    kept : (n - 1, m) array_like
        Rows that stay, cut to the ``m`` objective columns.
    candidates : (c, m) array_like
        Rows to try as the ``n``-th row.
    cutoff : float
        Candidates whose ``kappa`` provably reaches ``cutoff`` are not solved for and get
        ``inf``. Interlacing on the trailing 2 x 2 block bounds ``lambda_max`` from below;
        one evaluation of the secular function at ``lambda_max_bound / cutoff^2`` then tells
        whether ``lambda_min`` is below that point (:func:`_may_beat`). A search that only
        wants improvements on its current ``kappa`` skips nearly every candidate this way.

    Returns
    -------
    (c,) array
        Condition numbers (``inf`` where singular or screened out).
    """
    q = np.asarray(candidates, dtype=float)
    spec = gram_spectrum(kept, q.shape[1])
    rho = np.einsum("ij,ij->i", q, q)
    proj = q @ spec.V
    norm = np.sqrt(rho)
    z = np.divide(proj, norm[:, None], out=np.zeros_like(proj), where=norm[:, None] > 0.0)
    out = np.full(q.shape[0], np.inf)
    d = spec.d
    if np.isfinite(cutoff) and d.size > 1:
        z2 = z * z
        hi_lb = _largest_lower_bound(d, z2, z[:, -2] * z[:, -1], rho)
        keep = np.flatnonzero(_may_beat(d, z2, rho, hi_lb, cutoff))
    else:
        keep = np.arange(q.shape[0])
    if keep.size:
        lo, hi = secular_extremes(d, z[keep], rho[keep])
        out[keep] = kappa_from_extremes(lo, hi)
    return out


def _largest_lower_bound(
    d: FloatArray, z2: FloatArray, zmm: FloatArray, rho: FloatArray
) -> FloatArray:
    """Lower bound on the largest eigenvalue of ``diag(d) + rho z z^T``, per candidate.

    By Cauchy interlacing the largest eigenvalue is at least that of the trailing 2 x 2 block
    (``zmm = z_{m-1} z_m``), which has a closed form.
    """
    a, b, c = d[-2] + rho * z2[:, -2], d[-1] + rho * z2[:, -1], rho * zmm
    return 0.5 * (a + b) + np.hypot(0.5 * (a - b), c)


# Relative slack of the screening tests: they only discard a candidate when it fails to beat
# the cutoff by more than round-off could explain, so the search (which wants a gain of
# MIN_GAIN) never loses a true improvement to screening.
_SCREEN_SLACK = 1e-11
# Smallest relative drop of kappa the search accepts as a move: far above the screening slack
# and the solver's accuracy, so the fast and the SVD objective accept the same moves.
MIN_GAIN = 1e-9


def _may_beat(
    d: FloatArray, z2: FloatArray, rho: FloatArray, hi_lb: FloatArray, cutoff: float
) -> NDArray[np.bool_]:
    """Which candidates may have ``kappa < cutoff``; the others provably do not.

    ``kappa^2 = hi / lo >= hi_lb / lo``, so a candidate cannot beat ``cutoff`` when its
    smallest eigenvalue ``lo`` is at most ``x* = hi_lb / cutoff^2``. ``lo`` is the root of the
    secular function ``f``, which increases on ``(d_1, d_2)``: ``lo <= x*`` exactly when
    ``x* >= d_2`` or ``f(x*) >= 0``. One evaluation of ``f`` per candidate (the cost of one
    solver iteration) thus settles most of a neighbourhood without solving for any root.
    """
    x = hi_lb * (1.0 - _SCREEN_SLACK) / cutoff**2
    tau = x - d[0]  # shift from the d_1 pole, as in _smallest_root, for relative accuracy
    delta = d[1:] - d[0]
    # x* <= d_1 <= lo: nothing to learn, keep. x* >= d_2 >= lo: reject. In between: test f.
    beyond = tau >= delta[0]
    keep = ~beyond
    test = np.flatnonzero((tau > 0.0) & ~beyond)
    if test.size:
        w = rho[test, None] * z2[test]
        t = tau[test]
        f = 1.0 - w[:, 0] / t + (w[:, 1:] / (delta - t[:, None])).sum(axis=1)
        keep[test] = f < 0.0
    return keep


def _svd_with_cutoff(kept: ArrayLike, candidates: ArrayLike, cutoff: float = np.inf) -> FloatArray:
    # The reference has no screening; the cutoff is accepted so both methods share a signature.
    return condition_numbers_svd(kept, candidates)


KAPPA_METHODS: dict[str, Callable[[ArrayLike, ArrayLike, float], FloatArray]] = {
    "fast": condition_numbers_fast,
    "svd": _svd_with_cutoff,
}
