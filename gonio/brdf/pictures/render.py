"""Pictures of a BRDF: a sphere and a flat swatch under point lights and a studio environment.

A lab judges a measured material by looking at it, as in V&F 2016's Fig. 1 (environment light)
and Fig. 9 (point light, reference beside reconstruction). Everything here is NumPy over arrays;
nothing depends on a renderer package.

Scene conventions (image space = world space):

* The camera looks down ``-z``; ``x`` points right in the image and ``y`` up.
* **Sphere**: unit sphere, orthographic view, so every pixel sees it along ``wo = (0, 0, 1)``.
  The material's reference direction (specimen ``x``, the holder mark) at a point with normal
  ``n`` is world ``x`` projected onto the tangent plane; at the centre of the sphere the
  specimen frame is the image frame, as on the swatch. A brushed material's grooves therefore
  run left-right over the front of the sphere.
* **Swatch**: the square ``[-1, 1]^2`` of the plane ``z = 0`` seen from a pinhole camera at
  height :data:`SWATCH_DISTANCE` on the normal, lit by a point light at the same distance from
  the centre (by default at the camera: a "flash" picture, where every point sees the light
  in its mirror direction, so the highlight's outline is the specular lobe itself).
* **Lights** are given by their polar angle from the camera axis (``theta_deg``) and their
  azimuth in the image (``phi_deg``: 0 = right, 90 = up). A point light gives irradiance 1 on a
  surface facing it (falling off with ``1/r^2`` on the swatch, normalised at its centre).
* **Environment** (:func:`studio_environment`): a soft sky dome brighter towards image ``+y``,
  a dark floor, and two long thin softboxes, one horizontal and one vertical, whose
  reflections stretch and turn with an anisotropic material's grain.

Outgoing radiance is ``L = sum_k f(wi_k, wo) E_k cos(theta_i,k)`` in the BRDF's units (1/sr
for a calibrated result) per unit irradiance. :func:`to_srgb` maps it to display values with
an exposure that puts the brightest pixel at 1.0, so no highlight is clipped.

Tables are looked up with :class:`TableLookup`, arranged for millions of lookups and cheap for
a few (a page's curves): by default the monotone cubic in log of
:mod:`gonio.brdf.tables.interpolation` (a highlight between two nodes keeps its height and
shape), or the multilinear interpolation of
:meth:`gonio.brdf.tables.table.BRDFTable.eval_half_diff` (invalid cells left out, weights
renormalised).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import interpolation as interp
from gonio.brdf.tables.table import BRDFTable


class RenderError(ValueError):
    """A picture that cannot be drawn as asked (view kind, size, no material)."""


FloatArray = NDArray[np.float64]
Evaluator = Callable[[FloatArray, FloatArray], FloatArray]
"""``f(wi, wo)``: (N, 3) specimen-frame unit vectors -> (N, C) BRDF values, 0 below the horizon."""

SWATCH_DISTANCE = 3.0
"""Camera and light distance from the swatch centre, in swatch half-widths."""
DEFAULT_SIZE = 512
"""Pixels per view side."""
ENV_SAMPLES = 96
"""Sky directions of :func:`studio_environment` (Fibonacci sphere), besides the softboxes."""


# --------------------------------------------------------------------------- BRDF lookup
_LOOKUP_BLOCK = 1 << 17
"""Direction pairs :class:`TableLookup` interpolates at once (bounds its temporaries)."""
GATHER_SHARE = 0.5
"""Share of a table's cells up to which :class:`TableLookup` ("auto") computes the cubic's
nodes only where its points read: past it, once for the whole table is less work."""
NodeChoice = Literal["auto", "table", "gathered"]
NODE_CHOICES: tuple[NodeChoice, ...] = ("auto", "table", "gathered")


class TableLookup:
    """Fast lookup in a :class:`BRDFTable` for direction pairs, few or many.

    Periodic in ``ph`` and ``pd``, clamped in ``th`` and ``td``, invalid neighbours left out
    with the weights renormalised, 0 below the horizon. ``interpolation="multilinear"`` gives
    the same result as :meth:`BRDFTable.eval` (tested against it); the default,
    ``"log-pchip"``, interpolates ``ln(f + eps)`` with a monotone cubic along ``th``
    (:mod:`gonio.brdf.tables.interpolation`). Faster than :meth:`BRDFTable.eval` because the
    table is stored once as (cells, C) with the NaNs zeroed beside a validity column, so each
    corner is one flat gather.

    The cubic needs ``ln(f + eps)`` and its slope at the nodes it reads. For millions of
    points (a picture, an export) they are computed once for the whole table; for a few
    hundred (a page's curve) only at the cells those points read and their ``th``
    neighbours (:func:`gonio.brdf.tables.interpolation.gathered_nodes`): a 31-band table's
    whole set is 0.4 GB of float64 and seconds of CPU. Both give the same numbers, bit for bit.

    Parameters
    ----------
    table : BRDFTable
    interpolation : "log-pchip" or "multilinear"
    nodes : "auto", "table" or "gathered"
        Where the cubic's logs and slopes are computed: "table", every cell once, on the
        first lookup; "gathered", per lookup at the cells it reads; "auto" gathers for a
        lookup whose points read a small part of the table (:data:`GATHER_SHARE`) and
        switches to the whole table once the gathered cells add up to that share.

    Attributes
    ----------
    nodes_computed : int
        Cells whose ``ln(f + eps)`` this lookup has computed so far (a measure of its work).
    """

    def __init__(self, table: BRDFTable,
                 interpolation: interp.Interpolation = interp.DEFAULT_INTERPOLATION,
                 nodes: NodeChoice = "auto") -> None:
        if interpolation not in interp.INTERPOLATIONS:
            raise RenderError(f"unknown interpolation {interpolation!r}; use one of "
                              f"{', '.join(interp.INTERPOLATIONS)}")
        if nodes not in NODE_CHOICES:
            raise RenderError(f"unknown nodes {nodes!r}; use one of {', '.join(NODE_CHOICES)}")
        v = np.asarray(table.values)  # (C, 72, 18, 18, 36), float32 or float64 as stored
        flat = np.moveaxis(v, 0, -1).reshape(-1, v.shape[0])  # (cells, C)
        ok: NDArray[np.bool_] = np.asarray(np.isfinite(flat).all(axis=1))
        self._values: NDArray[np.floating[Any]] = np.where(ok[:, None], flat, 0.0).astype(
            v.dtype, copy=False)
        self._ok = ok
        self._valid: NDArray[np.float32] = ok.astype(np.float32)
        self.n_channels = int(v.shape[0])
        self.interpolation = interpolation
        self.node_choice: NodeChoice = nodes
        self.nodes_computed = 0
        # eps from the whole table whichever way the nodes are computed: it sets every log.
        self._eps = interp.log_offset(self._values, ok)
        self._nodes: FloatArray | None = None  # the whole table's, once computed

    def eval(self, wi: FloatArray, wo: FloatArray) -> FloatArray:
        """BRDF at (N, 3) direction pairs (specimen frame); (N, C), 1/sr."""
        i = np.asarray(wi, dtype=float).reshape(-1, 3)
        o = np.asarray(wo, dtype=float).reshape(-1, 3)
        out = np.zeros((i.shape[0], self.n_channels))
        up = (i[:, 2] > 0) & (o[:, 2] > 0)
        if not up.any():
            return out
        th, ph, td, pd = geo.directions_to_half_diff(i[up], o[up])
        out[up] = self.eval_half_diff(th, ph, td, pd)
        return out

    def eval_half_diff(self, th: FloatArray, ph: FloatArray, td: FloatArray, pd: FloatArray,
                       empty: float = 0.0) -> FloatArray:
        """BRDF at (N,) half/difference angles (radians); (N, C), 1/sr.

        ``empty`` is returned where no neighbouring cell is valid (grazing: by default 0,
        nothing reflected; an export passes NaN to mark the cell unknown).
        """
        th, ph, td, pd = (np.asarray(a, dtype=float).ravel() for a in (th, ph, td, pd))
        out = np.empty((th.size, self.n_channels))
        # In blocks: the cubic holds about twenty (N, C) temporaries, which for an export's
        # 1.5 million points would be gigabytes at once.
        for k in range(0, th.size, _LOOKUP_BLOCK):
            part = slice(k, k + _LOOKUP_BLOCK)
            q = th[part], ph[part], td[part], pd[part]
            if self.interpolation == "multilinear":
                res, weight = self._multilinear(*q)
            else:
                nodes, valid, cells = self._nodes_for(*q)
                logs, weight = interp.log_pchip_lookup(nodes, valid, *q, cells=cells)
                res = np.maximum(np.exp(logs) - self._eps, 0.0)
            res[weight <= 1e-12] = empty
            out[part] = res
        return out

    def _nodes_for(self, th: FloatArray, ph: FloatArray, td: FloatArray, pd: FloatArray
                   ) -> tuple[FloatArray, NDArray[np.floating[Any]], NDArray[np.intp] | None]:
        """Packed nodes, validity and their cells (None: every cell) for these points."""
        n_cells = self._ok.size
        if self._nodes is None and (self.node_choice == "gathered" or (
                self.node_choice == "auto"
                # A point reads at most 32 cells' logs (8 corners x 4 along th).
                and self.nodes_computed + 32 * th.size <= GATHER_SHARE * n_cells)):
            cells = interp.gathered_cells(th, ph, td, pd)
            nodes, computed = interp.gathered_nodes(self._values, self._ok, self._eps, cells)
            self.nodes_computed += computed
            return nodes, self._valid[cells], cells
        if self._nodes is None:
            logs = interp.node_logs(self._values, self._eps)
            self._nodes = interp.pack_nodes(logs, interp.node_slopes(logs, self._ok))
            self.nodes_computed += n_cells
        return self._nodes, self._valid, None

    def _multilinear(self, th: FloatArray, ph: FloatArray, td: FloatArray, pd: FloatArray
                     ) -> tuple[FloatArray, FloatArray]:
        strides = (geo.N_TH * geo.N_TD * geo.N_PD, geo.N_TD * geo.N_PD, geo.N_PD, 1)
        axes: list[tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]] = []
        for a, n, period, stride in (
            (ph, geo.N_PH, 2 * np.pi, strides[0]),
            (th, geo.N_TH, 0.0, strides[1]),
            (td, geo.N_TD, 0.0, strides[2]),
            (pd, geo.N_PD, np.pi, strides[3]),
        ):
            if period:
                u = np.mod(a, period) / geo.STEP
                i0 = np.floor(u).astype(np.intp)
                t = u - i0
                lo, hi = i0 % n, (i0 + 1) % n
            else:
                u = np.clip(a / geo.STEP, 0.0, n - 1)
                lo = np.minimum(np.floor(u).astype(np.intp), n - 2)
                t = u - lo
                hi = lo + 1
            axes.append((lo * stride, hi * stride, t))
        acc = np.zeros((th.size, self.n_channels), dtype=np.float64)
        wsum = np.zeros(th.size)
        for idx, w in geo.lattice_corners(axes):
            flat = idx[0] + idx[1] + idx[2] + idx[3]
            wv = w * self._valid[flat]
            acc += wv[:, None] * self._values[flat]
            wsum += wv
        with np.errstate(invalid="ignore", divide="ignore"):
            return acc / wsum[:, None], wsum


class _Prepared:
    """A BRDF made ready for rendering (tables get their :class:`TableLookup` once)."""

    def __init__(self, brdf: Any) -> None:
        self._fn: Evaluator = (TableLookup(brdf).eval if isinstance(brdf, BRDFTable)
                               else lambda wi, wo: np.nan_to_num(
                                   np.asarray(brdf.eval(wi, wo), dtype=float)))

    def __call__(self, wi: FloatArray, wo: FloatArray) -> FloatArray:
        return self._fn(wi, wo)


def evaluator(brdf: Any) -> Evaluator:
    """An :data:`Evaluator` for a table (fast lookup) or anything with ``eval(wi, wo)``.

    Passing the result again returns it unchanged, so renderers accept either.
    """
    return brdf if isinstance(brdf, _Prepared) else _Prepared(brdf)


def n_channels_of(brdf: Any) -> int:
    """Channels a BRDF returns (from its ``channels`` attribute, else by evaluating once)."""
    ch = getattr(brdf, "channels", None)
    if ch:
        return len(ch)
    z = np.array([[0.0, 0.0, 1.0]])
    return int(np.asarray(brdf.eval(z, z)).shape[-1])


# --------------------------------------------------------------------------- scene pieces
@dataclass(frozen=True)
class PointLight:
    """A point light's direction from the object: polar angle from the camera axis, azimuth
    in the image (0 = right, 90 = up), degrees."""

    theta_deg: float
    phi_deg: float

    def direction(self) -> FloatArray:
        return geo.spherical_to_direction(math.radians(self.theta_deg),
                                          math.radians(self.phi_deg))

    def label(self) -> str:
        return f"light {self.theta_deg:g}° from view, azimuth {self.phi_deg:g}°"


DEFAULT_SPHERE_LIGHTS: tuple[PointLight, ...] = (
    PointLight(20.0, 135.0), PointLight(55.0, 135.0), PointLight(55.0, 45.0),
)
"""Point lights of the default sphere views: near the view, then higher elevations from three
azimuths, so an anisotropic highlight is seen stretching and turning."""


def _frame(n: FloatArray, rotation_deg: float) -> tuple[FloatArray, FloatArray]:
    """Tangent ``t`` (material x) and bitangent ``b`` for normals (N, 3).

    ``t`` is world x projected on the tangent plane, then turned by ``rotation_deg`` about
    ``n`` (a specimen rotated by +angle on the stage).
    """
    x = np.array([1.0, 0.0, 0.0])
    t = x - (n @ x)[:, None] * n
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    # At the two points where n is +-x the projection vanishes: any tangent will do there.
    t = np.where(norm > 1e-9, t / np.maximum(norm, 1e-12), np.array([0.0, 1.0, 0.0]))
    b = np.cross(n, t)
    if rotation_deg:
        c, s = math.cos(math.radians(rotation_deg)), math.sin(math.radians(rotation_deg))
        t, b = c * t + s * b, -s * t + c * b
    return t, b


def _to_local(w: FloatArray, t: FloatArray, b: FloatArray, n: FloatArray) -> FloatArray:
    """World directions (N, 3) or (3,) into each point's (t, b, n) frame, (N, 3)."""
    w = np.broadcast_to(w, n.shape)
    return np.stack([np.sum(w * t, axis=1), np.sum(w * b, axis=1), np.sum(w * n, axis=1)],
                    axis=1)


def sphere_normals(size: int) -> tuple[NDArray[np.bool_], FloatArray]:
    """Pixels covered by the unit sphere and their normals.

    Parameters
    ----------
    size : int
        Image side, pixels; the sphere fills it with a one-pixel margin.

    Returns
    -------
    mask : (size, size) bool
    normals : (M, 3) float, unit normals of the covered pixels in row-major order (row 0 at
        the top of the image, so ``y`` decreases with the row).
    """
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    c = c * (1.0 + 2.0 / size)  # one pixel of margin around the disc
    x, y = np.meshgrid(c, -c)
    r2 = x * x + y * y
    mask = r2 < 1.0
    z = np.sqrt(np.maximum(1.0 - r2[mask], 0.0))
    return mask, np.stack([x[mask], y[mask], z], axis=1)


def swatch_points(size: int) -> FloatArray:
    """(size*size, 3) points of the swatch ``[-1, 1]^2`` (z = 0), row-major, row 0 at the top."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    return np.stack([x.ravel(), y.ravel(), np.zeros(size * size)], axis=1)


@dataclass(frozen=True)
class Environment:
    """Distant light as samples: directions (K, 3), radiance x solid angle (K, 3) RGB."""

    directions: FloatArray
    weights: FloatArray


_SKY = np.array([0.30, 0.36, 0.45])
_HORIZON = np.array([0.22, 0.21, 0.20])
_FLOOR = np.array([0.03, 0.028, 0.025])
# Softboxes: (centre direction, long axis, half-length rad, half-width rad, radiance).
_BOXES = (
    (np.array([-0.30, 0.60, 0.74]), np.array([1.0, 0.0, 0.0]), 0.60, 0.07, 30.0),
    (np.array([0.65, -0.05, 0.76]), np.array([0.0, 1.0, 0.0]), 0.55, 0.07, 20.0),
)


def _studio_radiance(w: FloatArray, boxes: bool = True) -> FloatArray:
    w = np.asarray(w, dtype=float)
    up = w[:, 1]
    sky = np.where((up > 0)[:, None], _HORIZON + (_SKY - _HORIZON) * np.sqrt(
        np.clip(up, 0, 1))[:, None], _FLOOR + (_HORIZON - _FLOOR) * np.exp(
        8.0 * np.minimum(up, 0))[:, None])
    if not boxes:
        return sky
    out = sky.copy()
    for centre, axis, half_len, half_w, level in _BOXES:
        c = centre / np.linalg.norm(centre)
        a = axis - (axis @ c) * c
        a /= np.linalg.norm(a)
        b = np.cross(c, a)
        cosang = w @ c
        along = np.arctan2(w @ a, cosang)
        across = np.arctan2(w @ b, cosang)
        inside = (cosang > 0) & (np.abs(along) < half_len) & (np.abs(across) < half_w)
        out[inside] = level
    return out


def studio_environment(n_sky: int = ENV_SAMPLES, box_steps: int = 16) -> Environment:
    """The procedural studio (module docstring) as point samples.

    The sky and floor are sampled on a Fibonacci sphere of ``n_sky`` directions (solid angle
    ``4 pi / n_sky`` each); each softbox by ``box_steps`` x 2 points over its area, so its
    long reflections stay continuous.
    """
    k = np.arange(n_sky) + 0.5
    if n_sky == 0:
        k = np.zeros(0)
    z = 1.0 - 2.0 * k / n_sky
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    sky_dirs = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1).reshape(-1, 3)  # y up
    sky_w = _studio_radiance(sky_dirs, boxes=False) * (4.0 * math.pi / max(n_sky, 1))
    dirs = [sky_dirs]
    weights = [sky_w]
    for centre, axis, half_len, half_w, level in _BOXES:
        c = centre / np.linalg.norm(centre)
        a = axis - (axis @ c) * c
        a /= np.linalg.norm(a)
        b = np.cross(c, a)
        s = (np.arange(box_steps) + 0.5) / box_steps * 2.0 - 1.0
        for across in (-0.5, 0.5):
            u = np.tan(s * half_len)[:, None] * a + math.tan(across * half_w) * b + c
            dirs.append(u / np.linalg.norm(u, axis=1, keepdims=True))
            area = (2 * half_len) * (2 * half_w)  # small-angle solid angle of the box
            box_rgb = level - _studio_radiance(dirs[-1], boxes=False)  # box replaces the sky
            weights.append(box_rgb * area / (2 * box_steps))
    return Environment(np.concatenate(dirs), np.concatenate(weights))


# --------------------------------------------------------------------------- rendering
def _rgb(values: FloatArray) -> FloatArray:
    """(N, C) channels to (N, 3) RGB: the first three channels, or grey for fewer."""
    if values.shape[1] >= 3:
        return values[:, :3]
    return np.repeat(values[:, :1], 3, axis=1)


def render_sphere(brdf: Any, light: PointLight | Environment, size: int = DEFAULT_SIZE,
                  rotation_deg: float = 0.0, *, batch: int = 1 << 17) -> FloatArray:
    """Linear radiance image (size, size, 3) of the sphere; background NaN.

    Parameters
    ----------
    brdf : BRDFTable, a model, or an :data:`Evaluator`
    light : PointLight (irradiance 1 facing it) or Environment
    size : int, pixels
    rotation_deg : float
        Turns the material about every normal (a specimen rotated on the stage).
    batch : int
        Direction pairs evaluated at once (bounds memory).

    Returns
    -------
    (size, size, 3) array: ``sum f cos E`` per pixel (1/sr x irradiance units); NaN outside
    the sphere.
    """
    f = evaluator(brdf)
    pieces: Iterable[_SpherePiece]
    if isinstance(light, PointLight):
        weights = np.ones((1, 3))
        if size <= GEOMETRY_CACHE_SIZE:
            mask, m, pieces = _point_light_geometry(size, light, rotation_deg, batch)
        else:
            mask, m, pieces = _sphere_geometry(size, light.direction()[None, :],
                                               rotation_deg, batch)
    else:
        weights = light.weights
        mask, m, pieces = _sphere_geometry(size, light.directions, rotation_deg, batch)
    rad = np.zeros((m, 3))
    for s_idx, m_idx, wi, wo, cos in pieces:
        # Copies: an evaluator may work in its arguments, and a cached piece is read-only.
        val = _rgb(f(wi.copy(), wo.copy()))
        contrib = val * cos * weights[s_idx]
        for c in range(3):
            rad[:, c] += np.bincount(m_idx, weights=contrib[:, c], minlength=m)
    img = np.full((size, size, 3), np.nan)
    img[mask] = rad
    return img


_SpherePiece = tuple[NDArray[np.intp], NDArray[np.intp], FloatArray, FloatArray, FloatArray]
"""One evaluation call of :func:`render_sphere`: light sample and pixel of each direction
pair, the local ``wi`` and ``wo`` (N, 3), and ``cos(theta_i)`` (N, 1)."""


def _sphere_pieces(n: FloatArray, t: FloatArray, b: FloatArray, dirs: FloatArray, batch: int
                   ) -> Iterator[_SpherePiece]:
    """The direction pairs of :func:`render_sphere` (normals ``n`` and their frames, light
    directions ``dirs`` (K, 3)) in evaluation calls of about ``batch`` pairs."""
    wo = _to_local(np.array([0.0, 0.0, 1.0]), t, b, n)
    frame = np.stack([t, b, n], axis=1)  # (M, 3, 3): rows t, b, n
    m = n.shape[0]
    per = max(1, batch // max(m, 1))  # light samples per evaluation call
    for k0 in range(0, dirs.shape[0], per):
        d = dirs[k0 : k0 + per]
        wi = np.einsum("sk,mjk->smj", d, frame)  # (S, M, 3) local light directions
        s_idx, m_idx = np.nonzero(wi[..., 2] > 0)
        if s_idx.size == 0:
            continue
        yield k0 + s_idx, m_idx, wi[s_idx, m_idx], wo[m_idx], wi[s_idx, m_idx, 2:3]


def _sphere_geometry(size: int, dirs: FloatArray, rotation_deg: float, batch: int
                     ) -> tuple[NDArray[np.bool_], int, Iterator[_SpherePiece]]:
    """The sphere's mask, its pixel count and its direction pairs (made as they are used, so
    an environment's many samples are never all held at once)."""
    mask, n = sphere_normals(size)
    t, b = _frame(n, rotation_deg)
    return mask, n.shape[0], _sphere_pieces(n, t, b, dirs, batch)


GEOMETRY_CACHE_SIZE = 128
"""Largest image side whose point-light geometry (the pixels' direction pairs) is kept for
the next rendering of the same view. The export's rendered fit renders the same 48 and 96
pixel views a thousand times (:mod:`gonio.export.judge`), and working out the directions took
about as long as evaluating a principled model at them; a figure's 512 pixel views are
rendered a few times each, and would hold megabytes each. At most 16 sphere and 8 swatch
views are kept (under a megabyte each at 128 pixels); the judge's are 8."""


@functools.lru_cache(maxsize=16)
def _point_light_geometry(size: int, light: PointLight, rotation_deg: float, batch: int
                          ) -> tuple[NDArray[np.bool_], int, tuple[_SpherePiece, ...]]:
    """:func:`_sphere_geometry` of one point light, kept (read-only) for the next rendering."""
    mask, m, pieces = _sphere_geometry(size, light.direction()[None, :], rotation_deg, batch)
    kept = tuple(pieces)
    for arr in (mask, *(a for piece in kept for a in piece)):
        arr.flags.writeable = False
    return mask, m, kept


def render_sphere_env(brdf: Any, env: Environment | None = None, size: int = DEFAULT_SIZE,
                      rotation_deg: float = 0.0, work_size: int = 160) -> FloatArray:
    """The sphere under an environment (default :func:`studio_environment`); background NaN.

    The environment integral costs one BRDF lookup per pixel and light sample, so it is
    computed at ``work_size`` pixels and enlarged (bilinear) to ``size``; the table's 5 degree
    grid holds no detail that the smaller image would lose.
    """
    img = _resize(render_sphere(brdf, env or studio_environment(), min(work_size, size),
                                rotation_deg), size)
    mask, _ = sphere_normals(size)
    # The enlarged disc's rim is blurred: cut it with the full-size outline instead.
    return np.where(mask[..., None], np.nan_to_num(img), np.nan)


def _grow(img: FloatArray, steps: int) -> FloatArray:
    """Extend the drawn (finite) region of ``img`` by ``steps`` pixels with neighbour means,
    so an enlarged disc has values up to its full-size outline."""
    out = img.copy()
    for _ in range(steps):
        ok = np.isfinite(out[..., 0])
        val = np.where(ok[..., None], out, 0.0)
        acc = np.zeros_like(val)
        cnt = np.zeros(ok.shape)
        for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            acc += np.roll(val, (dy, dx), axis=(0, 1))
            cnt += np.roll(ok, (dy, dx), axis=(0, 1))
        fill = ~ok & (cnt > 0)
        out[fill] = acc[fill] / cnt[fill][:, None]
    return out


def _resize(img: FloatArray, size: int) -> FloatArray:
    """Bilinear resize of a (h, h, 3) image with NaN background to (size, size, 3)."""
    h = img.shape[0]
    if h == size:
        return img
    img = _grow(img, 2)
    valid = np.isfinite(img[..., 0]).astype(float)
    filled = np.nan_to_num(img)
    c = (np.arange(size) + 0.5) / size * h - 0.5
    i0 = np.clip(np.floor(c).astype(int), 0, h - 2)
    tt = np.clip(c - i0, 0.0, 1.0)

    def interp(a: FloatArray) -> FloatArray:
        rows = a[i0] * (1 - tt)[:, None, None] + a[i0 + 1] * tt[:, None, None]
        return rows[:, i0] * (1 - tt)[None, :, None] + rows[:, i0 + 1] * tt[None, :, None]

    num = interp(filled)
    den = interp(np.repeat(valid[..., None], 3, axis=2))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 1e-6, num / np.maximum(den, 1e-12), np.nan)


def render_swatch(brdf: Any, light: PointLight = PointLight(0.0, 0.0),
                  size: int = DEFAULT_SIZE, rotation_deg: float = 0.0) -> FloatArray:
    """Linear radiance image (size, size, 3) of the flat swatch (module docstring).

    The camera is a pinhole at ``(0, 0, SWATCH_DISTANCE)``; the point light sits at the same
    distance from the swatch centre in the direction ``light`` and gives irradiance 1 at the
    centre (``1/r^2`` elsewhere). ``rotation_deg`` turns the specimen about its normal.
    """
    f = evaluator(brdf)
    geometry = _swatch_geometry if size <= GEOMETRY_CACHE_SIZE else _swatch_geometry.__wrapped__
    wi, wo, scale = geometry(size, light, rotation_deg)
    val = _rgb(f(wi.copy(), wo.copy()))  # copies: as in render_sphere
    return (val * scale).reshape(size, size, 3)


@functools.lru_cache(maxsize=8)
def _swatch_geometry(size: int, light: PointLight, rotation_deg: float
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The swatch's direction pairs in the specimen frame (size*size, 3) and each pixel's
    ``cos(theta_i) E`` (size*size, 1), kept (read-only) for the next rendering of the same
    view (:data:`GEOMETRY_CACHE_SIZE`)."""
    p = swatch_points(size)
    cam = np.array([0.0, 0.0, SWATCH_DISTANCE])
    lamp = SWATCH_DISTANCE * light.direction()
    wo = cam - p
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    to_l = lamp - p
    r2 = np.sum(to_l * to_l, axis=1)
    wi = to_l / np.sqrt(r2)[:, None]
    c, s = math.cos(math.radians(rotation_deg)), math.sin(math.radians(rotation_deg))
    # Specimen frame = world frame turned by rotation_deg: express directions in it.
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    e = SWATCH_DISTANCE**2 / r2
    out = (wi @ rot.T, wo @ rot.T, (wi[:, 2] * e)[:, None])
    for arr in out:
        arr.flags.writeable = False
    return out


# --------------------------------------------------------------------------- display
def exposure_for(images: Sequence[FloatArray]) -> float:
    """Scale that maps the brightest finite pixel of ``images`` to 1.0 (no clipping)."""
    top = max((float(np.nanmax(im)) for im in images if np.isfinite(im).any()), default=0.0)
    return 1.0 / top if top > 0 else 1.0


def to_srgb(img: FloatArray, exposure: float, background: tuple[int, int, int] = (38, 40, 44)
            ) -> NDArray[np.uint8]:
    """Linear radiance x exposure -> 8-bit sRGB (IEC 61966-2-1 transfer); NaN -> background."""
    x = np.clip(np.nan_to_num(img * exposure, nan=0.0), 0.0, 1.0)
    v = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    out = np.round(v * 255.0).astype(np.uint8)
    out[~np.isfinite(img).all(axis=-1)] = background
    return out


# --------------------------------------------------------------------------- figures
@dataclass(frozen=True)
class View:
    """One picture of a figure: ``kind`` is "sphere", "swatch" or "environment"."""

    kind: str
    light: PointLight | None = None

    def title(self) -> str:
        if self.kind == "environment":
            return "sphere, studio environment"
        assert self.light is not None
        where = "swatch, flash" if self.kind == "swatch" and self.light.theta_deg == 0 else (
            f"{self.kind}, {self.light.label()}")
        return where


DEFAULT_VIEWS: tuple[View, ...] = (
    *(View("sphere", lt) for lt in DEFAULT_SPHERE_LIGHTS),
    View("swatch", PointLight(0.0, 0.0)),
    View("environment"),
)


def render_view(brdf: Any, view: View, size: int = DEFAULT_SIZE, rotation_deg: float = 0.0
                ) -> FloatArray:
    """Linear radiance (size, size, 3) of one :class:`View`; NaN where nothing is drawn."""
    f = evaluator(brdf)
    if view.kind == "sphere":
        assert view.light is not None
        return render_sphere(f, view.light, size, rotation_deg)
    if view.kind == "swatch":
        return render_swatch(f, view.light or PointLight(0.0, 0.0), size, rotation_deg)
    if view.kind == "environment":
        return render_sphere_env(f, None, size, rotation_deg)
    raise RenderError(f"unknown view kind {view.kind!r}; use sphere, swatch or environment")


def drawn_mask(view: View, size: int = DEFAULT_SIZE) -> NDArray[np.bool_]:
    """(size, size) bool: the pixels :func:`render_view` draws for ``view`` (the sphere's disc,
    lit or not, for "sphere" and "environment"; every pixel for "swatch")."""
    if view.kind in ("sphere", "environment"):
        return sphere_normals(size)[0]
    if view.kind == "swatch":
        return np.ones((size, size), dtype=bool)
    raise RenderError(f"unknown view kind {view.kind!r}; use sphere, swatch or environment")


def render_rows(rows: Sequence[tuple[str, Any]], views: Sequence[View] = DEFAULT_VIEWS,
                size: int = DEFAULT_SIZE) -> list[list[FloatArray]]:
    """Linear radiance of every (row material, view); rows are (label, BRDF) pairs."""
    out = []
    for _label, brdf in rows:
        f = evaluator(brdf)  # one lookup structure per material, shared by its views
        out.append([render_view(f, v, size) for v in views])
    return out


def figure_png(rows: Sequence[tuple[str, Any]], views: Sequence[View] = DEFAULT_VIEWS,
               size: int = DEFAULT_SIZE, title: str = "") -> bytes:
    """A PNG figure: one row per material, one column per view, labelled.

    Exposure is set per column, shared by all rows, so the same view of two materials (truth
    and reconstruction, or two scans) is directly comparable and no pixel is clipped.

    Parameters
    ----------
    rows : sequence of (label, BRDF)
        BRDFs are tables, models or anything with ``eval(wi, wo)``.
    views : sequence of View
    size : int
        Pixels per view side (at least 64).
    title : str
        First line of the heading.
    """
    import io

    from PIL import Image, ImageDraw, ImageFont

    if size < 64:
        raise RenderError(f"render size must be at least 64 pixels, got {size}")
    if not rows:
        raise RenderError("a figure needs at least one material")
    imgs = render_rows(rows, views, size)
    fs, fs_small = max(12, size // 28), max(11, size // 36)
    font = ImageFont.load_default(size=fs)
    small = ImageFont.load_default(size=fs_small)
    # The label column is as wide as the longest word of any label needs (up to 14 font
    # sizes): "reconstruction" was cut after 13 characters ("reconstructio" / "n").
    words = [w for label, _b in rows for w in label.split()]
    widest = max((font.getlength(w) for w in words), default=0.0)
    left = math.ceil(max(7 * fs, min(widest, 14 * fs))) + 10
    top, gap, foot = 3 * fs, 6, 3 * fs
    w = left + len(views) * (size + gap)
    h = top + len(rows) * (size + gap) + foot
    canvas = Image.new("RGB", (w, h), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    ink = (30, 30, 30)
    draw.text((6, 4), title or "rendered BRDF", fill=ink, font=font)
    for j, v in enumerate(views):
        e = exposure_for([r[j] for r in imgs])
        draw.text((left + j * (size + gap) + 4, top - fs - 4), v.title(), fill=ink, font=small)
        for i, r in enumerate(imgs):
            canvas.paste(Image.fromarray(to_srgb(r[j], e)),
                         (left + j * (size + gap), top + i * (size + gap)))
    for i, (label, _b) in enumerate(rows):
        y = top + i * (size + gap) + size // 2 - fs
        draw.text((6, y), label_lines(label, font.getlength, left - 10), fill=ink, font=font)
    y = top + len(rows) * (size + gap) + 4
    draw.text((left, y), "sRGB; exposure per column (shared by the rows): the brightest pixel "
              "of the column is white, so no highlight is clipped.", fill=ink, font=small)
    draw.text((left, y + fs_small + 4), "The material's x axis (the holder mark) runs "
              "left-right at the centre of each sphere and swatch.", fill=ink, font=small)
    buf = io.BytesIO()
    canvas.save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


def label_lines(text: str, length: Callable[[str], float], width: float) -> str:
    """``text`` broken between words into lines no longer than ``width`` as ``length``
    measures them (a font's ``getlength``, pixels); a word too long for a line alone is cut
    where it must be.

    Parameters
    ----------
    text : the label
    length : the drawn length of a string, pixels
    width : the longest line allowed, pixels

    Returns
    -------
    str : the lines, joined by newlines
    """
    words: list[str] = []
    for word in text.split():
        while length(word) > width and len(word) > 1:
            cut = max(1, max(i for i in range(1, len(word) + 1)
                             if i == 1 or length(word[:i]) <= width))
            words.append(word[:cut])
            word = word[cut:]
        words.append(word)
    lines: list[str] = []
    line = ""
    for word in words:
        trial = f"{line} {word}".strip()
        if line and length(trial) > width:
            lines.append(line)
            line = word
        else:
            line = trial
    if line:
        lines.append(line)
    return "\n".join(lines)
