"""The tabulated anisotropic BRDF on gonio's 5 degree half/difference grid.

File format (``.npz``, readable with ``numpy.load`` alone; see ``docs/file-formats.md``):

=================  =================================  ==========================================
key                shape / dtype                      meaning
=================  =================================  ==========================================
``format``         () str                             ``"gonio-brdf-table"``
``version``        () int                             format version, currently 1
``values``         (C, 72, 18, 18, 36) float32/64     ``f[c, i_ph, i_th, i_td, i_pd]`` in 1/sr,
                                                      NaN at invalid cells
``channels``       (C,) str                           channel names (``"R"``, ``"G"``, ...)
``wavelengths_nm`` (C,) float                         NaN where a channel has no wavelength
``name``           () str                             material name
``provenance``     () str                             JSON object: where the values came from
=================  =================================  ==========================================
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.npzfile import read_npz, write_npz

FORMAT_NAME = "gonio-brdf-table"
FORMAT_VERSION = 1

#: (18, 18, 36) valid-cell mask, computed once: every table construction needs it and the
#: trigonometry behind :func:`geometry.valid_mask` is a noticeable share of a reconstruction.
VALID_MASK = geo.valid_mask()
VALID_MASK.setflags(write=False)
#: Flat indices (into one slice's 11,664 rows) of the valid cells, of the invalid ones, and of
#: the valid cells with ``th = 0`` (where every slice must agree: ``Qs`` of V&F's Eq. 5).
VALID_ROWS = np.flatnonzero(VALID_MASK.ravel())
INVALID_ROWS = np.flatnonzero(~VALID_MASK.ravel())
TH0_ROWS = VALID_ROWS[VALID_ROWS < geo.N_TD * geo.N_PD]
for _rows in (VALID_ROWS, INVALID_ROWS, TH0_ROWS):
    _rows.setflags(write=False)
_INVALID_MASK = ~VALID_MASK
_INVALID_MASK.setflags(write=False)


class TableError(ValueError):
    """A BRDF table or table file is malformed; the message says what and how to fix it."""


@dataclass(frozen=True)
class BRDFTable:
    """Anisotropic BRDF tabulated on the grid of :mod:`gonio.brdf.tables.geometry`.

    Parameters
    ----------
    values : (C, 72, 18, 18, 36) array, 1/sr
        ``f[c, i_ph, i_th, i_td, i_pd]``; invalid cells (see :func:`geometry.valid_mask`) are
        set to NaN on construction.
    channels : sequence of str, length C
    name : str
    wavelengths_nm : sequence of float, length C, optional
    provenance : mapping, optional
        JSON-serialisable description of the origin (model parameters, source file, ...).
    """

    values: NDArray[np.floating[Any]]
    channels: tuple[str, ...]
    name: str = "unnamed"
    wavelengths_nm: tuple[float, ...] | None = None
    provenance: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.asarray(self.values)
        if v.dtype not in (np.float32, np.float64):
            v = v.astype(np.float64)
        channels = self._check_shapes(v, self.channels, self.name, self.wavelengths_nm)
        # One private copy (the caller's array is neither changed nor frozen), NaN written at
        # the invalid cells in place; the checks below then run on the whole array, where
        # the invalid cells are NaN and cannot trip them.
        v = np.array(v, copy=True)
        v[:, :, _INVALID_MASK] = np.nan
        if not np.isfinite(v).any():
            raise TableError(f"table {self.name!r} has no finite value at any valid cell")
        if np.isinf(v).any():
            raise TableError(f"table {self.name!r} holds infinite values; replace them first")
        if (v < 0).any():
            raise TableError(
                f"table {self.name!r} holds negative BRDF values (min {np.nanmin(v):.3g}); "
                "clamp them to 0 before building the table"
            )
        self._freeze(v, channels)

    @staticmethod
    def _check_shapes(
        v: NDArray[np.floating[Any]],
        channels_in: Sequence[str],
        name: str,
        wavelengths_nm: Sequence[float] | None,
    ) -> tuple[str, ...]:
        """Shape, channel and wavelength-count checks; returns the channel names as strings."""
        if v.ndim != 5 or v.shape[1:] != geo.TABLE_SHAPE:
            raise TableError(
                f"table {name!r}: values have shape {v.shape}, expected "
                f"(C, {', '.join(map(str, geo.TABLE_SHAPE))}) = (channels, ph, th, td, pd) "
                "on the 5 degree grid"
            )
        channels = tuple(str(c) for c in channels_in)
        if len(channels) != v.shape[0]:
            raise TableError(
                f"table {name!r}: {len(channels)} channel names for {v.shape[0]} channels"
            )
        if wavelengths_nm is not None and len(wavelengths_nm) != v.shape[0]:
            raise TableError(
                f"table {name!r}: {len(wavelengths_nm)} wavelengths for {v.shape[0]} channels"
            )
        return channels

    def _freeze(self, v: NDArray[np.floating[Any]], channels: tuple[str, ...]) -> None:
        v.setflags(write=False)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "channels", channels)
        if self.wavelengths_nm is not None:
            object.__setattr__(self, "wavelengths_nm", tuple(float(w) for w in self.wavelengths_nm))
        object.__setattr__(self, "provenance", dict(self.provenance))

    @classmethod
    def trusted(
        cls,
        values: NDArray[np.floating[Any]],
        channels: Sequence[str],
        name: str = "unnamed",
        wavelengths_nm: Sequence[float] | None = None,
        provenance: Mapping[str, Any] | None = None,
    ) -> BRDFTable:
        """Wrap an array gonio itself produced, without the per-value validation pass.

        For code that builds tables from already valid data (a reconstruction, a rotation of
        a table): the full validation reads every one of the ``C x 933,120`` values several
        times, which costs more than the reconstruction's own solve. Only the cheap shape and
        channel checks run; user data must go through the normal constructor.

        Parameters
        ----------
        values : (C, 72, 18, 18, 36) float32 or float64 array, 1/sr
            Must already hold NaN at every invalid cell and finite non-negative values or NaN
            elsewhere. Taken over without a copy and made read-only: the caller must not keep
            a writable reference to it.
        channels, name, wavelengths_nm, provenance
            As for :class:`BRDFTable`.
        """
        if values.dtype not in (np.float32, np.float64):
            raise TableError(
                f"table {name!r}: trusted values must be float32 or float64, not {values.dtype}"
            )
        chans = cls._check_shapes(values, channels, name, wavelengths_nm)
        self = object.__new__(cls)
        object.__setattr__(self, "name", name)
        object.__setattr__(
            self, "wavelengths_nm", None if wavelengths_nm is None else tuple(wavelengths_nm)
        )
        object.__setattr__(self, "provenance", dict(provenance or {}))
        self._freeze(values, chans)
        return self

    # ------------------------------------------------------------------ shape helpers
    @property
    def n_channels(self) -> int:
        return int(self.values.shape[0])

    def columns(self) -> NDArray[np.floating[Any]]:
        """Slices as basis columns: (C * 72, N_ROWS), rows flattened over ``(th, td, pd)``."""
        return self.values.reshape(self.n_channels * geo.N_PH, geo.N_ROWS)

    def rotated(self, angle: float) -> BRDFTable:
        """The same material turned by ``angle`` radians about the normal.

        Only whole multiples of the 5 degree step are exact (a roll of the ``ph`` axis);
        other angles interpolate linearly along ``ph``.
        """
        steps = angle / geo.STEP
        k = math.floor(steps)
        t = steps - k
        a = np.roll(self.values, k, axis=1)
        out = a if t < 1e-12 else (1 - t) * a + t * np.roll(a, 1, axis=1)
        # Rolling along ph keeps the NaN pattern (it does not depend on ph) and a convex blend
        # of finite non-negative values stays so: the result needs no re-validation.
        return BRDFTable.trusted(
            np.ascontiguousarray(out), self.channels, self.name, self.wavelengths_nm,
            {**self.provenance, "rotated_deg": float(np.rad2deg(angle))},
        )

    # ------------------------------------------------------------------ lookup
    def eval_half_diff(
        self, th: ArrayLike, ph: ArrayLike, td: ArrayLike, pd: ArrayLike
    ) -> NDArray[np.float64]:
        """Multilinear lookup at half/difference angles.

        Periodic in ``ph`` (2 pi) and ``pd`` (pi), clamped in ``th`` and ``td`` (math.md 3).
        Invalid (NaN) neighbours are left out and the remaining weights renormalised, so values
        near the horizon come from the valid side only; a point with no valid neighbour is NaN.

        Parameters
        ----------
        th, ph, td, pd : array_like, radians, broadcastable to shape S

        Returns
        -------
        (*S, C) array, 1/sr
        """
        th_, ph_, td_, pd_ = np.broadcast_arrays(
            *(np.asarray(a, dtype=float) for a in (th, ph, td, pd))
        )
        shape = th_.shape
        coords = []
        for a, n, periodic, period in (
            (ph_, geo.N_PH, True, 2 * np.pi),
            (th_, geo.N_TH, False, 0.0),
            (td_, geo.N_TD, False, 0.0),
            (pd_, geo.N_PD, True, np.pi),
        ):
            x = a.ravel()
            if periodic:
                u = np.mod(x, period) / geo.STEP
                i0 = np.floor(u).astype(np.intp)
                t = u - i0
                coords.append((i0 % n, (i0 + 1) % n, t))
            else:
                u = np.clip(x / geo.STEP, 0.0, n - 1)
                i0 = np.minimum(np.floor(u).astype(np.intp), n - 2)
                t = u - i0
                coords.append((i0, i0 + 1, t))
        vals = self.values
        acc = np.zeros((x.size, self.n_channels))
        wsum = np.zeros(x.size)
        for idx, w in geo.lattice_corners(coords):
            v = vals[:, idx[0], idx[1], idx[2], idx[3]].T  # (N, C)
            ok = np.isfinite(v).all(axis=1) & (w > 0)
            acc[ok] += w[ok, None] * v[ok]
            wsum[ok] += w[ok]
        with np.errstate(invalid="ignore", divide="ignore"):
            out = acc / wsum[:, None]
        out[wsum <= 1e-12] = np.nan
        return out.reshape(*shape, self.n_channels)

    def eval(self, wi: ArrayLike, wo: ArrayLike) -> NDArray[np.float64]:
        """BRDF at direction pairs in the specimen frame.

        Parameters
        ----------
        wi, wo : (..., 3) array_like, unit vectors pointing away from the surface

        Returns
        -------
        (..., C) array, 1/sr; 0 where either direction is below the horizon
        """
        i = np.asarray(wi, dtype=float)
        o = np.asarray(wo, dtype=float)
        out = self.eval_half_diff(*geo.directions_to_half_diff(i, o))
        below = (i[..., 2] <= 0) | (o[..., 2] <= 0)
        out[below] = 0.0
        return out

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the table as ``.npz`` (layout in the module docstring); returns the path."""
        wl = (
            np.array(self.wavelengths_nm, dtype=float)
            if self.wavelengths_nm is not None
            else np.full(self.n_channels, np.nan)
        )
        return write_npz(
            path, FORMAT_NAME, FORMAT_VERSION, self.provenance,
            values=np.asarray(self.values), channels=np.array(self.channels),
            wavelengths_nm=wl, name=np.array(self.name),
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> BRDFTable:
        """Read a table written by :meth:`save`; clear :class:`TableError` on any problem."""
        data, prov = read_npz(
            path, format_name=FORMAT_NAME, version=FORMAT_VERSION,
            required=("values", "channels", "name"), error=TableError, kind="table",
        )
        wl = data.get("wavelengths_nm")
        wavelengths = None if wl is None or np.isnan(wl).all() else tuple(wl.tolist())
        try:
            return cls(
                data["values"], tuple(data["channels"].tolist()), str(data["name"]),
                wavelengths, prov,
            )
        except TableError as exc:
            raise TableError(f"{Path(path)}: {exc}") from None

def from_function(
    fn: Any,
    channels: Sequence[str],
    name: str,
    provenance: Mapping[str, Any] | None = None,
    dtype: type = np.float64,
) -> BRDFTable:
    """Tabulate ``fn(wi, wo) -> (..., C)`` at every grid cell (cell centres).

    Parameters
    ----------
    fn : callable
        Maps (N, 3) light and view unit vectors (specimen frame) to (N, C) BRDF values in 1/sr.
    channels : sequence of str
    name : str
    provenance : mapping, optional
    dtype : numpy float type of the stored values
    """
    th, td, pd = geo.grid_angles()
    mask = VALID_MASK
    out: NDArray[np.floating[Any]] = np.full(
        (len(channels), *geo.TABLE_SHAPE), np.nan, dtype=dtype
    )
    for k, ph in enumerate(geo.PH_GRID):
        wi, wo = geo.half_diff_to_directions(th[mask], ph, td[mask], pd[mask])
        vals = np.asarray(fn(wi, wo), dtype=float)
        out[:, k][:, mask] = np.maximum(vals, 0.0).T
    return BRDFTable(out, tuple(channels), name, None, dict(provenance or {}))
