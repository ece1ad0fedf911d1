"""The linear basis of isotropic BRDF slices (Vávra & Filip 2016, Sec. 3.1; MATH.md section 4).

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
``Q``              (N_ROWS, K) float64     ``U S``; rows of invalid cells are 0
``S``              (K,) float64            singular values
``f_med``          (N_ROWS,) float64       per-row median of the training columns, 1/sr
                                           (0 at invalid cells)
``mu``             (N_ROWS,) float64       per-row mean of the remapped columns (0 at invalid)
``valid``          (N_ROWS,) bool          valid-cell mask the basis was built with
``eps``            () float                remap constant
``materials``      (M,) str                names of the training materials
``provenance``     () str                  JSON object: how the basis was built
``grid_deg``       (4,) float              grid step and counts check: ``(step, n_th, n_td,
                                           n_pd)``; a basis from another grid is refused
=================  ======================  ==================================================
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

from gonio.brdf import geometry as geo
from gonio.brdf.npzfile import read_npz, write_npz
from gonio.brdf.table import BRDFTable

FloatArray = NDArray[np.float64]

FORMAT_NAME = "gonio-brdf-basis"
FORMAT_VERSION = 1
EPS = 1e-3
#: Components kept by :func:`default_basis` when none are asked for; chosen from the quality
#: table of ``bench/bench_quality.py`` (see ``docs/science.md``).
DEFAULT_COMPONENTS = 64
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
    """

    Q: FloatArray
    S: FloatArray
    f_med: FloatArray
    mu: FloatArray
    valid: NDArray[np.bool_]
    eps: float = EPS
    materials: tuple[str, ...] = ()
    provenance: Mapping[str, Any] = field(default_factory=dict)

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

    def truncated(self, k: int) -> Basis:
        """The first ``k`` components (1 <= k <= K)."""
        if not 1 <= k <= self.K:
            raise BasisError(f"cannot keep {k} components of a basis with K = {self.K}")
        if k == self.K:
            return self
        return Basis(
            self.Q[:, :k], self.S[:k], self.f_med, self.mu, self.valid, self.eps,
            self.materials, {**self.provenance, "truncated_from": self.K},
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
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the basis as ``.npz`` (layout in the module docstring); returns the path."""
        return write_npz(
            path, FORMAT_NAME, FORMAT_VERSION, self.provenance,
            Q=self.Q, S=self.S, f_med=self.f_med, mu=self.mu, valid=self.valid,
            eps=np.array(self.eps), materials=np.array(self.materials, dtype=str),
            grid_deg=_GRID_SIGNATURE,
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
                prov,
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
    """Learn the basis from training tables (MATH 4) with a randomized SVD.

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
    }
    return Basis(Q, S, f_full, mu_full, valid, eps, tuple(names), prov)


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
def default_basis(n_components: int | None = None, progress: bool = False) -> Basis:
    """The basis of the default synthetic library, built once and cached.

    Parameters
    ----------
    n_components : int, optional
        K; :data:`DEFAULT_COMPONENTS` when omitted.
    progress : bool
        Show progress bars while building the library and the basis.

    Returns
    -------
    Basis
        Loaded from ``<cache>/basis/default-K<K>-<key>.npz`` when present. ``<cache>`` and
        ``<key>`` are the library's (:func:`gonio.brdf.library.cache_root`,
        :func:`~gonio.brdf.library.library_key`), so a changed library recipe gives a new file.
    """
    from gonio.brdf import library  # the library depends on models; import it only when needed

    k = DEFAULT_COMPONENTS if n_components is None else int(n_components)
    path = library.cache_root() / "basis" / f"default-K{k}-{library.library_key()[:16]}.npz"
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass  # a stale or damaged cache entry is rebuilt below
    basis = build_basis(library.default_library(progress=progress), k, progress=progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis
