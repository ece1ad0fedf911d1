"""The V&F neighbourhood search for the best-conditioned basis rows (Sec. 3.3, math.md 8).

From a random start, drop one row and try every candidate cell of its ``h x h x h``
neighbourhood, keeping the best if it lowers ``kappa`` (:mod:`gonio.brdf.design.conditioning`
scores a whole neighbourhood at once). With a
:class:`~gonio.brdf.design.mounting.MountPlanner` every design the search visits can be
mounted.

Everything here works on plain arrays (``Q`` and flat row indices); the grid shape is a
parameter so tests can use small synthetic grids.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.conditioning import (
    KAPPA_METHODS,
    MIN_GAIN,
    KappaMethod,
    block_width,
    condition_number,
)
from gonio.brdf.design.errors import DesignError, FeasibilityError
from gonio.brdf.design.mounting import Mounting, MountPlanner
from gonio.brdf.tables.geometry import SLICE_SHAPE

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# Random collision-free starts tried before a collision-aware search gives up.
_START_TRIES = 20


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
        was given a :class:`~gonio.brdf.design.mounting.MountPlanner`; None otherwise.
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
        room, :meth:`~gonio.brdf.design.mounting.MountPlanner.move`). When the best cell of a
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
    if method not in KAPPA_METHODS:
        raise DesignError(f"unknown kappa method {method!r}; use 'fast' or 'svd'")
    kappas = KAPPA_METHODS[method]
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
            "of room",
            "lower {min_device_distance_deg}, raise {max_elevation_deg} or ask for fewer pairs",
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
                    better = np.flatnonzero(values < kappa * (1.0 - MIN_GAIN))
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
