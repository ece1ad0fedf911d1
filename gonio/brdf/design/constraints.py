"""What a rig can physically measure: its mounting constraints and the grid cells they leave.

A light/sensor pair measures one half/difference cell ``(th, td, pd)`` for every stage angle
(math.md 2). Which cells a rig can offer is limited by its mounts (math.md 8):

* both devices at most ``max_elevation_deg`` from the normal (grazing readings are noisy and
  low mounts shadow the specimen);
* the light and the sensor of a pair at least ``min_separation_deg`` apart (``2 td``): they
  cannot share a mount;
* no device inside an excluded region of the lab: a cone around a lab direction (a camera,
  the stage arm) or an elevation/azimuth box;
* any two mounted devices at least ``min_device_distance_deg`` apart.

The first two do not depend on where the pair sits in azimuth; exclusions and device distances
do. A pair's lab half-vector azimuth ``ph`` is free (the stage sweeps it anyway and it does not
change the condition number), so placement (:mod:`gonio.brdf.design.placement`,
:mod:`gonio.brdf.design.mounting`) chooses it to keep devices apart.

Angles are degrees in the public data classes (they come from users) and radians in the
array functions, as everywhere in ``gonio.brdf``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.errors import FeasibilityError
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


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
            f"{constraints.pair_separation_deg:g} deg, {len(constraints.exclusions)} exclusions)",
            "raise {max_elevation_deg} or lower {min_separation_deg} / {min_device_distance_deg}",
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
