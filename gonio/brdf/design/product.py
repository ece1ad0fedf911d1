"""Product rigs: ``L`` lights and ``S`` sensors where every light pairs with every sensor."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.design.conditioning import block_width, kappa_from_extremes
from gonio.brdf.design.constraints import RigConstraints, angular_distance, device_ok
from gonio.brdf.design.errors import DesignError, FeasibilityError
from gonio.brdf.design.pairs import BasisLike, PairDesign, geometry_design
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
RowsAt = Callable[[FloatArray, FloatArray, FloatArray], FloatArray]


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
    return kappa_from_extremes(s[:, -1] ** 2, s[:, 0] ** 2)


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
