"""The linear basis of isotropic BRDF slices (Vávra & Filip 2016, Sec. 3.1; docs/math.md section 4).

Every training material contributes one column per (channel, ``ph`` slice): the slice
``f[c, i_ph]`` flattened over ``(th, td, pd)`` into ``N_ROWS`` rows. The columns are remapped
to ``X = ln((A w + eps) / (f_med w + eps))`` with ``w = max(cos ti cos to, eps)`` and the
per-row median ``f_med``, centred by the per-row mean ``mu``, and decomposed ``Y = U S V^T``.
The basis keeps ``Q = U S`` for the first K components.

Decomposition and memory
------------------------
150 RGB materials give 32,400 columns over 7,861 valid rows. Holding that matrix in float64
would take 2.0 GB and a full SVD or an eigen-decomposition of the 7,861 x 7,861 row Gram
matrix costs about a minute on two cores, which is more than the whole build may take. Only
the leading K (<= a few hundred) components are ever used, so :func:`build_basis` computes
them with a randomized SVD (Halko, Martinsson & Tropp 2011, range finder with power
iterations):

* the remapped, centred training matrix is held once in float32 (1.0 GB for 150 materials);
* the range finder multiplies it by a Gaussian block of ``K + oversample`` columns and runs
  ``power_iterations`` rounds of ``Y (Y^T Z)`` with QR re-orthonormalisation in between; the
  fast BLAS float32 products here only steer the subspace;
* the final projection ``B = Z^T Y`` is accumulated in float64 over column blocks and the small
  ``(K + oversample)^2`` Gram matrix ``B B^T`` is eigen-decomposed in float64, which gives
  ``U`` and ``S``.

Peak memory is the float32 matrix plus a few ``rows x (K + oversample)`` panels and one float64
column block, on top of the training tables themselves. Measured figures are in
``docs/science.md`` (``bench/bench_basis.py``).

File format (``.npz``)
----------------------
=================  ======================  ==================================================
key                shape / dtype           meaning
=================  ======================  ==================================================
``format``         () str                  ``"gonio-brdf-basis"``
``version``        () int                  format version, currently 1
``Q``              (N_ROWS, K) float64     ``U S``; rows of invalid cells are 0 (float32 in
                                           the shipped basis; read back as float64)
``S``              (K,) float64            singular values
``f_med``          (N_ROWS,) float64       per-row median of the training columns, 1/sr
                                           (0 at invalid cells)
``mu``             (N_ROWS,) float64       per-row mean of the remapped columns (0 at invalid)
``valid``          (N_ROWS,) bool          valid-cell mask the basis was built with
``eps``            () float                remap constant
``materials``      (M,) str                names of the training materials
``provenance``     () str                  JSON object: how the basis was built; its
                                           ``without_twofold_symmetry`` lists the materials
                                           whose own prior has odd harmonics
``grid_deg``       (4,) float              grid step and counts check: ``(step, n_th, n_td,
                                           n_pd)``; a basis from another grid is refused
``ph_prior``       (37, K, K) float64      optional: covariance of the coefficients along
                                           ``ph`` per harmonic ``m = 0..36`` (see below;
                                           float32 when ``Q`` is)
``local_means``    (G, C, K) float64       optional: each folded-in table's coefficients
                                           averaged over ``ph``, per channel (the local
                                           priors, :func:`fold_in`; float32 when ``Q`` is)
``local_names``    (G,) str                the tables of ``local_means``
=================  ======================  ==================================================

Prior along ``ph`` (math.md 6)
----------------------------
The joint reconstruction treats the coefficients of one material as a stationary periodic
process along ``ph``: ``Cov(c(ph), c(ph')) = sum_m P_m cos(m (ph - ph'))``. ``P_m`` is learnt
from the training columns themselves: each (material, channel) gives 72 coefficient vectors
``c = S^-1 U^T x`` (one per slice), their discrete Fourier transform along ``ph`` gives
``c^_m``, and ``P_m`` is the mean over (material, channel) of ``Re(c^_m c^_m^H)`` (doubled for
``0 < m < 36``), times the number of columns. Isotropic materials contribute to ``P_0`` only.
The scaling makes ``sum_m P_m`` the identity over the training set (``U^T Y Y^T U = S^2``), so
the prior has V&F's ridge units: prior ``I / eta`` (isotropic limit) with unit noise.

Measured materials (:func:`fold_in`)
------------------------------------
Adding a few tables to a basis does not need a new randomized SVD of the whole library: the
centred training matrix is summarised by ``U S`` (its leading ``K0`` components), so the new
basis is the leading part of the thin SVD of ``[U S, sqrt(N0) (mu0 - mu), sqrt(w) (x_j - mu)]``
(Brand 2002's incremental SVD with a mean update): the old components, the shift of the mean,
and the new columns with weight ``w`` each. This costs about a second instead of a minute, so
leave-one-material-out studies and user imports rebuild cheaply. ``f_med`` is kept from the
base basis (the remap's reference only has to be a typical value).
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.npzfile import read_npz, write_npz
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]

FORMAT_NAME = "gonio-brdf-basis"
FORMAT_VERSION = 1
EPS = 1e-3
#: Components kept by :func:`default_basis` when none are asked for; chosen from the quality
#: table of ``bench/bench_quality.py`` (see ``docs/science.md``).
DEFAULT_COMPONENTS = 64
#: Harmonics 0..36 of a function sampled on the 72 ``ph`` slices.
N_HARMONICS = geo.N_PH // 2 + 1
#: Largest share of the prior's trace in odd harmonics for :attr:`Basis.half_turn_periodic`
#: (an imported material without twofold symmetry brings far more; round-off far less).
ODD_SHARE_MAX = 1e-6
_GRID_SIGNATURE = np.array([geo.STEP_DEG, geo.N_TH, geo.N_TD, geo.N_PD], dtype=float)


class BasisError(ValueError):
    """A basis, its inputs or its file are unusable; the message says what and what to do."""


# ---------------------------------------------------------------------------- remap
def remap(values: ArrayLike, f_med: ArrayLike, w: ArrayLike, eps: float = EPS) -> FloatArray:
    """Forward remap of V&F Eq. 1: ``ln((A w + eps) / (f_med w + eps))``.

    Parameters
    ----------
    values : array_like, 1/sr
        BRDF values ``A``; broadcast against ``f_med`` and ``w``.
    f_med : array_like, 1/sr
        Per-row median of the training data.
    w : array_like
        Cosine weight ``max(cos ti cos to, eps)``.
    eps : float

    Returns
    -------
    array
        Remapped values (dimensionless), broadcast shape.
    """
    a = np.asarray(values, dtype=float)
    fw = np.asarray(f_med, dtype=float) * np.asarray(w, dtype=float)
    return np.asarray(np.log((a * w + eps) / (fw + eps)))


def inverse_remap(
    x: ArrayLike, f_med: ArrayLike, w: ArrayLike, eps: float = EPS
) -> FloatArray:
    """Inverse of :func:`remap`: ``(exp(X) (f_med w + eps) - eps) / w`` (not clamped)."""
    w_ = np.asarray(w, dtype=float)
    fw = np.asarray(f_med, dtype=float) * w_
    return np.asarray((np.exp(np.asarray(x, dtype=float)) * (fw + eps) - eps) / w_)


def row_weight(eps: float = EPS) -> FloatArray:
    """(N_ROWS,) remap weight ``w`` of every grid row."""
    return geo.remap_weight(eps).ravel()


# ---------------------------------------------------------------------------- the basis
@dataclass(frozen=True)
class Basis:
    """A truncated linear basis of remapped isotropic BRDF slices.

    Parameters
    ----------
    Q : (N_ROWS, K) float64
        Principal components scaled by their singular values (``U S``); zero rows at invalid
        cells.
    S : (K,) float64
        Singular values, descending.
    f_med : (N_ROWS,) float64, 1/sr
        Per-row median of the training columns (0 at invalid cells).
    mu : (N_ROWS,) float64
        Per-row mean of the remapped columns (0 at invalid cells).
    valid : (N_ROWS,) bool
        Valid-cell mask (:func:`geometry.valid_mask`, flattened).
    eps : float
        Remap constant of Eq. 1.
    materials : tuple of str
        Training material names.
    provenance : dict
        JSON-serialisable build record.
    ph_prior : (37, K, K) float64, optional
        Covariance of the coefficients along ``ph`` per harmonic (module notes); ``None`` for
        a basis built without it (the joint fit then assumes an isotropic prior).
    local_means : (G, C, K) float64, optional
        Each table folded in by :func:`fold_in` (the measured and user tables): its
        coefficients averaged over ``ph``, one row per channel, in this basis' coordinates
        (centred on ``mu``). Their second moments are the local priors
        (:attr:`local_priors`); the joint fit may lean on the one its readings favour
        (:mod:`gonio.brdf.reconstruction.localprior`). ``None``: none.
    local_names : tuple of str
        The table of each row of ``local_means`` (G names).
    """

    Q: FloatArray
    S: FloatArray
    f_med: FloatArray
    mu: FloatArray
    valid: NDArray[np.bool_]
    eps: float = EPS
    materials: tuple[str, ...] = ()
    provenance: Mapping[str, Any] = field(default_factory=dict)
    ph_prior: FloatArray | None = None
    local_means: FloatArray | None = None
    local_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        Q = np.asarray(self.Q, dtype=np.float64)
        S = np.asarray(self.S, dtype=np.float64)
        f_med = np.asarray(self.f_med, dtype=np.float64)
        mu = np.asarray(self.mu, dtype=np.float64)
        valid = np.asarray(self.valid, dtype=bool)
        if Q.ndim != 2 or Q.shape[0] != geo.N_ROWS:
            raise BasisError(
                f"basis Q has shape {Q.shape}; expected ({geo.N_ROWS}, K): one row per cell of "
                "the 5 degree (th, td, pd) grid. The basis was built for another grid; rebuild "
                "it with `gonio basis build`"
            )
        K = Q.shape[1]
        for nm, arr, shape in (
            ("S", S, (K,)), ("f_med", f_med, (geo.N_ROWS,)), ("mu", mu, (geo.N_ROWS,)),
            ("valid", valid, (geo.N_ROWS,)),
        ):
            if arr.shape != shape:
                raise BasisError(f"basis field {nm} has shape {arr.shape}, expected {shape}")
        if not np.array_equal(valid, geo.valid_mask().ravel()):
            raise BasisError(
                "basis valid-cell mask differs from this gonio's grid; rebuild the basis with "
                "`gonio basis build`"
            )
        if not (np.isfinite(Q).all() and np.isfinite(f_med).all() and np.isfinite(mu).all()):
            raise BasisError("basis holds NaN or infinite values; rebuild it")
        if not self.eps > 0:
            raise BasisError(f"basis eps must be positive, got {self.eps}")
        if self.ph_prior is not None:
            prior = np.asarray(self.ph_prior, dtype=np.float64)
            if prior.shape != (N_HARMONICS, K, K) or not np.isfinite(prior).all():
                raise BasisError(
                    f"basis ph_prior has shape {prior.shape}, expected ({N_HARMONICS}, {K}, "
                    f"{K}) finite values; rebuild the basis"
                )
            prior.setflags(write=False)
            object.__setattr__(self, "ph_prior", prior)
        names = tuple(str(n) for n in self.local_names)
        if self.local_means is not None:
            local = np.asarray(self.local_means, dtype=np.float64)
            if (local.ndim != 3 or local.shape[0] != len(names) or local.shape[2] != K
                    or not np.isfinite(local).all()):
                raise BasisError(
                    f"basis local_means has shape {local.shape} for {len(names)} names, "
                    f"expected ({len(names)}, channels, {K}) finite values; rebuild the basis")
            local.setflags(write=False)
            object.__setattr__(self, "local_means", local)
        elif names:
            raise BasisError("basis local_names given without local_means; rebuild the basis")
        object.__setattr__(self, "local_names", names)
        Q = np.where(valid[:, None], Q, 0.0)
        for arr in (Q, S, f_med, mu, valid):
            arr.setflags(write=False)
        object.__setattr__(self, "Q", Q)
        object.__setattr__(self, "S", S)
        object.__setattr__(self, "f_med", f_med)
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "eps", float(self.eps))
        object.__setattr__(self, "materials", tuple(str(m) for m in self.materials))
        object.__setattr__(self, "provenance", dict(self.provenance))

    @property
    def K(self) -> int:
        """Number of components."""
        return int(self.Q.shape[1])

    @property
    def local_priors(self) -> FloatArray | None:
        """(G, K, K) the local priors: each folded-in table's second moment of its
        ``ph``-averaged coefficients, summed over channels (``sum_c m_c m_c^T``), scaled to the
        trace of the learnt prior's isotropic harmonic ``ph_prior[0]`` (so that leaning on one
        keeps the prior's size, whatever ``K``). ``None`` without ``local_means`` or
        ``ph_prior``."""
        if self.local_means is None or self.ph_prior is None:
            return None
        L = np.einsum("gck,gcl->gkl", self.local_means, self.local_means)
        size = np.trace(L, axis1=1, axis2=2)
        scale = np.where(size > 0, float(np.trace(self.ph_prior[0])) / np.where(
            size > 0, size, 1.0), 1.0)
        return np.asarray(L * scale[:, None, None])

    @property
    def half_turn_periodic(self) -> bool:
        """Whether the prior says a specimen turned by half a turn reads the same.

        True when the odd harmonics of :attr:`ph_prior` hold at most :data:`ODD_SHARE_MAX` of
        its trace (the shipped library's hold none: every material is reciprocal and twofold
        symmetric), or when there is no prior (isotropic). Scans of such a basis lose nothing
        by covering half a turn (:data:`gonio.brdf.reconstruction.samples.DEFAULT_SPAN_DEG`).
        """
        return self.ph_prior is None or not _has_odd_harmonics(self.ph_prior)

    @property
    def without_twofold_symmetry(self) -> tuple[str, ...]:
        """Training materials whose own prior holds odd harmonics (no twofold symmetry).

        Recorded by :func:`build_basis` and :func:`fold_in` in the provenance (key
        ``without_twofold_symmetry``); empty for a basis written before they recorded it, which
        then says only, through :attr:`half_turn_periodic`, that some material lacks it.
        """
        names = self.provenance.get("without_twofold_symmetry", ())
        return tuple(str(n) for n in names) if isinstance(names, list | tuple) else ()

    def truncated(self, k: int) -> Basis:
        """The first ``k`` components (1 <= k <= K)."""
        if not 1 <= k <= self.K:
            raise BasisError(f"cannot keep {k} components of a basis with K = {self.K}")
        if k == self.K:
            return self
        prior = None if self.ph_prior is None else self.ph_prior[:, :k, :k]
        local = None if self.local_means is None else self.local_means[:, :, :k]
        return Basis(
            self.Q[:, :k], self.S[:k], self.f_med, self.mu, self.valid, self.eps,
            self.materials, {**self.provenance, "truncated_from": self.K}, prior, local,
            self.local_names,
        )

    # ------------------------------------------------------------------ off-grid rows
    def neighbours(
        self, th: ArrayLike, td: ArrayLike, pd: ArrayLike
    ) -> tuple[NDArray[np.intp], FloatArray]:
        """Grid rows and trilinear weights around off-grid cells.

        Periodic in ``pd`` (period pi), clamped in ``th`` and ``td``; invalid neighbours get
        weight 0 and the rest are renormalised to sum to 1.

        Parameters
        ----------
        th, td, pd : (n,) array_like, radians

        Returns
        -------
        rows : (n, 8) intp
            Flat row indices of the eight surrounding grid cells.
        weights : (n, 8) float64
            Blend weights, each row summing to 1.

        Raises
        ------
        BasisError
            When a cell has no valid neighbour (both directions near or below the horizon).
        """
        th_, td_, pd_ = (np.atleast_1d(np.asarray(a, dtype=float)).ravel() for a in (th, td, pd))
        axes = []
        for a, n in ((th_, geo.N_TH), (td_, geo.N_TD)):
            u = np.clip(a / geo.STEP, 0.0, n - 1)
            i0 = np.minimum(np.floor(u).astype(np.intp), n - 2)
            axes.append((i0, i0 + 1, u - i0))
        u = np.mod(pd_, np.pi) / geo.STEP
        i0 = np.floor(u).astype(np.intp)
        t = u - i0
        axes.append((i0 % geo.N_PD, (i0 + 1) % geo.N_PD, t))
        rows = np.empty((th_.size, 8), dtype=np.intp)
        weights = np.empty((th_.size, 8))
        for corner, (idx, w) in enumerate(geo.lattice_corners(axes)):
            rows[:, corner] = geo.flat_row(*idx)
            weights[:, corner] = w
        weights = np.where(self.valid[rows], weights, 0.0)
        total = weights.sum(axis=1)
        bad = total <= 1e-12
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise BasisError(
                f"cell {k} (th={np.rad2deg(th_[k]):.1f}, td={np.rad2deg(td_[k]):.1f}, "
                f"pd={np.rad2deg(pd_[k]):.1f} deg) has no valid grid neighbour: its light or "
                "sensor is at or below the horizon; drop that pair"
            )
        return rows, weights / total[:, None]

    def rows_at(self, th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> FloatArray:
        """Basis rows at (possibly off-grid) cells: (n, K) trilinear blend of grid rows."""
        rows, weights = self.neighbours(th, td, pd)
        return np.einsum("nj,njk->nk", weights, self.Q[rows])

    def blend(self, per_row: ArrayLike, th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> FloatArray:
        """Blend a per-row quantity ((N_ROWS,) such as ``f_med`` or ``mu``) at cells: (n,)."""
        rows, weights = self.neighbours(th, td, pd)
        return np.asarray((weights * np.asarray(per_row, dtype=float)[rows]).sum(axis=1))

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike[str], dtype: type[np.floating[Any]] = np.float64,
             ) -> Path:
        """Write the basis as ``.npz`` (layout in the module docstring); returns the path.

        ``dtype`` is that of the two large arrays, ``Q`` and ``ph_prior``: float32 halves the
        file (the shipped basis) and :meth:`load` reads either back as float64.
        """
        return write_npz(
            path, FORMAT_NAME, FORMAT_VERSION, self.provenance,
            Q=self.Q.astype(dtype), S=self.S, f_med=self.f_med, mu=self.mu, valid=self.valid,
            eps=np.array(self.eps), materials=np.array(self.materials, dtype=str),
            grid_deg=_GRID_SIGNATURE,
            **({} if self.ph_prior is None else {"ph_prior": self.ph_prior.astype(dtype)}),
            **({} if self.local_means is None else {
                "local_means": self.local_means.astype(dtype),
                "local_names": np.array(self.local_names, dtype=str)}),
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Basis:
        """Read a basis written by :meth:`save`; :class:`BasisError` with the reason otherwise."""
        p = Path(path)
        data, prov = read_npz(
            p, format_name=FORMAT_NAME, version=FORMAT_VERSION,
            required=("Q", "S", "f_med", "mu", "valid", "eps", "grid_deg"),
            error=BasisError, kind="basis", how_to_make="build one with `gonio basis build`",
        )
        grid = np.asarray(data["grid_deg"], dtype=float)
        if grid.shape != _GRID_SIGNATURE.shape or not np.allclose(grid, _GRID_SIGNATURE):
            raise BasisError(
                f"{p}: basis was built on another grid (step, n_th, n_td, n_pd = "
                f"{grid.tolist()}; this gonio uses {_GRID_SIGNATURE.tolist()}); rebuild it "
                "with `gonio basis build`"
            )
        try:
            return cls(
                data["Q"], data["S"], data["f_med"], data["mu"], data["valid"],
                float(data["eps"]), tuple(np.asarray(data.get("materials", [])).tolist()),
                prov, data.get("ph_prior"), data.get("local_means"),
                tuple(np.asarray(data.get("local_names", [])).tolist()),
            )
        except BasisError as exc:
            raise BasisError(f"{p}: {exc}") from None


# ---------------------------------------------------------------------------- building
def _progress(it: Any, enabled: bool, desc: str, total: int | None = None) -> Any:
    if not enabled:
        return it
    from tqdm import tqdm  # only the CLI asks for bars; keep the import off the library path

    return tqdm(it, desc=desc, total=total, unit="material" if total else None)


def build_basis(
    tables: Sequence[BRDFTable],
    n_components: int,
    progress: bool = False,
    *,
    eps: float = EPS,
    oversample: int = 24,
    power_iterations: int = 3,
    seed: int = 0,
) -> Basis:
    """Learn the basis from training tables (math.md 4) with a randomized SVD.

    Parameters
    ----------
    tables : sequence of BRDFTable
        Training materials; every channel of every ``ph`` slice becomes one column. A NaN at a
        valid cell (an unmeasured value) is treated as the row median, i.e. remapped to 0.
    n_components : int
        K, the number of components kept (at most the number of columns).
    progress : bool
        Show tqdm progress bars.
    eps : float
        Remap constant of Eq. 1.
    oversample, power_iterations : int
        Randomized SVD settings: extra probe vectors and ``Y Y^T`` rounds (see module notes).
    seed : int
        Seed of the Gaussian probe block; the result is deterministic for a given seed.

    Returns
    -------
    Basis
    """
    if len(tables) == 0:
        raise BasisError("cannot build a basis from zero materials; give at least one table")
    names = [t.name for t in tables]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise BasisError(f"training materials must have distinct names; repeated: {dupes}")
    m = sum(t.n_channels * geo.N_PH for t in tables)
    if not 1 <= n_components <= m:
        raise BasisError(
            f"n_components must be between 1 and the number of training columns ({m}), "
            f"got {n_components}"
        )
    t0 = time.perf_counter()
    valid = geo.valid_mask().ravel()
    rows = np.flatnonzero(valid)
    p = rows.size
    A = np.empty((p, m), dtype=np.float32)
    j = 0
    for t in _progress(tables, progress, "basis: gather", len(tables)):
        cols = t.columns()[:, rows]  # (C*72, p)
        A[:, j : j + cols.shape[0]] = cols.T
        j += cols.shape[0]

    # Median, remap and centring run over blocks of rows so the temporaries stay small.
    w = row_weight(eps)[rows]
    f_med = np.empty(p)
    mu = np.empty(p)
    block = 512
    for r0 in range(0, p, block):
        blk = A[r0 : r0 + block]
        has_nan = np.isnan(blk).any()
        med = np.nanmedian(blk, axis=1) if has_nan else np.median(blk, axis=1)
        if np.isnan(med).any():
            raise BasisError(
                "some valid cells hold no finite value in any training table; the basis "
                "cannot learn them"
            )
        f_med[r0 : r0 + block] = med
        x = remap(blk, med[:, None], w[r0 : r0 + block, None], eps)
        if has_nan:
            x = np.nan_to_num(x, nan=0.0)
        mu[r0 : r0 + block] = x.mean(axis=1)
        A[r0 : r0 + block] = x - mu[r0 : r0 + block, None]
    Y = A  # remapped and centred in place

    U, S = _randomized_svd(Y, n_components, oversample, power_iterations, seed)
    coef = _coefficients(Y, U, S)
    prior = ph_prior_from_coefficients(coef, m)
    odd = _odd_materials(names, coef, [t.n_channels * geo.N_PH for t in tables])
    Q = np.zeros((geo.N_ROWS, n_components))
    Q[rows] = U * S
    f_full = np.zeros(geo.N_ROWS)
    f_full[rows] = f_med
    mu_full = np.zeros(geo.N_ROWS)
    mu_full[rows] = mu
    prov = {
        "method": "randomized SVD of the remapped, centred slice matrix",
        "n_materials": len(tables),
        "n_columns": m,
        "n_valid_rows": int(p),
        "oversample": oversample,
        "power_iterations": power_iterations,
        "seed": seed,
        "build_seconds": round(time.perf_counter() - t0, 3),
        "materials_digest": _names_digest(names),
        "without_twofold_symmetry": odd,
    }
    return Basis(Q, S, f_full, mu_full, valid, eps, tuple(names), prov, prior)


def _has_odd_harmonics(prior: FloatArray) -> bool:
    """Whether the odd harmonics of a (37, K, K) prior hold more than :data:`ODD_SHARE_MAX` of
    its trace (see :attr:`Basis.half_turn_periodic`)."""
    traces = np.abs(np.trace(prior, axis1=1, axis2=2))
    return bool(traces[1::2].sum() > ODD_SHARE_MAX * max(traces.sum(), 1e-300))


def _odd_materials(names: Sequence[str], coef: FloatArray, columns: Sequence[int]) -> list[str]:
    """The materials among ``names`` whose own coefficients ((K, sum(columns)), ``columns[i]``
    consecutive ones for material ``i``, groups of 72 ``ph`` slices) hold odd harmonics.

    Recorded so a warning about a half-turn scan can name them: the whole prior only says that
    some material lacks the twofold symmetry, not which.
    """
    out, j = [], 0
    for name, n in zip(names, columns, strict=True):
        if n >= geo.N_PH and _has_odd_harmonics(ph_prior_from_coefficients(coef[:, j:j + n], 1.0)):
            out.append(name)
        j += n
    return out


def _coefficients(Y: NDArray[np.float32], U: FloatArray, S: FloatArray) -> FloatArray:
    """Coefficients ``S^-1 U^T Y`` (K, m) of every training column, in column blocks."""
    Ut = (U / np.where(S > 0, S, 1.0)).T.astype(np.float32)
    out = np.empty((U.shape[1], Y.shape[1]))
    for c0 in range(0, Y.shape[1], 8192):
        out[:, c0 : c0 + 8192] = Ut @ Y[:, c0 : c0 + 8192]
    return out


def ph_prior_from_coefficients(coef: FloatArray, n_columns: float) -> FloatArray:
    """Per-harmonic covariance of coefficients along ``ph`` (module notes, "Prior along ph").

    Parameters
    ----------
    coef : (K, G * 72) float64
        Coefficients of G groups of 72 consecutive columns (one group = one material channel,
        slices in ``ph`` order).
    n_columns : float
        Number of training columns the covariances are scaled by.

    Returns
    -------
    (37, K, K) float64
        ``P_m`` for ``m = 0..36``.
    """
    K = coef.shape[0]
    groups = coef.reshape(K, -1, geo.N_PH)
    F = np.fft.rfft(groups, axis=2) / geo.N_PH  # (K, G, 37)
    double = np.full(N_HARMONICS, 2.0)
    double[0] = double[-1] = 1.0
    P = np.einsum("kgm,lgm->mkl", F, F.conj()).real * (double / groups.shape[1])[:, None, None]
    return np.asarray(P * n_columns)


def fold_in(
    base: Basis,
    tables: Sequence[BRDFTable],
    weight: float,
    n_components: int | None = None,
) -> Basis:
    """Add measured tables to a basis by an incremental SVD (module notes, "Measured materials").

    Parameters
    ----------
    base : Basis
        A basis built by :func:`build_basis` (its ``provenance["n_columns"]`` says how many
        columns it summarises); the more components it keeps, the less of it is lost.
    tables : sequence of BRDFTable
        The added materials (R, G, B). Identical ``ph`` slices (isotropic tables) are
        counted once with 72 times the weight.
    weight : float
        How many synthetic materials one added material counts as (>= 0; 0 returns the base
        truncated to ``n_components``).
    n_components : int, optional
        K of the result; default ``base.K``.

    Returns
    -------
    Basis
        Its ``ph_prior`` is the base's, carried into the new components, plus the added
        materials' own (isotropic or not).
    """
    k = base.K if n_components is None else int(n_components)
    if not 1 <= k <= base.K:
        raise BasisError(f"cannot keep {k} components when folding into a basis with K = {base.K}")
    if weight < 0 or not np.isfinite(weight):
        raise BasisError(f"the weight of added materials must be >= 0, got {weight}")
    if weight == 0 or not tables:
        return base.truncated(k)
    n0 = float(base.provenance.get("n_columns", 0)) or float(len(base.materials) * 3 * geo.N_PH)
    rows = np.flatnonzero(base.valid)
    w_rows = row_weight(base.eps)[rows]
    cols: list[FloatArray] = []
    col_w: list[float] = []
    groups: list[tuple[int, int, float]] = []  # (first column, count, weight of each column)
    # (name, first column, columns) of the tables that are not isotropic: 72 slices a channel
    anisotropic: list[tuple[str, int, int]] = []
    owners: list[int] = []  # which added table each group is a channel of
    for ti, t in enumerate(tables):
        v = np.asarray(t.values, dtype=np.float64).reshape(
            t.n_channels, geo.N_PH, geo.N_ROWS)[:, :, rows]
        iso = bool(np.allclose(v, v[:, :1], equal_nan=True))
        if not iso:
            anisotropic.append((t.name, len(cols), t.n_channels * geo.N_PH))
        for c in range(t.n_channels):
            owners.append(ti)
            x = remap(v[c], base.f_med[rows], w_rows, base.eps)
            x = np.nan_to_num(x, nan=0.0)  # unmeasured cells count as the median (as build)
            if iso:
                groups.append((len(cols), 1, weight * geo.N_PH))
                cols.append(x[0])
                col_w.append(weight * geo.N_PH)
            else:
                groups.append((len(cols), geo.N_PH, weight))
                cols.extend(x)
                col_w.extend([weight] * geo.N_PH)
    X = np.stack(cols, axis=1)  # (p, J)
    cw = np.asarray(col_w)
    n_total = n0 + cw.sum()
    mu0 = base.mu[rows]
    mu = (n0 * mu0 + X @ cw) / n_total
    M = np.concatenate(
        [base.Q[rows], np.sqrt(n0) * (mu0 - mu)[:, None], (X - mu[:, None]) * np.sqrt(cw)],
        axis=1,
    )
    U, S, _ = np.linalg.svd(M, full_matrices=False)
    U, S = U[:, :k], S[:k]
    flip = np.sign(U[np.abs(U).argmax(axis=0), np.arange(k)])
    flip[flip == 0] = 1.0
    U = U * flip
    Q = np.zeros((geo.N_ROWS, k))
    Q[rows] = U * S
    mu_full = np.zeros(geo.N_ROWS)
    mu_full[rows] = mu
    pinv = (U / S).T  # (k, p): coefficients of a centred column in the new basis
    C = pinv @ (X - mu[:, None])  # (k, J)
    # Which added materials lack the twofold symmetry (an isotropic table has it), so that a
    # warning about a half-turn scan can name them.
    odd = [*base.without_twofold_symmetry]
    for name, first, n in anisotropic:
        odd += _odd_materials([name], C[:, first:first + n], [n])
    prior = None
    T = pinv @ base.Q[rows]  # (k, K0)
    if base.ph_prior is not None:
        d = pinv @ (mu0 - mu)
        # Priors are sums over the training columns (sum_m P_m ~ I): carry the base's into the
        # new coordinates (c_new = T c_old + d), then add the shift of the mean and the new
        # columns.
        prior = T @ base.ph_prior @ T.T
        prior[0] += n0 * np.outer(d, d)
        for first, count, wcol in groups:
            sub = C[:, first : first + count]
            if count == 1:
                prior[0] += wcol * np.outer(sub[:, 0], sub[:, 0])
            else:
                prior += wcol * geo.N_PH * ph_prior_from_coefficients(sub, 1.0)
    local_means, local_names = _local_means(base, tables, T, C, groups, owners,
                                            pinv @ (mu0 - mu))
    names = (*base.materials, *(t.name for t in tables))
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise BasisError(f"training materials must have distinct names; repeated: {dupes}")
    prov = {
        **base.provenance,
        "n_columns": n_total,
        "folded_in": {"materials": [t.name for t in tables], "weight": float(weight),
                      "base_K": base.K},
        "materials_digest": _names_digest(names),
        "without_twofold_symmetry": odd,
    }
    return Basis(Q, S, base.f_med, mu_full, base.valid, base.eps, names, prov, prior,
                 local_means, local_names)


def _local_means(
    base: Basis, tables: Sequence[BRDFTable], T: FloatArray, C: FloatArray,
    groups: Sequence[tuple[int, int, float]], owners: Sequence[int], shift: FloatArray,
) -> tuple[FloatArray | None, tuple[str, ...]]:
    """Each added table's ``ph``-averaged coefficients per channel, for :func:`fold_in`.

    The base's own rows are carried into the new coordinates exactly, as every coefficient
    is: ``T m + shift`` (``shift`` the old mean in the new coordinates). The rows must share
    one number of channels; tables with another are left out of the local priors.
    """
    entries: list[tuple[str, FloatArray]] = []
    if base.local_means is not None:
        carried = base.local_means @ T.T + shift[None, None, :]
        entries += list(zip(base.local_names, carried, strict=True))
    for i, t in enumerate(tables):
        means = [C[:, first:first + count].mean(axis=1)
                 for (first, count, _), owner in zip(groups, owners, strict=True) if owner == i]
        entries.append((t.name, np.stack(means)))
    if not entries:
        return None, ()
    width = entries[0][1].shape[0]
    kept = [(n, m) for n, m in entries if m.shape[0] == width]
    return np.stack([m for _, m in kept]), tuple(n for n, _ in kept)


def _randomized_svd(
    Y: NDArray[np.float32], k: int, oversample: int, power_iterations: int, seed: int
) -> tuple[FloatArray, FloatArray]:
    """Leading ``k`` left singular vectors (p, k) and values (k,) of ``Y`` (p, m), float32 input."""
    p, m = Y.shape
    ell = min(k + max(oversample, 0), p, m)
    rng = np.random.default_rng(seed)
    Z = Y @ rng.standard_normal((m, ell)).astype(np.float32)
    for _ in range(power_iterations):
        # Re-orthonormalising between products keeps float32 round-off from collapsing the
        # panel onto the top singular vector.
        Z = np.linalg.qr(Z)[0].astype(np.float32)
        W = np.linalg.qr(Y.T @ Z)[0].astype(np.float32)
        Z = Y @ W
    Z64 = np.linalg.qr(Z.astype(np.float64))[0]  # (p, ell) orthonormal basis of the range
    # B = Z^T Y in float64, one column block at a time; only its Gram matrix is needed.
    gram = np.zeros((ell, ell))
    for c0 in range(0, m, 4096):
        B = Z64.T @ Y[:, c0 : c0 + 4096].astype(np.float64)
        gram += B @ B.T
    evals, evecs = np.linalg.eigh(gram)
    order = np.argsort(evals)[::-1][:k]
    S = np.sqrt(np.maximum(evals[order], 0.0))
    U = Z64 @ evecs[:, order]
    # Fix the sign of each component (largest entry positive) so builds are reproducible.
    flip = np.sign(U[np.abs(U).argmax(axis=0), np.arange(U.shape[1])])
    flip[flip == 0] = 1.0
    return U * flip, S


def _names_digest(names: Sequence[str]) -> str:
    return hashlib.sha256("\n".join(names).encode()).hexdigest()[:16]


def leave_one_out(tables: Sequence[BRDFTable], index: int, n_components: int) -> Basis:
    """Basis built from every table except ``tables[index]`` (for honest evaluation).

    Parameters
    ----------
    tables : sequence of BRDFTable
    index : int
        Position of the held-out material (negative indices count from the end).
    n_components : int
    """
    n = len(tables)
    if not -n <= index < n:
        raise BasisError(f"leave-one-out index {index} is outside the {n} training tables")
    idx = index % n
    kept = [t for i, t in enumerate(tables) if i != idx]
    basis = build_basis(kept, n_components)
    return Basis(
        basis.Q, basis.S, basis.f_med, basis.mu, basis.valid, basis.eps, basis.materials,
        {**basis.provenance, "held_out": tables[idx].name},
    )


# ---------------------------------------------------------------------------- default basis
#: How many synthetic materials one shipped measured material counts as in the default basis
#: (chosen by the leave-one-measured-material-out study of ``bench/bench_unseen.py``).
MEASURED_WEIGHT = 1.0
#: The synthetic part is built with this many extra components, so folding the measured
#: tables in (:func:`fold_in`) loses little of it.
_FOLD_EXTRA = 32
#: What a cached default basis holds beyond the arrays every version had; a new entry makes
#: caches written before it build again (2: the folded-in tables' local means).
_DEFAULT_LAYOUT = "local-priors-2"


def _library_tag(asymmetric: bool) -> str:
    """Cache-name part identifying the synthetic library (and its asymmetric families)."""
    from gonio.brdf.materials import library

    tag = library.library_key()[:16]
    return f"{tag}-asym{library.library_key(asymmetric=True)[:8]}" if asymmetric else tag


def synthetic_basis(n_components: int, progress: bool = False, *,
                    asymmetric: bool = False) -> Basis:
    """The basis of the synthetic library alone: shipped, or built once and cached.

    The one gonio ships (:mod:`gonio.brdf.reconstruction.shipped`, K = 96, the default
    basis' base) is used when its fingerprint matches this code; any other K, or a stale
    shipped file, is built and cached as ``<cache>/basis/synthetic-K<K>-<key>.npz``,
    ``<cache>`` and ``<key>`` the library's (:func:`gonio.brdf.materials.library.cache_root`,
    :func:`~gonio.brdf.materials.library.library_key`). With ``asymmetric`` the library's
    families without twofold symmetry are trained on too (never the shipped file; science.md
    7.4), cached as ``synthetic-K<K>-<key>-asym<key>.npz``.
    """
    # the library depends on models; import it only when needed
    from gonio.brdf.materials import library
    from gonio.brdf.reconstruction import shipped

    ready = None if asymmetric else shipped.shipped_basis(n_components)
    if ready is not None:
        return ready

    path = (library.cache_root() / "basis"
            / f"synthetic-K{n_components}-{_library_tag(asymmetric)}.npz")
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass  # a stale or damaged cache entry is rebuilt below
    tables = (library.default_library(progress=progress, asymmetric=True) if asymmetric
              else library.default_library(progress=progress))
    k = min(n_components, sum(t.n_channels * geo.N_PH for t in tables))
    basis = build_basis(tables, k, progress=progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis


def default_basis_path(
    n_components: int | None = None,
    *,
    exclude: Sequence[str] = (),
    measured_weight: float | None = None,
    user_library: bool = True,
    asymmetric: bool = False,
) -> Path:
    """Cache file of :func:`default_basis` for these arguments (it may not exist yet).

    ``<cache>/basis/default-K<K>-<key>.npz``; the key hashes the library, the shipped
    measured data, the user library's tables, the weight and ``exclude``.
    """
    from gonio.brdf.materials import library, measured

    k = DEFAULT_COMPONENTS if n_components is None else int(n_components)
    weight = MEASURED_WEIGHT if measured_weight is None else float(measured_weight)
    key = hashlib.sha256("\n".join([
        _library_tag(asymmetric) if asymmetric else library.library_key(),
        measured.measured_digest(),
        measured.user_library_digest() if user_library else "-", repr(weight),
        ",".join(sorted(exclude)), _DEFAULT_LAYOUT,
    ]).encode()).hexdigest()[:16]
    return library.cache_root() / "basis" / f"default-K{k}-{key}.npz"


def default_basis(
    n_components: int | None = None,
    progress: bool = False,
    *,
    exclude: Sequence[str] = (),
    measured_weight: float | None = None,
    user_library: bool = True,
    asymmetric: bool = False,
) -> Basis:
    """The default basis: synthetic library + shipped measured materials + the user's tables.

    Parameters
    ----------
    n_components : int, optional
        K; :data:`DEFAULT_COMPONENTS` when omitted.
    progress : bool
        Show progress bars while building the library and the basis.
    exclude : sequence of str
        Shipped measured materials to leave out (held-out studies).
    measured_weight : float, optional
        How many synthetic materials each measured or user table counts as; default
        :data:`MEASURED_WEIGHT`. 0 gives the synthetic basis alone.
    user_library : bool
        Include the tables of :func:`gonio.brdf.materials.measured.user_library_dir`
        (``gonio library import``).
    asymmetric : bool
        Train on the library's families without twofold symmetry too (off by default; the
        shipped basis has none; science.md 7.4 measures what they cost).

    Returns
    -------
    Basis
        The synthetic basis (:func:`synthetic_basis`, K + 32 components) with the measured
        tables folded in (:func:`fold_in`), cached as
        ``<cache>/basis/default-K<K>-<key>.npz``; the key covers the library, the shipped
        data, the user tables, the weight and ``exclude``.
    """
    from gonio.brdf.materials import measured

    k = DEFAULT_COMPONENTS if n_components is None else int(n_components)
    weight = MEASURED_WEIGHT if measured_weight is None else float(measured_weight)
    path = default_basis_path(k, exclude=exclude, measured_weight=weight,
                              user_library=user_library, asymmetric=asymmetric)
    key = path.stem.rsplit("-", 1)[-1]
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass  # a stale or damaged cache entry is rebuilt below
    base = synthetic_basis(k + _FOLD_EXTRA, progress=progress, asymmetric=asymmetric)
    extra = measured.measured_tables(exclude) + (measured.user_tables() if user_library else [])
    basis = fold_in(base, extra, weight, min(k, base.K))
    # asymmetric_library: the basis a scan switches to for a specimen without twofold
    # symmetry (it does not lean on local priors, localprior's module notes).
    basis = Basis(basis.Q, basis.S, basis.f_med, basis.mu, basis.valid, basis.eps,
                  basis.materials, {**basis.provenance, "default_key": key,
                                    "asymmetric_library": bool(asymmetric)}, basis.ph_prior,
                  basis.local_means, basis.local_names)
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis
