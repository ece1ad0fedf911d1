"""Choosing sampling directions: the condition-number objective and its search (MATH 6).

A design is a set of ``n`` rows of the basis matrix ``Q`` (one row per grid cell
``(th, td, pd)``). Reconstruction solves for the basis coefficients from those rows, so the
design is judged by the condition number ``kappa`` of the selected rows restricted to the first
``m = min(n, K)`` columns: a square block when ``n <= K`` (as NJR15 and V&F do), a tall
``n x K`` block otherwise.

The search is V&F's neighbourhood search (Sec. 3.3): from a random start, drop one row and try
every candidate cell of its ``h x h x h`` neighbourhood, keeping the best if it lowers ``kappa``.
Each trial is a rank-one update of the Gram matrix of the kept rows, so its extreme eigenvalues
are roots of the secular equation (V&F App. B, Golub 1973). :func:`condition_numbers_fast`
solves it for all candidates of a neighbourhood at once; :func:`condition_numbers_svd` is the
plain-SVD reference it is tested against.

Everything here works on plain arrays (``Q`` and flat row indices); the grid shape is a
parameter so tests can use small synthetic grids.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.feasibility import (
    FeasibilityError,
    Mounting,
    MountPlanner,
    RigConstraints,
    angular_distance,
    candidate_rows,
    device_ok,
    min_pairwise_distance,
    place_pairs,
    rows_to_cells,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.geometry import SLICE_SHAPE

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
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
# Random collision-free starts tried before a collision-aware search gives up.
_START_TRIES = 20


class DesignError(ValueError):
    """A sampling design that cannot be computed as asked (bad n, too few candidates ...)."""


def block_width(n: int, n_components: int) -> int:
    """Columns of ``Q`` the objective uses for ``n`` rows: ``min(n, K)``."""
    return min(int(n), int(n_components))


def _kappa_from_extremes(lo: FloatArray, hi: FloatArray) -> FloatArray:
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
    return float(_kappa_from_extremes(np.array(s[-1] ** 2), np.array(s[0] ** 2)))


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
    return _kappa_from_extremes(s[:, -1] ** 2, s[:, 0] ** 2)


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
        out[keep] = _kappa_from_extremes(lo, hi)
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
# _MIN_GAIN) never loses a true improvement to screening.
_SCREEN_SLACK = 1e-11
# Smallest relative drop of kappa the search accepts as a move: far above the screening slack
# and the solver's accuracy, so the fast and the SVD objective accept the same moves.
_MIN_GAIN = 1e-9


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


_KAPPA_METHODS: dict[str, Callable[[ArrayLike, ArrayLike, float], FloatArray]] = {
    "fast": condition_numbers_fast,
    "svd": _svd_with_cutoff,
}


def neighbourhood(
    flat: int, h: int, grid_shape: tuple[int, int, int] = SLICE_SHAPE
) -> IntArray:
    """Flat indices of the ``h x h x h`` cells around ``flat`` (including itself).

    The first two axes (``th``, ``td``) are clipped at the grid edges; the last (``pd``) wraps,
    since ``pd`` is periodic with period pi.
    """
    if h < 1 or h % 2 == 0:
        raise DesignError(f"neighbourhood size h must be an odd number >= 1, got {h}")
    i, j, k = (int(v) for v in np.unravel_index(flat, grid_shape))
    r = h // 2
    ii = np.arange(max(0, i - r), min(grid_shape[0], i + r + 1))
    jj = np.arange(max(0, j - r), min(grid_shape[1], j + r + 1))
    kk = np.unique(np.mod(np.arange(k - r, k + r + 1), grid_shape[2]))
    a, b, c = np.meshgrid(ii, jj, kk, indexing="ij")
    return np.ravel_multi_index((a.ravel(), b.ravel(), c.ravel()), grid_shape).astype(np.intp)


@dataclass(frozen=True)
class SearchResult:
    """Outcome of :func:`optimize_rows`.

    Attributes
    ----------
    rows : (n,) int array
        Selected flat row indices of ``Q`` (sorted).
    kappa : float
        Their condition number over the first ``min(n, K)`` columns.
    evaluations : int
        Candidate rows whose ``kappa`` was evaluated.
    neighbourhoods : int
        Neighbourhoods searched (one secular or SVD batch each).
    seconds : float
        Wall time of the search.
    history : list of float
        Final ``kappa`` of every descent, in order.
    ph_lab : (n,) array, radians, or None
        Collision-free lab azimuth of each row (in the order of ``rows``) when the search
        was given a :class:`~gonio.brdf.design.feasibility.MountPlanner`; None otherwise.
    """

    rows: IntArray
    kappa: float
    evaluations: int
    neighbourhoods: int
    seconds: float
    history: list[float] = field(default_factory=list)
    ph_lab: FloatArray | None = None


def optimize_rows(
    Q: ArrayLike,
    candidates: ArrayLike,
    n: int,
    *,
    h: int = 7,
    starts: int = 10,
    descents: int = 10,
    seed: int | None = 0,
    method: KappaMethod = "fast",
    grid_shape: tuple[int, int, int] = SLICE_SHAPE,
    time_limit_s: float | None = None,
    mounts: MountPlanner | None = None,
) -> SearchResult:
    """V&F neighbourhood search for ``n`` rows of ``Q`` with the lowest condition number.

    Steps (V&F Sec. 3.3): (1) pick ``n`` random candidate rows; (2) drop a random row and move
    it to the best cell of its ``h x h x h`` neighbourhood if that lowers ``kappa``; (3) repeat
    until every row has been tried once without improvement; (4) restore the start and
    descend again, ``descents`` times in all; (5) repeat from (1), ``starts`` times in all.

    Parameters
    ----------
    Q : (p, K) array_like
        Basis rows, ``p = prod(grid_shape)``.
    candidates : (c,) array_like of int
        Flat rows that may be chosen (valid and feasible cells).
    n : int
        Number of rows (pairs) to choose, ``1 <= n <= c``.
    h : int
        Odd neighbourhood size (V&F: 7).
    starts, descents : int
        Random starts, and descents from each start (V&F: 10 and 10).
    seed : int or None
        Seed of the random generator; the same seed gives the same design.
    method : {"fast", "svd"}
        Secular-equation update or the plain-SVD reference.
    grid_shape : tuple of 3 ints
        Shape of the ``(th, td, pd)`` grid behind the flat indices.
    time_limit_s : float, optional
        Stop starting new descents after this many seconds (the best design so far is kept).
    mounts : MountPlanner, optional
        Make the search collision-aware (standard grid only): every start is a random
        collision-free design, each row carries a lab azimuth, and a move is taken only when
        the new cell can be mounted beside the other pairs (one of which may turn to make
        room, :meth:`~gonio.brdf.design.feasibility.MountPlanner.move`). When the best cell of a
        neighbourhood cannot be mounted, the next best improving one is tried. Every design
        the search visits, and so the one it returns, is mountable.

    Returns
    -------
    SearchResult

    Raises
    ------
    DesignError
        For bad arguments.
    FeasibilityError
        When ``mounts`` is given and no random start of ``n`` pairs can be mounted.
    """
    Qa = np.asarray(Q, dtype=float)
    cand = np.unique(np.asarray(candidates, dtype=np.intp).ravel())
    if Qa.ndim != 2 or Qa.shape[0] != int(np.prod(grid_shape)):
        raise DesignError(
            f"Q must have one row per grid cell ({int(np.prod(grid_shape))}), got shape {Qa.shape}"
        )
    if n < 1:
        raise DesignError(f"the number of pairs must be at least 1, got {n}")
    if cand.size == 0:
        raise DesignError("no candidate cells: every cell was ruled out; relax the constraints")
    if n > cand.size:
        raise DesignError(
            f"{n} pairs asked for but only {cand.size} feasible cells exist; "
            "ask for fewer pairs or relax the constraints"
        )
    if method not in _KAPPA_METHODS:
        raise DesignError(f"unknown kappa method {method!r}; use 'fast' or 'svd'")
    kappas = _KAPPA_METHODS[method]
    m = block_width(n, Qa.shape[1])
    A = Qa[:, :m]
    is_cand = np.zeros(Qa.shape[0], dtype=bool)
    is_cand[cand] = True
    # Neighbourhoods of candidate cells, restricted to candidates, built once on demand.
    near_cache: dict[int, IntArray] = {}

    def near_of(flat: int) -> IntArray:
        got = near_cache.get(flat)
        if got is None:
            got = neighbourhood(flat, h, grid_shape)
            got = got[is_cand[got]]
            near_cache[flat] = got
        return got

    if mounts is not None and grid_shape != SLICE_SHAPE:
        raise DesignError("a collision-aware search (mounts) needs the standard (18, 18, 36) grid")

    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()

    def random_start() -> tuple[IntArray, Mounting | None]:
        if mounts is None:
            return rng.choice(cand, size=n, replace=False), None
        for _ in range(_START_TRIES):
            got = mounts.start(rng, cand, n)
            if got is not None:
                return got
        c = mounts.constraints
        raise FeasibilityError(
            f"cannot mount {n} pairs with every two devices at least "
            f"{c.min_device_distance_deg:g} deg apart: {_START_TRIES} random designs all ran out "
            "of room; lower --min-device-distance, raise --max-elevation or ask for fewer pairs"
        )

    # A random design to return if the time limit stops the search before any descent.
    best_rows, best_mount = random_start()
    best_kappa = condition_number(A[best_rows])
    evaluations = 0
    searched = 0
    history: list[float] = []
    taken = np.zeros(Qa.shape[0], dtype=bool)
    for _ in range(starts):
        start, start_mount = random_start()
        for _ in range(descents):
            if time_limit_s is not None and time.perf_counter() - t0 > time_limit_s:
                break
            sel = start.copy()
            mount = None if start_mount is None else start_mount.copy()
            taken[:] = False
            taken[sel] = True
            kappa = condition_number(A[sel])
            # settled[slot] = number of moves made when that slot last found no move; while
            # no move happens after that, trying it again would give the same answer.
            moves = 0
            settled = np.full(n, -1)
            improved = True
            while improved:
                # One sweep tries every row once in random order; a sweep with no accepted
                # move means no single move helps: this descent has converged.
                improved = False
                for slot in rng.permutation(n):
                    if settled[slot] == moves:
                        continue
                    settled[slot] = moves
                    current = int(sel[slot])
                    others = np.delete(sel, slot)
                    near = near_of(current)
                    # The current cell is left out: its kappa is the current one, and
                    # screening cannot rule it out (it does not beat itself by round-off).
                    near = near[~taken[near]]
                    if near.size == 0:
                        continue
                    values = kappas(A[others], A[near], kappa)
                    evaluations += near.size
                    searched += 1
                    better = np.flatnonzero(values < kappa * (1.0 - _MIN_GAIN))
                    # Best first; with mounts, a cell that collides gives way to the next.
                    for k in better[np.argsort(values[better], kind="stable")]:
                        if (mount is not None and mounts is not None
                                and not mounts.move(mount, int(slot), int(near[k]))):
                            continue
                        taken[current] = False
                        taken[near[k]] = True
                        sel[slot] = near[k]
                        kappa = float(values[k])
                        improved = True
                        moves += 1
                        break
            history.append(kappa)
            if kappa < best_kappa:
                best_kappa, best_rows, best_mount = kappa, sel.copy(), mount
    order = np.argsort(best_rows)
    ph_lab = None
    if best_mount is not None and mounts is not None:
        ph_lab = mounts.ph[best_mount.az[order]]
    return SearchResult(
        rows=best_rows[order],
        kappa=condition_number(A[best_rows]),
        evaluations=evaluations,
        neighbourhoods=searched,
        seconds=time.perf_counter() - t0,
        history=history,
        ph_lab=ph_lab,
    )


# ---------------------------------------------------------------------------- basis adapters
RowsAt = Callable[[FloatArray, FloatArray, FloatArray], FloatArray]


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
) -> PairDesign:
    """Optimize ``n`` independent light/sensor pairs and place them in the lab.

    Candidates are the basis's valid cells that ``constraints`` allow
    (:func:`gonio.brdf.design.feasibility.candidate_rows`). The search is :func:`optimize_rows` with
    a :class:`~gonio.brdf.design.feasibility.MountPlanner`, so every design it visits can be mounted
    with ``min_device_distance_deg`` between any two devices and outside every exclusion. The
    search's placement is then spread by :func:`gonio.brdf.design.feasibility.place_pairs` (it keeps
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
    return PairDesign(
        name="optimized",
        cells=placement.cells,
        ph_lab=placement.ph_lab,
        lights_deg=placement.lab_deg[:, :2],
        sensors_deg=placement.lab_deg[:, 2:],
        pairs=np.stack([np.arange(n), np.arange(n)], axis=1).astype(np.intp),
        kappa=result.kappa,
        min_distance_deg=placement.min_distance_deg,
        search=result,
    )


# ---------------------------------------------------------------------------- product rigs
def _lab_grid(constraints: RigConstraints, step_deg: float) -> FloatArray:
    """(P, 2) ``(theta, phi)`` radians of device positions on a lab grid within max elevation."""
    thetas = np.arange(0.0, constraints.max_elevation_deg + 1e-9, step_deg)
    phis = np.arange(0.0, 360.0 - 1e-9, step_deg)
    t, p = np.meshgrid(thetas, phis, indexing="ij")
    # The zenith is one position, not one per azimuth.
    keep = (t > 0) | (p == 0)
    return np.deg2rad(np.stack([t[keep], p[keep]], axis=1))


def product_kappa(rows_at: RowsAt, lights: FloatArray, sensors: FloatArray) -> FloatArray:
    """``kappa`` of the ``L * S`` pairs induced by batches of light and sensor directions.

    Parameters
    ----------
    rows_at : callable
        ``(th, td, pd) -> (n, K)`` basis rows at off-grid cells (``Basis.rows_at``).
    lights : (B, L, 3) array
        Light directions of ``B`` candidate rigs.
    sensors : (B, S, 3) array
        Sensor directions of the same rigs.

    Returns
    -------
    (B,) array
        Condition numbers over the first ``min(L S, K)`` columns.
    """
    B, L, _ = lights.shape
    S = sensors.shape[1]
    wi = np.broadcast_to(lights[:, :, None, :], (B, L, S, 3))
    wo = np.broadcast_to(sensors[:, None, :, :], (B, L, S, 3))
    th, _, td, pd = geo.directions_to_half_diff(wi, wo)
    rows = rows_at(th.ravel(), td.ravel(), pd.ravel())
    m = block_width(L * S, rows.shape[1])
    blocks = rows[:, :m].reshape(B, L * S, m)
    s = np.asarray(np.linalg.svd(blocks, compute_uv=False), dtype=float)
    return _kappa_from_extremes(s[:, -1] ** 2, s[:, 0] ** 2)


def _random_rig(
    grid_dirs: FloatArray, is_light: NDArray[np.bool_], constraints: RigConstraints,
    rng: np.random.Generator, tries: int = 200,
) -> IntArray | None:
    """Grid indices of a random feasible rig (devices placed one by one), or None."""
    need = np.deg2rad(constraints.min_device_distance_deg)
    sep = np.deg2rad(max(constraints.min_separation_deg, constraints.min_device_distance_deg))
    ok_single = device_ok(grid_dirs, constraints)
    for _ in range(tries):
        chosen: list[int] = []
        for k in range(is_light.size):
            allowed = ok_single.copy()
            for j, c in enumerate(chosen):
                limit = sep if is_light[j] != is_light[k] else need
                allowed &= angular_distance(grid_dirs, grid_dirs[c]) >= limit - 1e-9
            opts = np.flatnonzero(allowed)
            if opts.size == 0:
                break
            chosen.append(int(rng.choice(opts)))
        else:
            return np.array(chosen, dtype=np.intp)
    return None


def design_product_rig(
    basis: BasisLike,
    n_lights: int,
    n_sensors: int,
    constraints: RigConstraints,
    *,
    step_deg: float = 5.0,
    h: int = 7,
    starts: int = 10,
    seed: int | None = 0,
    time_limit_s: float | None = None,
) -> PairDesign:
    """Place ``L`` lights and ``S`` sensors so the ``L * S`` induced pairs condition well.

    Every light pairs with every sensor, so moving one device changes a whole row or column
    of pairs at once, and each induced cell depends on both directions; the rank-one update
    does not apply. The search is the same neighbourhood scheme on the devices instead of the
    cells: devices live on a ``step_deg`` lab grid (elevation up to the limit, all azimuths);
    one device at a time moves to the best feasible position in its ``h x h`` (elevation x
    azimuth) neighbourhood, scored by a batched SVD of every candidate rig's ``L S x m`` block,
    until no device moves; ``starts`` random feasible starts.

    Parameters
    ----------
    basis : BasisLike
    n_lights, n_sensors : int
        ``L`` and ``S`` (at least 1 each).
    constraints : RigConstraints
        Elevation limit, light-sensor separation, device distance and exclusions are enforced
        on the devices themselves.
    step_deg : float
        Lab grid step, degrees.
    h : int
        Odd neighbourhood size in grid steps.
    starts : int
        Random starts.
    seed : int or None
    time_limit_s : float, optional
        Stop starting new descents after this many seconds.

    Returns
    -------
    PairDesign
        Named ``product``; ``pairs`` lists every ``(light, sensor)`` combination.
    """
    if n_lights < 1 or n_sensors < 1:
        raise DesignError(
            f"a product rig needs at least one light and one sensor, got {n_lights} and {n_sensors}"
        )
    if h < 1 or h % 2 == 0:
        raise DesignError(f"neighbourhood size h must be an odd number >= 1, got {h}")
    grid = _lab_grid(constraints, step_deg)
    gdirs = geo.spherical_to_direction(grid[:, 0], grid[:, 1])
    n_t = int(constraints.max_elevation_deg // step_deg) + 1
    n_p = round(360.0 / step_deg)
    is_light = np.array([True] * n_lights + [False] * n_sensors)
    nd = is_light.size
    need = np.deg2rad(constraints.min_device_distance_deg)
    sep = np.deg2rad(max(constraints.min_separation_deg, constraints.min_device_distance_deg))
    ok_single = device_ok(gdirs, constraints)
    # Grid index of (i_theta, i_phi); the zenith (i_theta = 0) is index 0 for every azimuth.
    def index_of(it: IntArray, ip: IntArray) -> IntArray:
        return np.where(it == 0, 0, 1 + (it - 1) * n_p + np.mod(ip, n_p))

    def coords_of(g: int) -> tuple[int, int]:
        return (0, 0) if g == 0 else (1 + (g - 1) // n_p, (g - 1) % n_p)

    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    best: tuple[float, IntArray] | None = None
    r = h // 2
    for _ in range(starts):
        if time_limit_s is not None and time.perf_counter() - t0 > time_limit_s:
            break
        rig = _random_rig(gdirs, is_light, constraints, rng)
        if rig is None:
            continue
        kappa = float(product_kappa(basis.rows_at, gdirs[rig][None, :n_lights],
                                    gdirs[rig][None, n_lights:])[0])
        improved = True
        while improved:
            improved = False
            for k in rng.permutation(nd):
                it, ip = coords_of(int(rig[k]))
                ti = np.arange(max(0, it - r), min(n_t, it + r + 1))
                pi = np.arange(ip - r, ip + r + 1)
                cand = np.unique(index_of(np.repeat(ti, pi.size), np.tile(pi, ti.size)))
                others = np.delete(np.arange(nd), k)
                allowed = ok_single[cand].copy()
                for j in others:
                    limit = sep if is_light[j] != is_light[k] else need
                    allowed &= angular_distance(gdirs[cand], gdirs[rig[j]]) >= limit - 1e-9
                cand = cand[allowed]
                if cand.size == 0:
                    continue
                rigs = np.repeat(rig[None, :], cand.size, axis=0)
                rigs[:, k] = cand
                dirs = gdirs[rigs]
                values = product_kappa(basis.rows_at, dirs[:, :n_lights], dirs[:, n_lights:])
                best_j = int(np.argmin(values))
                if values[best_j] < kappa * (1.0 - 1e-12):
                    rig, kappa, improved = rigs[best_j], float(values[best_j]), True
        if best is None or kappa < best[0]:
            best = (kappa, rig.copy())
    if best is None:
        raise FeasibilityError(
            f"could not place {n_lights} lights and {n_sensors} sensors under these constraints "
            "(elevation, separation, device distance, exclusions); relax them or use fewer devices"
        )
    _, rig = best
    dirs = gdirs[rig]
    pairs = np.array([(a, b) for a in range(n_lights) for b in range(n_sensors)], dtype=np.intp)
    design = geometry_design(basis, "product", dirs[:n_lights], dirs[n_lights:], pairs)
    return design
