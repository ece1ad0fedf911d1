"""Directions, the Rusinkiewicz half/difference parameterization and the 5 degree grid.

Conventions (docs/math.md sections 1-3, 10):

* Specimen frame: z is the surface normal, x the reference mark on the holder.
* Directions are unit vectors pointing away from the surface: ``wi`` toward the light,
  ``wo`` toward the sensor.
* Angles are radians everywhere in this module.
* Stage angle ``alpha`` turns the specimen by ``+alpha`` about z, so a lab direction with
  azimuth ``phi_lab`` has specimen azimuth ``phi_lab - alpha``.
* Grid: ``th, td`` in {0, 5, ..., 85} deg (18 each), ``pd`` in {0, ..., 175} deg (36),
  ``ph`` in {0, ..., 355} deg (72). Tables are ``f[c, i_ph, i_th, i_td, i_pd]``; one ``ph``
  slice flattened in C order over ``(th, td, pd)`` is one basis column of ``N_ROWS`` rows.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

STEP_DEG = 5.0
N_PH, N_TH, N_TD, N_PD = 72, 18, 18, 36
SLICE_SHAPE: tuple[int, int, int] = (N_TH, N_TD, N_PD)
TABLE_SHAPE: tuple[int, int, int, int] = (N_PH, N_TH, N_TD, N_PD)
N_ROWS = N_TH * N_TD * N_PD  # 11,664 rows of one slice column

STEP = np.deg2rad(STEP_DEG)
TH_GRID: FloatArray = np.deg2rad(np.arange(N_TH) * STEP_DEG)
TD_GRID: FloatArray = np.deg2rad(np.arange(N_TD) * STEP_DEG)
PD_GRID: FloatArray = np.deg2rad(np.arange(N_PD) * STEP_DEG)
PH_GRID: FloatArray = np.deg2rad(np.arange(N_PH) * STEP_DEG)

# A cell is valid when both elevations are strictly above the horizon; cells that land exactly
# on the horizon (cos = 0 up to rounding) carry no usable signal and are treated as invalid.
_HORIZON_TOL = 1e-9


def spherical_to_direction(theta: ArrayLike, phi: ArrayLike) -> FloatArray:
    """Unit vectors from elevation-from-normal and azimuth.

    Parameters
    ----------
    theta, phi : array_like, radians, broadcastable
        Polar angle from the normal and azimuth from x.

    Returns
    -------
    (..., 3) array
        Unit vectors.
    """
    t = np.asarray(theta, dtype=float)
    p = np.asarray(phi, dtype=float)
    st = np.sin(t)
    return np.stack(np.broadcast_arrays(st * np.cos(p), st * np.sin(p), np.cos(t)), axis=-1)


def direction_to_spherical(w: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Polar angle and azimuth (in ``[0, 2 pi)``) of unit vectors ``w`` of shape (..., 3)."""
    v = np.asarray(w, dtype=float)
    # atan2 keeps full precision near the poles, where arccos(z) loses half the digits.
    theta = np.arctan2(np.hypot(v[..., 0], v[..., 1]), v[..., 2])
    phi = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2 * np.pi)
    return theta, phi


def rotate_z(w: ArrayLike, angle: ArrayLike) -> FloatArray:
    """Rotate vectors ``w`` (..., 3) by ``angle`` (radians, broadcastable) about z."""
    v = np.asarray(w, dtype=float)
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    x = c * v[..., 0] - s * v[..., 1]
    y = s * v[..., 0] + c * v[..., 1]
    return np.stack(np.broadcast_arrays(x, y, v[..., 2]), axis=-1)


def lab_to_specimen(w_lab: ArrayLike, stage_angle: ArrayLike) -> FloatArray:
    """Express lab-frame directions in the specimen frame at stage angle ``alpha``.

    The stage turns the specimen by ``+alpha``, so the lab direction turns by ``-alpha``
    relative to the specimen.
    """
    return rotate_z(w_lab, -np.asarray(stage_angle, dtype=float))


def half_diff_to_directions(
    th: ArrayLike, ph: ArrayLike, td: ArrayLike, pd: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Light and view directions from half/difference angles (math.md 2, forward map).

    ``d = (sin td cos pd, sin td sin pd, cos td)``, ``i = Rz(ph) Ry(th) d`` and
    ``o = Rz(ph) Ry(th) (-d_x, -d_y, d_z)``.

    Parameters
    ----------
    th, ph, td, pd : array_like, radians, broadcastable

    Returns
    -------
    wi, wo : (..., 3) arrays, unit vectors
    """
    th_, ph_, td_, pd_ = (np.asarray(a, dtype=float) for a in (th, ph, td, pd))
    th_, ph_, td_, pd_ = np.broadcast_arrays(th_, ph_, td_, pd_)
    dx = np.sin(td_) * np.cos(pd_)
    dy = np.sin(td_) * np.sin(pd_)
    dz = np.cos(td_)
    ct, st = np.cos(th_), np.sin(th_)

    def _ry_then_rz(x: FloatArray, y: FloatArray, z: FloatArray) -> FloatArray:
        xr = ct * x + st * z
        zr = -st * x + ct * z
        return rotate_z(np.stack([xr, y, zr], axis=-1), ph_)

    return _ry_then_rz(dx, dy, dz), _ry_then_rz(-dx, -dy, dz)


def directions_to_half_diff(
    wi: ArrayLike, wo: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Half/difference angles of direction pairs (math.md 2, inverse map).

    Parameters
    ----------
    wi, wo : (..., 3) array_like, unit vectors pointing away from the surface

    Returns
    -------
    th : array, radians in ``[0, pi]``
    ph : array, radians in ``[0, 2 pi)``; 0 where ``th = 0`` (undefined there)
    td : array, radians in ``[0, pi/2]``
    pd : array, radians in ``[0, pi)`` (reciprocity folds ``pd + pi`` onto ``pd``)
    """
    i = np.asarray(wi, dtype=float)
    o = np.asarray(wo, dtype=float)
    h = i + o
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    # Exactly opposite directions have no half vector; use the normal so the result is defined.
    h = np.where(norm > 1e-12, h / np.where(norm > 1e-12, norm, 1.0), np.array([0.0, 0.0, 1.0]))
    th = np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])  # exact near th = 0, unlike acos
    on_axis = np.hypot(h[..., 0], h[..., 1]) < 1e-12
    ph = np.where(on_axis, 0.0, np.mod(np.arctan2(h[..., 1], h[..., 0]), 2 * np.pi))
    d = rotate_z(i, -ph)
    ct, st = np.cos(th), np.sin(th)
    dx = ct * d[..., 0] - st * d[..., 2]
    dz = st * d[..., 0] + ct * d[..., 2]
    td = np.arctan2(np.hypot(dx, d[..., 1]), dz)
    pd = np.mod(np.arctan2(d[..., 1], dx), np.pi)
    # Round-off can put pd a hair below pi; fold it onto 0 so it stays in [0, pi).
    pd = np.where(pd >= np.pi - 1e-12, 0.0, pd)
    return th, ph, td, pd


def cell_cosines(th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """``cos theta_i`` and ``cos theta_o`` of half/difference cells (independent of ``ph``)."""
    th_, td_, pd_ = (np.asarray(a, dtype=float) for a in (th, td, pd))
    a = np.cos(th_) * np.cos(td_)
    b = np.sin(th_) * np.sin(td_) * np.cos(pd_)
    return a - b, a + b


def grid_angles() -> tuple[FloatArray, FloatArray, FloatArray]:
    """The slice grid as three (18, 18, 36) arrays ``th, td, pd`` in radians (``ij`` indexing)."""
    th, td, pd = np.meshgrid(TH_GRID, TD_GRID, PD_GRID, indexing="ij")
    return th, td, pd


def valid_mask() -> NDArray[np.bool_]:
    """(18, 18, 36) bool: cells whose light and view are both strictly above the horizon."""
    ci, co = cell_cosines(*grid_angles())
    return (ci > _HORIZON_TOL) & (co > _HORIZON_TOL)


def remap_weight(eps: float = 1e-3) -> FloatArray:
    """(18, 18, 36) ``w = max(cos ti cos to, eps)`` of the basis remap (math.md 4)."""
    ci, co = cell_cosines(*grid_angles())
    return np.maximum(ci * co, eps)


def volume_weight() -> FloatArray:
    """(18, 18, 36) volume weight of each grid cell (math.md 10, ``000_`` Eq. 10).

    ``wV = 4 cos td sin td sin th`` integrated over each cell's extent (cell centres on the
    grid, half-width 2.5 deg, clipped to ``[0, 90]`` deg), so the ``th = 0`` row keeps a
    positive weight. The constant ``dph dpd`` factor is included.
    """
    half = STEP / 2

    def _edges(grid: FloatArray) -> tuple[FloatArray, FloatArray]:
        return np.clip(grid - half, 0.0, np.pi / 2), np.clip(grid + half, 0.0, np.pi / 2)

    lo, hi = _edges(TH_GRID)
    w_th = np.cos(lo) - np.cos(hi)  # integral of sin th
    lo, hi = _edges(TD_GRID)
    w_td = 2.0 * (np.sin(hi) ** 2 - np.sin(lo) ** 2)  # integral of 4 cos td sin td
    w = w_th[:, None, None] * w_td[None, :, None] * np.full(N_PD, STEP)[None, None, :]
    return w * STEP


def stage_shifted_ph(ph_lab: ArrayLike, stage_angle: ArrayLike) -> FloatArray:
    """Specimen ``ph`` of a fixed lab pair at stage angle ``alpha``: ``ph_lab - alpha`` mod 2 pi."""
    return np.mod(np.asarray(ph_lab, dtype=float) - np.asarray(stage_angle, dtype=float), 2 * np.pi)


def flat_row(i_th: ArrayLike, i_td: ArrayLike, i_pd: ArrayLike) -> NDArray[np.intp]:
    """Flat basis row index of grid cells (C order over ``(th, td, pd)``)."""
    return np.ravel_multi_index(
        (np.asarray(i_th), np.asarray(i_td), np.asarray(i_pd)), SLICE_SHAPE
    ).astype(np.intp)


def lattice_corners(
    axes: Sequence[tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]],
) -> Iterator[tuple[list[NDArray[np.intp]], FloatArray]]:
    """The ``2**d`` corners of the grid cell around each of N points, for multilinear blends.

    Parameters
    ----------
    axes : sequence of d ``(lo, hi, frac)`` triples of (N,) arrays
        Lower and upper grid index along each axis and the fraction of the way from lo to hi.

    Yields
    ------
    index : list of d (N,) int arrays
        The corner's grid index along each axis.
    weight : (N,) array
        Its multilinear weight; the weights of all corners sum to 1.
    """
    n = axes[0][2].shape[0]
    for corner in range(1 << len(axes)):
        index = []
        weight = np.ones(n)
        for axis, (lo, hi, frac) in enumerate(axes):
            if (corner >> axis) & 1:
                index.append(hi)
                weight = weight * frac
            else:
                index.append(lo)
                weight = weight * (1.0 - frac)
        yield index, weight
