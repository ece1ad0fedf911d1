"""What a rig can physically measure: candidate cells and collision-free lab placements.

A light/sensor pair measures one half/difference cell ``(th, td, pd)`` for every stage angle
(MATH 2). Which cells a rig can offer is limited by its mounts (MATH 6):

* both devices at most ``max_elevation_deg`` from the normal (grazing readings are noisy and
  low mounts shadow the specimen);
* the light and the sensor of a pair at least ``min_separation_deg`` apart (``2 td``): they
  cannot share a mount;
* no device inside an excluded region of the lab: a cone around a lab direction (a camera,
  the stage arm) or an elevation/azimuth box;
* any two mounted devices at least ``min_device_distance_deg`` apart.

The first two do not depend on where the pair sits in azimuth; exclusions and device distances
do. A pair's lab half-vector azimuth ``ph`` is free (the stage sweeps it anyway and it does not
change the condition number), so :func:`place_pairs` chooses it to keep devices apart.

Angles are degrees in the public data classes (they come from users) and radians in the
array functions, as everywhere in ``gonio.brdf``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


class FeasibilityError(ValueError):
    """Constraints that rule out the design asked for; the message says what to relax."""


@dataclass(frozen=True)
class ConeExclusion:
    """No device within ``radius_deg`` of the lab direction ``(theta_deg, phi_deg)``."""

    theta_deg: float
    phi_deg: float
    radius_deg: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.theta_deg <= 180.0:
            raise FeasibilityError(f"cone exclusion theta {self.theta_deg} deg is not in [0, 180]")
        if not 0.0 < self.radius_deg < 180.0:
            raise FeasibilityError(
                f"cone exclusion radius {self.radius_deg} deg is not in (0, 180)"
            )

    def contains(self, dirs: ArrayLike) -> BoolArray:
        """Whether lab directions ``dirs`` (..., 3) lie inside the cone."""
        axis = geo.spherical_to_direction(np.deg2rad(self.theta_deg), np.deg2rad(self.phi_deg))
        cos_r = math.cos(math.radians(self.radius_deg))
        return np.asarray(np.asarray(dirs, dtype=float) @ axis > cos_r - 1e-12)

    def describe(self) -> str:
        return f"cone of {self.radius_deg:g} deg around ({self.theta_deg:g}, {self.phi_deg:g})"


@dataclass(frozen=True)
class BoxExclusion:
    """No device with elevation in ``[theta_min, theta_max]`` and azimuth in ``[phi_min, phi_max]``.

    Azimuths are taken mod 360; ``phi_min > phi_max`` wraps through 0 (``350..10``).
    """

    theta_min_deg: float
    theta_max_deg: float
    phi_min_deg: float
    phi_max_deg: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.theta_min_deg <= self.theta_max_deg <= 90.0:
            raise FeasibilityError(
                f"box exclusion elevations {self.theta_min_deg}..{self.theta_max_deg} deg must "
                "satisfy 0 <= min <= max <= 90"
            )

    def contains(self, dirs: ArrayLike) -> BoolArray:
        """Whether lab directions ``dirs`` (..., 3) lie inside the box."""
        theta, phi = geo.direction_to_spherical(dirs)
        t = np.rad2deg(theta)
        p = np.mod(np.rad2deg(phi), 360.0)
        lo, hi = self.phi_min_deg % 360.0, self.phi_max_deg % 360.0
        in_phi = (p >= lo) & (p <= hi) if lo <= hi else (p >= lo) | (p <= hi)
        if self.phi_max_deg - self.phi_min_deg >= 360.0:
            in_phi = np.ones_like(in_phi)
        tol = 1e-9
        in_theta = (t >= self.theta_min_deg - tol) & (t <= self.theta_max_deg + tol)
        return np.asarray(in_theta & in_phi)

    def describe(self) -> str:
        return (
            f"box theta {self.theta_min_deg:g}..{self.theta_max_deg:g}, "
            f"phi {self.phi_min_deg:g}..{self.phi_max_deg:g} deg"
        )


Exclusion = ConeExclusion | BoxExclusion


def parse_exclusion(text: str) -> Exclusion:
    """Parse ``cone:THETA,PHI,RADIUS`` or ``box:THETA_MIN,THETA_MAX,PHI_MIN,PHI_MAX`` (degrees)."""
    kind, _, rest = text.partition(":")
    kind = kind.strip().lower()
    try:
        values = [float(v) for v in rest.split(",")] if rest.strip() else []
    except ValueError:
        values = []
    if kind == "cone" and len(values) == 3:
        return ConeExclusion(*values)
    if kind == "box" and len(values) == 4:
        return BoxExclusion(*values)
    raise FeasibilityError(
        f"cannot read exclusion {text!r}; write cone:THETA,PHI,RADIUS (e.g. cone:0,0,8 keeps "
        "devices 8 deg away from the normal) or box:THETA_MIN,THETA_MAX,PHI_MIN,PHI_MAX "
        "(e.g. box:60,90,80,100), all in degrees"
    )


@dataclass(frozen=True)
class RigConstraints:
    """Mounting limits of a rig (degrees).

    Attributes
    ----------
    max_elevation_deg : float
        Largest device angle from the surface normal, in (0, 90).
    min_separation_deg : float
        Smallest angle between the light and the sensor of a pair (``2 td``).
    min_device_distance_deg : float
        Smallest angle between any two mounted devices (also within a pair).
    exclusions : tuple of ConeExclusion or BoxExclusion
        Lab regions where no device may sit.
    """

    max_elevation_deg: float = 80.0
    min_separation_deg: float = 10.0
    min_device_distance_deg: float = 10.0
    exclusions: tuple[Exclusion, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not 0.0 < self.max_elevation_deg < 90.0:
            raise FeasibilityError(
                f"max elevation {self.max_elevation_deg} deg must be in (0, 90): it is the largest "
                "angle between a device and the specimen normal"
            )
        for name, v in (
            ("min separation", self.min_separation_deg),
            ("min device distance", self.min_device_distance_deg),
        ):
            if not 0.0 <= v < 180.0:
                raise FeasibilityError(f"{name} {v} deg must be in [0, 180)")

    @property
    def pair_separation_deg(self) -> float:
        """Smallest light-sensor angle of one pair: both limits apply to it."""
        return max(self.min_separation_deg, self.min_device_distance_deg)


def excluded(dirs: ArrayLike, exclusions: Sequence[Exclusion]) -> BoolArray:
    """Whether lab directions (..., 3) fall in any of ``exclusions``."""
    d = np.asarray(dirs, dtype=float)
    out = np.zeros(d.shape[:-1], dtype=bool)
    for ex in exclusions:
        out |= ex.contains(d)
    return out


def device_ok(dirs: ArrayLike, constraints: RigConstraints) -> BoolArray:
    """Whether single devices at lab directions (..., 3) respect elevation and exclusions."""
    d = np.asarray(dirs, dtype=float)
    cos_max = math.cos(math.radians(constraints.max_elevation_deg))
    return np.asarray((d[..., 2] >= cos_max - 1e-12) & ~excluded(d, constraints.exclusions))


def ph_options(step_deg: float = 5.0) -> FloatArray:
    """Lab half-vector azimuths tried when placing a pair: ``0, step, ...`` below 360 (radians)."""
    if not 0.0 < step_deg <= 90.0:
        raise FeasibilityError(f"azimuth step {step_deg} deg must be in (0, 90]")
    return np.deg2rad(np.arange(0.0, 360.0 - 1e-9, step_deg))


def on_axis_ph(cells: ArrayLike, ph: ArrayLike) -> BoolArray:
    """(n, P) bool: ``False`` where a cell with ``th = 0`` would be turned away from ``ph = 0``.

    At ``th = 0`` the half vector is the normal and turning the pair by ``ph`` is the same as
    measuring the cell ``pd + ph`` instead: the lab directions cannot tell the two apart (the
    inverse map reports ``ph = 0``). Such cells keep ``ph = 0`` so that a design's cells, its
    lab directions and its condition number agree; turning is done by picking another ``pd``.
    """
    c = np.asarray(cells, dtype=float).reshape(-1, 3)
    p = np.asarray(ph, dtype=float).ravel()
    return (c[:, 0, None] > 1e-12) | (p[None, :] == 0.0)


def allowed_ph(cells: ArrayLike, constraints: RigConstraints, ph: ArrayLike) -> BoolArray:
    """For each cell and lab azimuth, whether both devices avoid every exclusion.

    ``th = 0`` cells only allow ``ph = 0`` (:func:`on_axis_ph`).

    Parameters
    ----------
    cells : (n, 3) array_like, radians
        ``(th, td, pd)``.
    ph : (P,) array_like, radians
        Lab half-vector azimuths to test.

    Returns
    -------
    (n, P) bool
    """
    c = np.asarray(cells, dtype=float).reshape(-1, 3)
    p = np.asarray(ph, dtype=float)
    ok = on_axis_ph(c, p)
    if not constraints.exclusions:
        return ok
    wi, wo = geo.half_diff_to_directions(
        c[:, None, 0], p[None, :], c[:, None, 1], c[:, None, 2]
    )
    return ok & ~excluded(wi, constraints.exclusions) & ~excluded(wo, constraints.exclusions)


def feasible_mask(
    constraints: RigConstraints, valid: ArrayLike | None = None, ph_step_deg: float = 5.0
) -> BoolArray:
    """(18, 18, 36) bool: grid cells a rig with ``constraints`` can measure.

    A cell is feasible when it is valid (both devices above the horizon, and in ``valid`` if
    given, e.g. a basis's mask), both elevations are within the limit, ``2 td`` meets the pair
    separation, and at least one lab azimuth (tried every ``ph_step_deg``) keeps both devices
    out of every exclusion.
    """
    th, td, pd = geo.grid_angles()
    ci, co = geo.cell_cosines(th, td, pd)
    cos_max = math.cos(math.radians(constraints.max_elevation_deg))
    ok = geo.valid_mask() & (ci >= cos_max - 1e-12) & (co >= cos_max - 1e-12)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool).reshape(geo.SLICE_SHAPE)
    ok &= 2.0 * np.rad2deg(td) >= constraints.pair_separation_deg - 1e-9
    if constraints.exclusions and ok.any():
        idx = np.flatnonzero(ok)
        cells = np.stack([th.ravel()[idx], td.ravel()[idx], pd.ravel()[idx]], axis=1)
        reachable = allowed_ph(cells, constraints, ph_options(ph_step_deg)).any(axis=1)
        flat = ok.ravel().copy()
        flat[idx[~reachable]] = False
        ok = flat.reshape(geo.SLICE_SHAPE)
    return ok


def candidate_rows(
    constraints: RigConstraints, valid: ArrayLike | None = None, ph_step_deg: float = 5.0
) -> NDArray[np.intp]:
    """Flat basis rows of the feasible cells; raises when there are none."""
    rows = np.flatnonzero(feasible_mask(constraints, valid, ph_step_deg)).astype(np.intp)
    if rows.size == 0:
        raise FeasibilityError(
            "no grid cell is feasible under these constraints "
            f"(max elevation {constraints.max_elevation_deg:g} deg, pair separation "
            f"{constraints.pair_separation_deg:g} deg, {len(constraints.exclusions)} exclusions); "
            "raise --max-elevation or lower --min-separation / --min-device-distance"
        )
    return rows


def rows_to_cells(rows: ArrayLike) -> FloatArray:
    """(n, 3) ``(th, td, pd)`` radians of flat grid rows."""
    i, j, k = np.unravel_index(np.asarray(rows, dtype=np.intp), geo.SLICE_SHAPE)
    return np.stack([geo.TH_GRID[i], geo.TD_GRID[j], geo.PD_GRID[k]], axis=-1)


def angular_distance(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Angle (radians) between unit vectors ``a`` (..., 3) and ``b`` (..., 3), broadcast."""
    # atan2 of cross and dot stays accurate for nearly parallel vectors, unlike acos.
    a_ = np.asarray(a, dtype=float)
    b_ = np.asarray(b, dtype=float)
    cross = np.linalg.norm(np.cross(a_, b_), axis=-1)
    return np.arctan2(cross, np.sum(a_ * b_, axis=-1))


def min_pairwise_distance(dirs: ArrayLike) -> float:
    """Smallest angle (radians) between any two of ``dirs`` (m, 3); inf for fewer than two."""
    d = np.asarray(dirs, dtype=float).reshape(-1, 3)
    if d.shape[0] < 2:
        return math.inf
    dist = angular_distance(d[:, None, :], d[None, :, :])
    iu = np.triu_indices(d.shape[0], 1)
    return float(dist[iu].min())


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
        raise FeasibilityError("a design needs at least one pair; ask for --pairs 1 or more")
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
                f"required {constraints.pair_separation_deg:g} deg; drop the pair or lower "
                "--min-separation / --min-device-distance"
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
            f"{math.degrees(worst):.1f} deg after {orderings} orders); lower "
            "--min-device-distance or ask for fewer pairs"
        )
    ph_lab = ph[choice]
    all_dirs = np.concatenate([wi[np.arange(n), choice], wo[np.arange(n), choice]])
    return Placement(
        cells=c,
        ph_lab=ph_lab,
        lab_deg=lab_degrees(c, ph_lab),
        min_distance_deg=math.degrees(min_pairwise_distance(all_dirs)),
    )


def _distances_to(wi: FloatArray, wo: FloatArray, k: int, dev: FloatArray) -> FloatArray:
    """(P,) smallest angle from pair ``k``'s two devices, at each azimuth, to devices ``dev``."""
    if dev.shape[0] == 0:
        return np.full(wi.shape[1], math.inf)
    return np.minimum(
        angular_distance(wi[k][:, None, :], dev[None, :, :]).min(axis=1),
        angular_distance(wo[k][:, None, :], dev[None, :, :]).min(axis=1),
    )


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
        d = angular_distance(devices()[:, None, :], devices()[None, :, :])
        np.fill_diagonal(d, math.inf)
        a, b = np.unravel_index(int(np.argmin(d)), d.shape)
        return float(d[a, b]), (int(a) % n, int(b) % n)

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


# ------------------------------------------------------------------ placement during a search
@dataclass
class Mounting:
    """Lab placement of the pairs a search currently holds (mutable search state).

    Attributes
    ----------
    rows : (n,) int array
        Flat grid row (cell) of each pair.
    az : (n,) int array
        Index into :attr:`MountPlanner.ph` of each pair's lab half-vector azimuth.
    devices : (n, 2, 3) array
        Light and sensor direction of each pair at that azimuth (lab, unit vectors).
    """

    rows: NDArray[np.intp]
    az: NDArray[np.intp]
    devices: FloatArray

    def copy(self) -> Mounting:
        return Mounting(self.rows.copy(), self.az.copy(), self.devices.copy())


class MountPlanner:
    """Incremental, collision-free placement of pairs for a search over grid cells.

    A pair's lab azimuth ``ph`` is free (it does not change ``kappa``), so a cell can join a
    design when some azimuth keeps both its devices out of every exclusion and at least
    ``min_device_distance_deg`` from every device already mounted. Rotating ``ph`` rotates both
    devices about the lab normal, so every azimuth of a cell comes from one pair of directions
    and a table of sines and cosines. Among the azimuths that fit, the one whose closest device
    is farthest away is taken (maximin), leaving room for later moves.

    Parameters
    ----------
    constraints : RigConstraints
    ph_step_deg : float
        Azimuth resolution, degrees (the same grid :func:`place_pairs` uses by default).
    nudges : int
        Azimuths tried when a move fits only if one neighbouring pair is re-placed (0: never
        re-place a neighbour).

    Rows are flat indices of the standard ``(th, td, pd)`` grid (:func:`rows_to_cells`).
    """

    def __init__(
        self, constraints: RigConstraints, ph_step_deg: float = 1.0, nudges: int = 4
    ) -> None:
        self.constraints = constraints
        self._nudges = int(nudges)
        self.ph = ph_options(ph_step_deg)
        self._cos_ph = np.cos(self.ph)
        self._sin_ph = np.sin(self.ph)
        # dot(Rz(ph) v, u) = cos ph (v_x u_x + v_y u_y) + sin ph (v_x u_y - v_y u_x) + v_z u_z,
        # so the cosines between a turned device and fixed ones, at every azimuth, are one
        # (P, 3) x (3, D) product with this table; nothing needs turning.
        self._trig = np.stack([self._cos_ph, self._sin_ph, np.ones_like(self.ph)], axis=1)
        # Two devices collide when their angle is below the limit, i.e. their cosine above
        # cos(limit); the slack matches place_pairs' 1e-9 rad tolerance.
        need = math.radians(constraints.min_device_distance_deg)
        self._cos_need = math.cos(max(need - 1e-9, 0.0)) if need > 0.0 else math.inf
        # Per row: its devices at ph = 0 and where both are allowed (a search revisits rows).
        self._cache: dict[int, tuple[FloatArray, BoolArray]] = {}

    @property
    def collisions_possible(self) -> bool:
        """Whether mounted pairs can get in each other's way (a device-distance limit is set).

        Without one, any feasible cell fits at any of its allowed azimuths whatever else is
        mounted, so a search need not track placements.
        """
        return self.constraints.min_device_distance_deg > 0.0

    def _rotated(self, v: FloatArray) -> FloatArray:
        """(P, 3): ``v`` rotated about the lab normal by every azimuth of :attr:`ph`."""
        x = self._cos_ph * v[0] - self._sin_ph * v[1]
        y = self._sin_ph * v[0] + self._cos_ph * v[1]
        return np.stack([x, y, np.full_like(x, v[2])], axis=-1)

    def _row(self, row: int) -> tuple[FloatArray, BoolArray]:
        """(2, 3) devices of ``row`` at ``ph = 0`` and its (P,) allowed azimuths, cached."""
        got = self._cache.get(row)
        if got is None:
            th, td, pd = rows_to_cells(np.array([row]))[0]
            wi0, wo0 = geo.half_diff_to_directions(th, 0.0, td, pd)
            wi, wo = self._rotated(wi0), self._rotated(wo0)
            allowed = device_ok(wi, self.constraints) & device_ok(wo, self.constraints)
            allowed &= on_axis_ph(np.array([[th, td, pd]]), self.ph)[0]
            got = (np.stack([wi0, wo0]), allowed)
            self._cache[row] = got
        return got

    def azimuth_options(self, row: int) -> tuple[FloatArray, FloatArray, BoolArray]:
        """Devices of flat grid ``row`` at every azimuth, and where both are allowed.

        Returns
        -------
        wi, wo : (P, 3) arrays
            Light and sensor directions at each azimuth of :attr:`ph`.
        allowed : (P,) bool
            Both devices within the elevation limit and outside every exclusion (and only
            ``ph = 0`` for a ``th = 0`` cell, see :func:`on_axis_ph`).
        """
        dev0, allowed = self._row(row)
        return self._rotated(dev0[0]), self._rotated(dev0[1]), allowed

    def _cosines(self, dev0: FloatArray, others: FloatArray) -> FloatArray:
        """(P, 2, D): cosine between each device of a pair turned to every azimuth and others.

        ``dev0`` (2, 3) are the pair's devices at ``ph = 0``; ``others`` (D, 3).
        """
        v, u = dev0[:, None, :], others[None, :, :]
        m = np.stack([
            v[..., 0] * u[..., 0] + v[..., 1] * u[..., 1],
            v[..., 0] * u[..., 1] - v[..., 1] * u[..., 0],
            v[..., 2] * u[..., 2],
        ])  # (3, 2, D)
        return (self._trig @ m.reshape(3, -1)).reshape(self.ph.size, 2, -1)

    def _turned(self, dev0: FloatArray, j: int) -> FloatArray:
        """(2, 3): the pair's devices at azimuth index ``j``."""
        c, s = self._cos_ph[j], self._sin_ph[j]
        x, y = dev0[:, 0], dev0[:, 1]
        return np.stack([c * x - s * y, s * x + c * y, dev0[:, 2]], axis=1)

    def best_azimuth(self, row: int, others: ArrayLike) -> tuple[int, FloatArray]:
        """Maximin azimuth for ``row`` among the devices ``others`` (D, 3).

        Returns
        -------
        index : int
            Index into :attr:`ph`, or -1 when no allowed azimuth keeps both devices far enough
            from every device in ``others``.
        devices : (2, 3) array
            Light and sensor direction at that azimuth (meaningless when ``index`` is -1).
        """
        dev0, allowed = self._row(row)
        dev = np.asarray(others, dtype=float).reshape(-1, 3)
        if dev.shape[0]:
            # Largest cosine = closest device.
            closest = self._cosines(dev0, dev).reshape(self.ph.size, -1).max(axis=1)
        else:
            closest = np.full(self.ph.size, -1.0)
        fits = allowed & (closest <= self._cos_need)
        if not fits.any():
            return -1, np.zeros((2, 3))
        j = int(np.argmin(np.where(fits, closest, np.inf)))
        return j, self._turned(dev0, j)

    def start(
        self, rng: np.random.Generator, candidates: ArrayLike, n: int
    ) -> tuple[NDArray[np.intp], Mounting] | None:
        """A random collision-free design: ``n`` candidate rows added in random order.

        Rows that do not fit beside those already mounted are skipped; None when the
        candidates run out before ``n`` fit.

        Returns
        -------
        rows : (n,) int array
        mounting : Mounting
        """
        rows: list[int] = []
        az: list[int] = []
        devices: list[FloatArray] = []
        for r in rng.permutation(np.asarray(candidates, dtype=np.intp)):
            placed = np.concatenate(devices) if devices else np.zeros((0, 3))
            j, dev = self.best_azimuth(int(r), placed)
            if j < 0:
                continue
            rows.append(int(r))
            az.append(j)
            devices.append(dev)
            if len(rows) == n:
                picked = np.array(rows, dtype=np.intp)
                return picked, Mounting(picked.copy(), np.array(az, dtype=np.intp),
                                        np.stack(devices))
        return None

    def move(self, mounting: Mounting, slot: int, row: int) -> bool:
        """Mount ``row`` in place of pair ``slot``; False if it cannot be made to fit.

        First with every other pair held. Failing that, a neighbour may step aside: at the
        azimuths where the new devices are too close to exactly one other pair, that pair is
        re-placed (maximin) around the rest, trying the most open such azimuths first. Only
        one pair other than ``slot`` ever moves, and its cell stays the same, so ``kappa``
        does not change. ``mounting`` is updated only on success.
        """
        keep = np.arange(mounting.az.size) != slot
        others = mounting.devices[keep]  # (n - 1, 2, 3)
        dev0, allowed = self._row(row)
        # Closest approach (largest cosine) of the new pair to each other pair, per azimuth;
        # elementwise maxima over strided views are much cheaper than a multi-axis reduce.
        cos = self._cosines(dev0, others.reshape(-1, 3))  # (P, 2, 2 (n - 1))
        either = np.maximum(cos[:, 0], cos[:, 1])
        per_pair = np.maximum(either[:, 0::2], either[:, 1::2])  # (P, n - 1)
        closest = per_pair.max(axis=1) if per_pair.shape[1] else np.full(self.ph.size, -1.0)
        fits = allowed & (closest <= self._cos_need)
        if fits.any():
            j = int(np.argmin(np.where(fits, closest, np.inf)))
            self._set(mounting, slot, row, j, self._turned(dev0, j))
            return True
        if others.shape[0] < 2 or self._nudges == 0:
            return False
        blocking = per_pair > self._cos_need
        one = allowed & (blocking.sum(axis=1) == 1)
        if not one.any():
            return False
        rest_closest = np.where(blocking, -np.inf, per_pair).max(axis=1)
        tries = np.flatnonzero(one)
        tries = tries[np.argsort(rest_closest[tries], kind="stable")][: self._nudges]
        pair_ids = np.flatnonzero(keep)
        for jj in tries:
            p = int(np.argmax(blocking[jj]))  # the one pair in the way, among the others
            new_dev = self._turned(dev0, int(jj))
            rest = np.delete(others, p, axis=0).reshape(-1, 3)
            target = int(pair_ids[p])
            jp, dev_p = self.best_azimuth(int(mounting.rows[target]),
                                          np.concatenate([rest, new_dev]))
            if jp >= 0:
                self._set(mounting, slot, row, int(jj), new_dev)
                self._set(mounting, target, int(mounting.rows[target]), jp, dev_p)
                return True
        return False

    @staticmethod
    def _set(mounting: Mounting, slot: int, row: int, az: int, dev: FloatArray) -> None:
        mounting.rows[slot] = row
        mounting.az[slot] = az
        mounting.devices[slot] = dev
