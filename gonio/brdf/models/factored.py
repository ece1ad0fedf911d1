"""The non-parametric factored BRDF of ``000_d13a1931629fe3af`` (math.md 12) and its fit.

Model, per channel ``c`` (directions in the specimen frame, BRDF in 1/sr)::

    f_c(i, o) = rho_d[c] / pi
              + rho_s[c] D(th, ph) F[c](td) G(theta_i, phi_i) G(theta_o, phi_o) / (4 cos ti cos to)

with ``(th, ph, td, pd)`` the half/difference angles of ``(i, o)`` (math.md 2). The three factors
are tables:

* ``D`` on gonio's half-vector grid, ``th`` 0..85 deg x ``ph`` 0..355 deg (18 x 72), shared by
  all channels (the microgeometry is achromatic);
* ``F`` on the ``td`` grid 0..85 deg (18), one curve per channel (metals have coloured Fresnel);
* ``G`` on directions, ``theta`` 0..90 deg x ``phi`` 0..355 deg in 5 degree steps (19 x 72),
  shared by all channels, used separably for light and view.

Off-grid values are bilinear (``ph`` and ``phi`` periodic, elevations clamped).

Fit (000 Sec. 2): alternating weighted least squares over the valid cells of a table. Each
step solves one factor exactly with the others held fixed: ``D`` (one closed-form ratio per
node, since every table cell falls on exactly one ``D`` node), then ``F`` (likewise), then
``G`` (bilinear in direction: a small dense normal-equation solve; fitted once for the light
side with the view side fixed and once the other way round, the two averaged and smoothed),
then ``rho_d`` and ``rho_s`` (a non-negative 2 x 2 solve per channel). After every factor step
the dynamic-range clamp normalises the factor's maximum to 1 (moving the scale into ``rho_s``)
and clamps its minimum to 1e-6.

Weights: each cell carries the volume-form weight ``wV = 4 cos td sin td sin th`` (000 Eq. 10,
:func:`geometry.volume_weight`). The supplement calls ``wV`` a *sub*-weight and does not give
the rest; gonio multiplies it by ``1 / max(f, floor)^2`` with ``floor = max(1e-3, 0.1 median
f)`` (``weighting="relative"``, default), so the fit minimises a volume-weighted relative
squared error like the relMSE it reports; cells at exactly 0 (clamped measurements) are left
out.
``weighting="volume"`` uses ``wV`` alone (absolute errors, dominated by the specular peak).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics as bmetrics
from gonio.brdf.tables.npzfile import read_npz, write_npz
from gonio.brdf.tables.table import VALID_MASK, BRDFTable

FloatArray = NDArray[np.float64]
Weighting = Literal["relative", "volume"]

FORMAT_NAME = "gonio-factored"
FORMAT_VERSION = 1
#: Dynamic-range clamp of 000 Sec. 2: every factor's maximum is 1, its minimum this.
DR_MIN = 1e-6
#: ``G`` grid: elevations 0..90 deg (19 nodes, the horizon included), azimuths 0..355 (72).
N_G_THETA = 19
N_G_PHI = geo.N_PH
G_THETA_GRID: FloatArray = np.deg2rad(np.arange(N_G_THETA) * geo.STEP_DEG)
#: Floor of the relative weight, 1/sr: the same as the reported relMSE's (metrics.REL_FLOOR).
REL_FLOOR = bmetrics.REL_FLOOR
#: ... or this fraction of the table's median value, whichever is larger (fit weights only).
REL_FLOOR_FRACTION = 0.1
#: Start of the diffuse level: this quantile of each channel's off-specular cells, times pi.
_INIT_DIFFUSE_QUANTILE = 0.25


class FactoredError(ValueError):
    """A factored model or file is malformed, or a table cannot be fitted; says what to do."""


@dataclass(frozen=True)
class FactoredBRDF:
    """A fitted factored BRDF (module docstring for the model).

    Parameters
    ----------
    rho_d : (C,) array
        Diffuse albedo per channel (the diffuse term is ``rho_d / pi``, 1/sr).
    rho_s : (C,) array
        Specular scale per channel (1/sr with the dimensionless, max-normalised factors).
    D : (18, 72) array
        Half-vector distribution on ``th`` 0..85 deg x ``ph`` 0..355 deg, max 1.
    F : (C, 18) array
        Fresnel-like factor on ``td`` 0..85 deg per channel, each max 1.
    G : (19, 72) array
        Shadowing factor on ``theta`` 0..90 deg x ``phi`` 0..355 deg, max 1.
    channels : tuple of str, length C
    name : str
    metrics : mapping
        Fit quality against the fitted table (``rel_mse``, ``mape``, ``psnr``, ``log_rmse``),
        iterations, seconds, weighting.
    """

    rho_d: FloatArray
    rho_s: FloatArray
    D: FloatArray
    F: FloatArray
    G: FloatArray
    channels: tuple[str, ...]
    name: str = "unnamed"
    metrics: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        c = len(self.channels)
        shapes = {
            "rho_d": (np.shape(self.rho_d), (c,)),
            "rho_s": (np.shape(self.rho_s), (c,)),
            "D": (np.shape(self.D), (geo.N_TH, geo.N_PH)),
            "F": (np.shape(self.F), (c, geo.N_TD)),
            "G": (np.shape(self.G), (N_G_THETA, N_G_PHI)),
        }
        for key, (got, want) in shapes.items():
            if got != want:
                raise FactoredError(
                    f"factored model {self.name!r}: {key} has shape {got}, expected {want} "
                    f"for {c} channels"
                )
        for key in ("rho_d", "rho_s", "D", "F", "G"):
            arr = np.asarray(getattr(self, key), dtype=float)
            if not np.isfinite(arr).all() or (arr < 0).any():
                raise FactoredError(
                    f"factored model {self.name!r}: {key} must be finite and non-negative"
                )
            arr = arr.copy()
            arr.setflags(write=False)
            object.__setattr__(self, key, arr)
        object.__setattr__(self, "channels", tuple(str(x) for x in self.channels))
        object.__setattr__(self, "metrics", dict(self.metrics))

    # ------------------------------------------------------------------ evaluation
    def eval(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """The model at direction pairs.

        Parameters
        ----------
        wi, wo : (..., 3) array_like, unit vectors in the specimen frame

        Returns
        -------
        (..., C) array, 1/sr; 0 where either direction is at or below the horizon
        """
        i = np.asarray(wi, dtype=float)
        o = np.asarray(wo, dtype=float)
        i, o = np.broadcast_arrays(i, o)
        shape = i.shape[:-1]
        i2, o2 = i.reshape(-1, 3), o.reshape(-1, 3)
        out = np.zeros((i2.shape[0], len(self.channels)))
        above = (i2[:, 2] > 0) & (o2[:, 2] > 0)
        if above.any():
            ia, oa = i2[above], o2[above]
            th, ph, td, _ = geo.directions_to_half_diff(ia, oa)
            d = _bilinear(self.D, geo.TH_GRID, th, ph)
            f = np.stack([np.interp(td, geo.TD_GRID, fc) for fc in self.F], axis=-1)
            ti, pi_ = geo.direction_to_spherical(ia)
            to, po = geo.direction_to_spherical(oa)
            g = _bilinear(self.G, G_THETA_GRID, ti, pi_) * _bilinear(self.G, G_THETA_GRID, to, po)
            spec = d * g / (4.0 * ia[:, 2] * oa[:, 2])
            out[above] = self.rho_d / np.pi + spec[:, None] * f * self.rho_s
        return out.reshape(*shape, len(self.channels))

    def to_table(self, name: str | None = None) -> BRDFTable:
        """The model tabulated on gonio's grid (cell centres), as a :class:`BRDFTable`."""
        cells = _Cells.get()
        values = np.full((len(self.channels), *geo.TABLE_SHAPE), np.nan)
        values[:, :, VALID_MASK] = _model_values(self, cells)
        return BRDFTable.trusted(
            values, self.channels, name or self.name, None,
            {"source": "factored", "of": self.name},
        )

    # ------------------------------------------------------------------ files
    def arrays(self) -> dict[str, NDArray[Any]]:
        """The model as named arrays (the ``.npz`` and HDF5 layouts share these names)."""
        return {
            "rho_d": np.asarray(self.rho_d), "rho_s": np.asarray(self.rho_s),
            "D": np.asarray(self.D), "F": np.asarray(self.F), "G": np.asarray(self.G),
            "channels": np.array(self.channels),
            "D_theta_h_deg": np.rad2deg(geo.TH_GRID), "D_phi_h_deg": np.rad2deg(geo.PH_GRID),
            "F_theta_d_deg": np.rad2deg(geo.TD_GRID),
            "G_theta_deg": np.rad2deg(G_THETA_GRID), "G_phi_deg": np.rad2deg(geo.PH_GRID),
        }

    def save(
        self, path: str | os.PathLike[str], provenance: Mapping[str, Any] | None = None
    ) -> Path:
        """Write the ``.npz`` file of docs/file-formats.md; returns the path."""
        prov = {"metrics": dict(self.metrics), **dict(provenance or {})}
        return write_npz(
            path, FORMAT_NAME, FORMAT_VERSION, prov, name=np.array(self.name), **self.arrays()
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> FactoredBRDF:
        """Read a file written by :meth:`save`; :class:`FactoredError` on any problem."""
        data, prov = read_npz(
            path, format_name=FORMAT_NAME, version=FORMAT_VERSION,
            required=("rho_d", "rho_s", "D", "F", "G", "channels", "name"),
            error=FactoredError, kind="factored BRDF",
            how_to_make="write one with 'gonio export RESULT.h5 --format factored'",
        )
        return cls.from_arrays(data, str(data["name"]), prov.get("metrics", {}))

    @classmethod
    def from_arrays(
        cls, data: Mapping[str, Any], name: str, metrics: Mapping[str, Any] | None = None
    ) -> FactoredBRDF:
        """Rebuild from the arrays of :meth:`arrays` (extra keys are ignored)."""
        chans = tuple(
            x.decode() if isinstance(x, bytes) else str(x) for x in np.asarray(data["channels"])
        )
        return cls(
            np.asarray(data["rho_d"], float), np.asarray(data["rho_s"], float),
            np.asarray(data["D"], float), np.asarray(data["F"], float),
            np.asarray(data["G"], float), chans, name, dict(metrics or {}),
        )


# ---------------------------------------------------------------------------- interpolation
def _axis(x: FloatArray, grid_step: float, n: int, periodic: bool) -> tuple[
    NDArray[np.intp], NDArray[np.intp], FloatArray
]:
    """Lower/upper node and fraction along one axis of a uniform grid starting at 0."""
    if periodic:
        u = np.mod(x, 2 * np.pi) / grid_step
        i0 = np.floor(u).astype(np.intp)
        t = u - i0
        return i0 % n, (i0 + 1) % n, t
    u = np.clip(x / grid_step, 0.0, n - 1)
    i0 = np.minimum(np.floor(u).astype(np.intp), n - 2)
    return i0, i0 + 1, u - i0


def _bilinear(table: FloatArray, theta_grid: FloatArray, theta: FloatArray,
              phi: FloatArray) -> FloatArray:
    """Bilinear lookup in a (n_theta, 72) table, clamped in theta and periodic in phi."""
    a0, a1, ta = _axis(np.asarray(theta, float), geo.STEP, theta_grid.size, periodic=False)
    b0, b1, tb = _axis(np.asarray(phi, float), geo.STEP, geo.N_PH, periodic=True)
    return np.asarray(
        (1 - ta) * ((1 - tb) * table[a0, b0] + tb * table[a0, b1])
        + ta * ((1 - tb) * table[a1, b0] + tb * table[a1, b1]),
        dtype=float,
    )


# ---------------------------------------------------------------------------- cell geometry
@dataclass(frozen=True)
class _Cells:
    """Per valid cell and ``ph`` slice: factor node indices and weights (computed once).

    Arrays over cells are (72, Nv): slice ``k`` is ``ph = 5 k`` deg, ``Nv`` the valid cells of
    a slice in the C order of ``VALID_MASK``.
    """

    d_node: NDArray[np.intp]          # (72, Nv) flat index into D (18 x 72)
    td_index: NDArray[np.intp]        # (Nv,) index into F's grid
    th_index: NDArray[np.intp]        # (Nv,)
    g_in: tuple[NDArray[np.intp], FloatArray]   # (4, 72, Nv) flat G nodes, (4, Nv) weights
    g_out: tuple[NDArray[np.intp], FloatArray]
    geom: FloatArray                  # (Nv,) 1 / (4 cos ti cos to)
    wv: FloatArray                    # (Nv,) volume weight

    @staticmethod
    def get() -> _Cells:
        global _CELLS
        if _CELLS is None:
            _CELLS = _build_cells()
        return _CELLS


_CELLS: _Cells | None = None


def _g_corners(w: FloatArray) -> tuple[NDArray[np.intp], FloatArray]:
    """Bilinear G nodes of directions ``w`` (Nv, 3) at ph = 0, and of their turned copies.

    Turning a slice by ``ph = 5 k`` deg adds ``k`` whole steps to the azimuth, so the corner
    weights are the same in every slice and only the azimuth index shifts.
    """
    theta, phi = geo.direction_to_spherical(w)
    a0, a1, ta = _axis(theta, geo.STEP, N_G_THETA, periodic=False)
    b0, b1, tb = _axis(phi, geo.STEP, N_G_PHI, periodic=True)
    k = np.arange(geo.N_PH)[:, None]
    nodes = np.stack([
        a * N_G_PHI + (b[None, :] + k) % N_G_PHI
        for a, b in ((a0, b0), (a0, b1), (a1, b0), (a1, b1))
    ])
    weights = np.stack([(1 - ta) * (1 - tb), (1 - ta) * tb, ta * (1 - tb), ta * tb])
    return nodes.astype(np.intp), weights


def _build_cells() -> _Cells:
    th, td, pd = geo.grid_angles()
    ith, itd, _ = np.meshgrid(
        np.arange(geo.N_TH), np.arange(geo.N_TD), np.arange(geo.N_PD), indexing="ij"
    )
    m = VALID_MASK
    wi, wo = geo.half_diff_to_directions(th[m], 0.0, td[m], pd[m])
    k = np.arange(geo.N_PH)[:, None]
    d_node = ith[m][None, :] * geo.N_PH + k
    return _Cells(
        d_node=d_node.astype(np.intp), td_index=itd[m].astype(np.intp),
        th_index=ith[m].astype(np.intp), g_in=_g_corners(wi), g_out=_g_corners(wo),
        geom=1.0 / (4.0 * wi[:, 2] * wo[:, 2]), wv=geo.volume_weight()[m],
    )


def _g_values(G: FloatArray, corners: tuple[NDArray[np.intp], FloatArray]) -> FloatArray:
    nodes, w = corners
    flat = G.ravel()
    return np.asarray(sum(w[j][None, :] * flat[nodes[j]] for j in range(4)), dtype=float)


def _model_values(model: FactoredBRDF, cells: _Cells) -> FloatArray:
    """(C, 72, Nv) model values at the valid cells of every slice."""
    spec = _spec_shape(model.D, model.G, cells)  # (72, Nv), without F and rho_s
    f = model.F[:, cells.td_index]  # (C, Nv)
    return np.asarray(
        model.rho_d[:, None, None] / np.pi
        + model.rho_s[:, None, None] * f[:, None, :] * spec[None], dtype=float,
    )


def _spec_shape(D: FloatArray, G: FloatArray, cells: _Cells) -> FloatArray:
    return np.asarray(
        D.ravel()[cells.d_node] * _g_values(G, cells.g_in) * _g_values(G, cells.g_out)
        * cells.geom[None, :], dtype=float,
    )


# ---------------------------------------------------------------------------- the fit
def _dr_clamp(x: FloatArray) -> tuple[FloatArray, float]:
    """Normalise the maximum to 1 and clamp the minimum to :data:`DR_MIN`; returns the scale."""
    top = float(np.max(x))
    if not math.isfinite(top) or top <= 0:
        return np.full_like(x, DR_MIN), 0.0
    return np.maximum(x / top, DR_MIN), top


def _smooth_g(G: FloatArray) -> FloatArray:
    """One [1, 2, 1] / 4 binomial pass along the azimuth (periodic); theta = 0 pooled.

    000 smooths G after averaging its light- and view-side fits "for stable optimization"
    without saying how. gonio smooths along the azimuth only, where sparsely hit nodes ring
    from one node to the next; smoothing along the elevation would lift the horizon node, and
    the model divides G by ``cos theta``, which goes to 0 there: a lifted horizon node turns
    into large errors at grazing cells.
    """
    out = 0.25 * np.roll(G, 1, axis=1) + 0.5 * G + 0.25 * np.roll(G, -1, axis=1)
    out[0] = out[0].mean()  # theta = 0 is one direction: every azimuth node holds one value
    return np.asarray(out, dtype=float)


#: Bilinear corners of a G lookup in the order of :func:`_g_corners`, as (theta, phi) offsets
#: from the first corner: every pair of corners of one lookup couples two nodes a fixed offset
#: apart, which makes the normal matrix a 9-point stencil.
_CORNER_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


def _solve_g(
    side: tuple[NDArray[np.intp], FloatArray], a2w: FloatArray, ayw: FloatArray, G0: FloatArray
) -> FloatArray:
    """Weighted least-squares G (one side) from per-cell ``sum_c W a^2`` and ``sum_c W a r``.

    ``G(side) = sum_j b_j g_j`` (bilinear), so the normal equations are
    ``sum W a^2 b_j b_l g_l = sum W a r b_j``. Corner ``l`` of a lookup is always the same
    offset from corner ``j``, so each (j, l) block is a ``bincount`` over the row node and the
    matrix is sparse (9 entries a row). A small ridge toward the present ``G0`` keeps nodes no
    cell reaches (and barely reached ones) where they are.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    nodes, w = side
    n = N_G_THETA * N_G_PHI
    node_theta, node_phi = np.divmod(np.arange(n), N_G_PHI)
    rows: list[NDArray[np.intp]] = []
    cols: list[NDArray[np.intp]] = []
    vals: list[FloatArray] = []
    rhs = np.zeros(n)
    for j in range(4):
        bj = w[j][None, :]
        rhs += np.bincount(nodes[j].ravel(), (ayw * bj).ravel(), minlength=n)
        for k in range(j, 4):
            acc = np.bincount(nodes[j].ravel(), (a2w * bj * w[k][None, :]).ravel(), minlength=n)
            dt = _CORNER_OFFSETS[k][0] - _CORNER_OFFSETS[j][0]
            dp = _CORNER_OFFSETS[k][1] - _CORNER_OFFSETS[j][1]
            t2 = node_theta + dt
            keep = (acc != 0) & (t2 >= 0) & (t2 < N_G_THETA)
            r = np.flatnonzero(keep)
            c = t2[keep] * N_G_PHI + (node_phi[keep] + dp) % N_G_PHI
            rows.append(r)
            cols.append(c)
            vals.append(acc[keep])
            if k != j:
                rows.append(c)
                cols.append(r)
                vals.append(acc[keep])
    A = coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    ).tocsr()
    ridge = 1e-6 * float(A.diagonal().max(initial=0.0)) + 1e-30
    A = A + ridge * _identity(n)
    g = spsolve(A.tocsc(), rhs + ridge * G0.ravel())
    return np.asarray(np.asarray(g).reshape(N_G_THETA, N_G_PHI), dtype=float)


def _identity(n: int) -> Any:
    from scipy.sparse import identity

    return identity(n, format="csr")


def fit_factored(
    table: BRDFTable,
    *,
    iterations: int = 20,
    tol: float = 1e-4,
    weighting: Weighting = "relative",
    init: FactoredBRDF | None = None,
) -> FactoredBRDF:
    """Fit the factored model to a table by alternating weighted least squares (000 Sec. 2).

    Parameters
    ----------
    table : BRDFTable
        The BRDF to factor (a reconstruction, a library or measured table), 1/sr. NaN cells
        (unmeasured) are left out.
    iterations : int
        Maximum rounds of the D, F, G, rho alternation.
    tol : float
        Stop when a round lowers the weighted objective by less than this fraction.
    weighting : {"relative", "volume"}
        Cell weights (module docstring).
    init : FactoredBRDF, optional
        Start from this model (a warm start) instead of flat factors.

    Returns
    -------
    FactoredBRDF
        With ``metrics``: ``rel_mse``, ``mape``, ``psnr``, ``log_rmse`` of the model against
        ``table`` (:mod:`gonio.brdf.tables.metrics`), ``iterations``, ``seconds``, ``weighting``.

    Raises
    ------
    FactoredError
        Bad arguments, or a table with no positive finite value.
    """
    if weighting not in ("relative", "volume"):
        raise FactoredError(f"weighting = {weighting!r}; use 'relative' or 'volume'")
    if iterations < 1:
        raise FactoredError(f"iterations = {iterations}; give at least 1")
    t0 = time.perf_counter()
    cells = _Cells.get()
    y = np.asarray(table.values, dtype=float)[:, :, VALID_MASK]  # (C, 72, Nv)
    ok = np.isfinite(y)
    if not (ok & (y > 0)).any():
        raise FactoredError(f"table {table.name!r} has no positive finite value to factor")
    y = np.where(ok, y, 0.0)
    W = np.where(ok, cells.wv[None, None, :], 0.0)
    if weighting == "relative":
        # A cell at exactly 0 is a clamped measurement (noise below zero), not a value whose
        # relative error means anything: at the floor's weight a handful of them would pull
        # the whole fit toward 0. They are left out, like NaN cells.
        # The floor scales with the material: measured tables hold many noisy near-zero
        # cells at grazing angles, and at a fixed 1e-3 floor those few cells (weights 1e4
        # times a typical cell's) would decide the whole fit.
        floor = max(REL_FLOOR, REL_FLOOR_FRACTION * float(np.median(y[ok & (y > 0)])))
        W = np.where(y > 0, W / np.maximum(y, floor) ** 2, 0.0)
    W /= W.sum()
    nc = y.shape[0]

    # Start: diffuse from a dark quantile, flat factors; the first D step finds the lobe.
    rho_d = _initial_diffuse(y, ok & (y > 0), cells)
    rho_s = np.ones(nc)
    D = np.ones((geo.N_TH, geo.N_PH))
    F = np.ones((nc, geo.N_TD))
    G = np.ones((N_G_THETA, N_G_PHI))
    if init is not None:
        rho_d, rho_s = np.array(init.rho_d), np.array(init.rho_s)
        D, F, G = np.array(init.D), np.array(init.F), np.array(init.G)
    n_d = geo.N_TH * geo.N_PH

    def objective() -> float:
        spec = _spec_shape(D, G, cells)
        m = rho_d[:, None, None] / np.pi + (rho_s[:, None] * F[:, cells.td_index])[:, None] * spec
        return float(np.sum(W * (m - y) ** 2))

    last = math.inf
    done = 0
    for done in range(1, iterations + 1):  # noqa: B007 (reported after the loop)
        resid = y - rho_d[:, None, None] / np.pi  # what the specular term must explain
        g_in, g_out = _g_values(G, cells.g_in), _g_values(G, cells.g_out)
        # Every step's normal equations need only two channel sums per cell: with the
        # specular term rho_s F(td) x (rest), sum_c W c^2 and sum_c W c r, c = rho_s F(td).
        s2, s1 = _channel_sums(W, resid, rho_s[:, None] * F[:, cells.td_index])

        # D step: every cell sits on one D node, so each node is a weighted ratio.
        gg = g_in * g_out * cells.geom[None, :]
        num = np.bincount(cells.d_node.ravel(), (s1 * gg).ravel(), minlength=n_d)
        den = np.bincount(cells.d_node.ravel(), (s2 * gg * gg).ravel(), minlength=n_d)
        num, den = num.reshape(geo.N_TH, geo.N_PH), den.reshape(geo.N_TH, geo.N_PH)
        # th = 0 is the normal for every ph: pool its nodes into one value.
        num[0], den[0] = num[0].sum(), den[0].sum()
        D = np.where(den > 0, num / np.where(den > 0, den, 1.0), D)
        D, s = _dr_clamp(D)
        rho_s = rho_s * s

        # F step: each cell sits on one td node, per channel.
        b = D.ravel()[cells.d_node] * gg  # (72, Nv)
        wb = W * b[None]
        nf = np.stack([np.bincount(cells.td_index, (wb[c] * resid[c]).sum(0), minlength=geo.N_TD)
                       for c in range(nc)])
        df = np.stack([np.bincount(cells.td_index, (wb[c] * b).sum(0), minlength=geo.N_TD)
                       for c in range(nc)])
        # A channel with no specular part (rho_s = 0) keeps its F: nothing constrains it.
        use = (df > 0) & (rho_s[:, None] > 0)
        F = np.where(use, nf / np.where(use, df, 1.0) / np.where(use, rho_s[:, None], 1.0), F)
        for c in range(nc):
            F[c], s = _dr_clamp(F[c])
            rho_s[c] *= s

        # G step: light side with the view side fixed, then the reverse; average, smooth.
        s2, s1 = _channel_sums(W, resid, rho_s[:, None] * F[:, cells.td_index])
        base = D.ravel()[cells.d_node] * cells.geom[None, :]
        sides = []
        for fit_side, other in ((cells.g_in, g_out), (cells.g_out, g_in)):
            a = base * other
            sides.append(_solve_g(fit_side, s2 * a * a, s1 * a, G))
        G = _smooth_g(np.maximum(0.5 * (sides[0] + sides[1]), 0.0))
        G, s = _dr_clamp(G)
        rho_s = rho_s * s * s

        # rho step: per channel, non-negative weighted least squares on [1/pi, spec].
        spec = _spec_shape(D, G, cells)
        for c in range(nc):
            rho_d[c], rho_s[c] = _nonneg_pair(W[c], y[c], F[c, cells.td_index][None] * spec)
        e = objective()
        if math.isfinite(last) and 0.0 <= last - e <= tol * last:
            break
        last = e

    model = FactoredBRDF(rho_d, rho_s, D, F, G, table.channels, table.name)
    quality: dict[str, Any] = dict(fit_metrics(model.to_table(), table))
    quality.update(iterations=done, seconds=round(time.perf_counter() - t0, 3),
                   weighting=weighting)
    return FactoredBRDF(rho_d, rho_s, D, F, G, table.channels, table.name, quality)


def _initial_diffuse(y: FloatArray, ok: NDArray[np.bool_], cells: _Cells) -> FloatArray:
    """A first diffuse albedo per channel: pi times a low quantile of off-specular cells.

    Off-specular means ``th >= 30`` deg with both elevations within 60 deg of the normal:
    far from a glossy peak and from the noisy, often clamped grazing cells of measured data.
    The start matters: a specular term with ``G ~ cos theta`` can mimic a Lambert term, so a
    start with no diffuse lets the specular factors absorb it and the fit ends with a tiny
    ``rho_d``, a huge ``rho_s`` and a poor model.
    """
    th, td, pd = geo.grid_angles()
    ci, co = geo.cell_cosines(th, td, pd)
    off = ((th >= np.deg2rad(30)) & (np.minimum(ci, co) >= 0.5))[VALID_MASK]
    out = np.zeros(y.shape[0])
    for c in range(y.shape[0]):
        sel = ok[c][:, off]
        vals = y[c][:, off][sel]
        if vals.size == 0:
            vals = y[c][ok[c]]
        out[c] = np.pi * float(np.quantile(vals, _INIT_DIFFUSE_QUANTILE)) if vals.size else 0.0
    return out


def _channel_sums(
    W: FloatArray, resid: FloatArray, coef: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``sum_c W c^2`` and ``sum_c W c r`` per cell: (C, 72, Nv) weights and residuals with a
    (C, Nv) per-channel coefficient -> two (72, Nv) arrays."""
    wc = W * coef[:, None, :]
    return (
        np.asarray((wc * coef[:, None, :]).sum(0), dtype=float),
        np.asarray((wc * resid).sum(0), dtype=float),
    )


def _nonneg_pair(w: FloatArray, y: FloatArray, v: FloatArray) -> tuple[float, float]:
    """Non-negative weighted least squares ``y ~ p / pi + q v``; returns ``(p, q)``.

    Two unknowns, so the active-set cases (one of them at zero) are checked by hand.
    """
    u = 1.0 / np.pi
    wv = w * v
    suu, svv, suv = float(w.sum()) * u * u, float((wv * v).sum()), float(wv.sum()) * u
    suy, svy = float((w * y).sum()) * u, float((wv * y).sum())
    det = suu * svv - suv * suv
    if det > 1e-12 * suu * svv:
        p = (svv * suy - suv * svy) / det
        q = (suu * svy - suv * suy) / det
        if p >= 0 and q >= 0:
            return p, q
    # One of them at zero: take the better of the two one-term fits.
    p1 = max(suy / suu, 0.0) if suu > 0 else 0.0
    q1 = max(svy / svv, 0.0) if svv > 0 else 0.0
    e_p = float((w * (y - p1 * u) ** 2).sum())
    e_q = float((w * (y - q1 * v) ** 2).sum())
    return (p1, 0.0) if e_p <= e_q else (0.0, q1)


def fit_metrics(f_hat: BRDFTable, f_ref: BRDFTable) -> dict[str, float]:
    """The errors a fit is reported with: 000 Table 1's relMSE, MAPE, PSNR, plus log_rmse.

    All volume-weighted over the valid cells of both tables (:mod:`gonio.brdf.tables.metrics`;
    MAPE as a fraction). 000 evaluates its metrics on rendered images; these are on the BRDF
    itself, which is what a fit of a table can be held to without a renderer.
    """
    return {
        "rel_mse": bmetrics.rel_mse(f_hat, f_ref),
        "mape": bmetrics.mape(f_hat, f_ref),
        "psnr": bmetrics.psnr(f_hat, f_ref),
        "log_rmse": bmetrics.log_rmse(f_hat, f_ref),
    }
