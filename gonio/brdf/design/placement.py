"""Collision-free lab placement of a finished design's independent pairs.

A pair's lab half-vector azimuth ``ph`` is free, so :func:`place_pairs` chooses one per pair
that keeps every two devices at least ``min_device_distance_deg`` apart and out of every
exclusion (:mod:`gonio.brdf.design.constraints`), widening the closest gap where it can.
:func:`check_devices` lists the violations of a product rig's devices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.constraints import (
    RigConstraints,
    angular_distance,
    device_ok,
    min_pairwise_distance,
    on_axis_ph,
    ph_options,
)
from gonio.brdf.design.errors import FeasibilityError
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Placement:
    """Lab placement of independent light/sensor pairs.

    Attributes
    ----------
    cells : (n, 3) array, radians
        ``(th, td, pd)`` of each pair.
    ph_lab : (n,) array, radians
        Lab half-vector azimuth chosen for each pair.
    lab_deg : (n, 4) array, degrees
        ``(theta_i, phi_i, theta_v, phi_v)``: light and sensor directions in the lab.
    min_distance_deg : float
        Smallest angle between any two mounted devices.
    """

    cells: FloatArray
    ph_lab: FloatArray
    lab_deg: FloatArray
    min_distance_deg: float


def lab_degrees(cells: ArrayLike, ph_lab: ArrayLike) -> FloatArray:
    """(n, 4) ``(theta_i, phi_i, theta_v, phi_v)`` degrees of cells placed at lab ``ph``."""
    c = np.asarray(cells, dtype=float).reshape(-1, 3)
    wi, wo = geo.half_diff_to_directions(c[:, 0], np.asarray(ph_lab, dtype=float), c[:, 1], c[:, 2])
    ti, pi = geo.direction_to_spherical(wi)
    to, po = geo.direction_to_spherical(wo)
    # Round-off can leave an azimuth a hair below 360; fold it to 0.
    out = np.rad2deg(np.stack([ti, pi, to, po], axis=-1))
    out[:, 1::2] = np.where(out[:, 1::2] > 360.0 - 1e-9, 0.0, out[:, 1::2])
    return out


def place_pairs(
    cells: ArrayLike,
    constraints: RigConstraints,
    *,
    ph_step_deg: float = 1.0,
    orderings: int = 20,
    seed: int = 0,
    initial_ph: ArrayLike | None = None,
) -> Placement:
    """Choose each pair's lab azimuth so no two mounted devices come too close.

    Greedy maximin: pairs are placed one after another (the most constrained first), each at
    the allowed azimuth that keeps its two devices farthest from every device placed so far.
    If some pair cannot keep ``min_device_distance_deg``, the placement is retried with
    shuffled orders. A known placement (``initial_ph``, e.g. from a collision-aware search)
    is tried first; every candidate placement is then spread by re-placing one of the closest
    two devices' pairs at a time while that widens the gap.

    Parameters
    ----------
    cells : (n, 3) array_like, radians
        ``(th, td, pd)`` of each pair.
    constraints : RigConstraints
    ph_step_deg : float
        Azimuth resolution of the search, degrees.
    orderings : int
        Orders tried before giving up.
    seed : int
        Seed for the shuffled orders.
    initial_ph : (n,) array_like, radians, optional
        Lab azimuth of each pair in a placement to start from; snapped to the
        ``ph_step_deg`` grid. When it (after spreading) keeps every device distance, the greedy
        orders are not needed.

    Returns
    -------
    Placement

    Raises
    ------
    FeasibilityError
        For zero pairs, a pair no azimuth can place (exclusions, elevation, separation), or
        when no order keeps every two devices far enough apart.
    """
    c = np.asarray(cells, dtype=float).reshape(-1, 3)
    n = c.shape[0]
    if n == 0:
        raise FeasibilityError("a design needs at least one pair")
    ph = ph_options(ph_step_deg)
    wi, wo = geo.half_diff_to_directions(c[:, None, 0], ph[None, :], c[:, None, 1], c[:, None, 2])
    allowed = device_ok(wi, constraints) & device_ok(wo, constraints) & on_axis_ph(c, ph)
    own = np.rad2deg(angular_distance(wi[:, 0], wo[:, 0]))
    for k in range(n):
        where = (
            f"pair {k} (th={np.rad2deg(c[k, 0]):.1f}, td={np.rad2deg(c[k, 1]):.1f}, "
            f"pd={np.rad2deg(c[k, 2]):.1f} deg)"
        )
        if not allowed[k].any():
            raise FeasibilityError(
                f"{where} cannot be placed at any azimuth: a device is above the max elevation "
                "or inside an excluded region; relax the constraints or drop the pair"
            )
        if own[k] < constraints.pair_separation_deg - 1e-6:
            raise FeasibilityError(
                f"{where}: its light and sensor are only {own[k]:.1f} deg apart, below the "
                f"required {constraints.pair_separation_deg:g} deg",
                "drop the pair or lower {min_separation_deg} / {min_device_distance_deg}",
            )
    need = math.radians(constraints.min_device_distance_deg)
    rng = np.random.default_rng(seed)
    base = np.argsort(allowed.sum(axis=1), kind="stable")
    best: tuple[float, NDArray[np.intp]] | None = None
    if initial_ph is not None:
        start = np.asarray(initial_ph, dtype=float).ravel()
        if start.shape != (n,):
            raise FeasibilityError(f"initial_ph needs one azimuth per pair ({n}), got {start.size}")
        step = math.radians(ph_step_deg)
        choice = np.mod(np.rint(np.mod(start, 2.0 * math.pi) / step), ph.size).astype(np.intp)
        if allowed[np.arange(n), choice].all():
            best = (_repair(wi, wo, allowed, choice), choice.copy())
    for attempt in range(max(1, orderings)):
        if best is not None and best[0] >= need - 1e-9:
            break
        order = base if attempt == 0 else rng.permutation(n)
        choice = _greedy(wi, wo, allowed, order)
        worst = _repair(wi, wo, allowed, choice)
        if best is None or worst > best[0]:
            best = (worst, choice.copy())
    assert best is not None
    worst, choice = best
    if worst < need - 1e-9:
        raise FeasibilityError(
            f"cannot mount {n} pairs with every two devices at least "
            f"{constraints.min_device_distance_deg:g} deg apart (best found: "
            f"{math.degrees(worst):.1f} deg after {orderings} orders)",
            "lower {min_device_distance_deg} or ask for fewer pairs",
        )
    ph_lab = ph[choice]
    all_dirs = np.concatenate([wi[np.arange(n), choice], wo[np.arange(n), choice]])
    return Placement(
        cells=c,
        ph_lab=ph_lab,
        lab_deg=lab_degrees(c, ph_lab),
        min_distance_deg=math.degrees(min_pairwise_distance(all_dirs)),
    )


#: Dot-product margin within which a device still counts as a possible nearest one. For unit
#: vectors the angle grows at least as fast as the dot product falls (|d cos(t)/dt| <= 1), and
#: both the matrix product and ``angular_distance`` are off by a few 1e-16, so a device more
#: than this below the largest dot product has a larger ``angular_distance`` than the device
#: with the largest one, whatever the rounding. Candidates get ``angular_distance`` itself, so
#: the minimum is the very float the full matrix holds.
_NEAR_MARGIN = 1e-9


def _nearest_angles(a: FloatArray, b: FloatArray) -> FloatArray:
    """(m,) smallest angle (radians) from each of ``a`` (m, 3) to any of ``b`` (k >= 1, 3).

    Bit for bit ``angular_distance(a[:, None], b[None]).min(axis=1)`` for finite unit vectors:
    the nearest by angle is the one with the largest dot product, so one matrix product finds
    the few devices within :data:`_NEAR_MARGIN` of it and only those get the exact angle.
    """
    dots = a @ b.T
    rows, cols = np.nonzero(dots >= dots.max(axis=1, keepdims=True) - _NEAR_MARGIN)
    angles = angular_distance(a[rows], b[cols])
    # Every row keeps at least its own maximum, and nonzero lists the rows in order.
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    return np.minimum.reduceat(angles, starts)


def _closest_two(dirs: FloatArray) -> tuple[float, int, int]:
    """Smallest angle (radians) between two of ``dirs`` (m >= 2, 3) and the indices ``(a, b)``.

    Bit for bit the minimum and the first (row-major) argmin of the full
    ``angular_distance`` matrix with an infinite diagonal, for finite unit vectors (see
    :func:`_nearest_angles`): every entry that can reach the minimum is among the candidates,
    which ``np.nonzero`` lists in row-major order.
    """
    dots = dirs @ dirs.T
    np.fill_diagonal(dots, -math.inf)
    rows, cols = np.nonzero(dots >= dots.max() - _NEAR_MARGIN)
    angles = angular_distance(dirs[rows], dirs[cols])
    i = int(np.argmin(angles))
    return float(angles[i]), int(rows[i]), int(cols[i])


def _distances_to(wi: FloatArray, wo: FloatArray, k: int, dev: FloatArray) -> FloatArray:
    """(P,) smallest angle from pair ``k``'s two devices, at each azimuth, to devices ``dev``."""
    if dev.shape[0] == 0:
        return np.full(wi.shape[1], math.inf)
    p = wi.shape[1]
    near = _nearest_angles(np.concatenate([wi[k], wo[k]]), dev)
    return np.minimum(near[:p], near[p:])


def _greedy(
    wi: FloatArray, wo: FloatArray, allowed: BoolArray, order: NDArray[np.intp]
) -> NDArray[np.intp]:
    """Place pairs in ``order``, each at the allowed azimuth farthest from those placed."""
    choice = np.zeros(wi.shape[0], dtype=np.intp)
    placed: list[FloatArray] = []
    for k in order:
        dev = np.stack(placed) if placed else np.zeros((0, 3))
        dist = np.where(allowed[k], _distances_to(wi, wo, int(k), dev), -math.inf)
        choice[k] = int(np.argmax(dist))
        placed.extend([wi[k, choice[k]], wo[k, choice[k]]])
    return choice


def _repair(
    wi: FloatArray, wo: FloatArray, allowed: BoolArray, choice: NDArray[np.intp], rounds: int = 100
) -> float:
    """Coordinate ascent on the closest two devices; updates ``choice``, returns its min distance.

    Greedy placement fixes early pairs before it knows the later ones; re-placing one pair of
    the currently closest couple, with every other pair held, often opens the gap.
    """
    n = wi.shape[0]
    idx = np.arange(n)

    def devices() -> FloatArray:
        return np.concatenate([wi[idx, choice], wo[idx, choice]])

    def closest() -> tuple[float, tuple[int, int]]:
        d, a, b = _closest_two(devices())
        return d, (a % n, b % n)

    if n < 2:
        return math.inf
    worst, culprits = closest()
    for _ in range(rounds):
        improved = False
        for k in culprits:
            rest = idx != k
            others = np.concatenate([wi[rest, choice[rest]], wo[rest, choice[rest]]])
            own = angular_distance(wi[k], wo[k])  # the pair's own two devices, per azimuth
            dist = np.minimum(_distances_to(wi, wo, k, others), own)
            dist = np.where(allowed[k], dist, -math.inf)
            j = int(np.argmax(dist))
            old = choice[k]
            choice[k] = j
            new_worst, new_culprits = closest()
            if new_worst > worst + 1e-12:
                worst, culprits, improved = new_worst, new_culprits, True
                break
            choice[k] = old
        if not improved:
            break
    return worst


def check_devices(
    lights: ArrayLike, sensors: ArrayLike, constraints: RigConstraints
) -> list[str]:
    """Constraint violations of a product rig's device directions (empty when feasible).

    Parameters
    ----------
    lights : (L, 3) array_like
        Light directions in the lab (unit vectors).
    sensors : (S, 3) array_like
        Sensor directions in the lab.
    """
    li = np.asarray(lights, dtype=float).reshape(-1, 3)
    se = np.asarray(sensors, dtype=float).reshape(-1, 3)
    problems: list[str] = []
    for label, dirs in (("light", li), ("sensor", se)):
        bad = ~device_ok(dirs, constraints)
        problems += [
            f"{label} {k} is above the max elevation or excluded" for k in np.flatnonzero(bad)
        ]
    sep = np.rad2deg(angular_distance(li[:, None, :], se[None, :, :]))
    if sep.size and sep.min() < constraints.min_separation_deg - 1e-6:
        problems.append(
            f"a light and a sensor are {sep.min():.1f} deg apart "
            f"(< {constraints.min_separation_deg:g})"
        )
    dmin = math.degrees(min_pairwise_distance(np.concatenate([li, se])))
    if dmin < constraints.min_device_distance_deg - 1e-6:
        problems.append(
            f"two devices are {dmin:.1f} deg apart (< {constraints.min_device_distance_deg:g})"
        )
    return problems
