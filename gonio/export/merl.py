"""The MERL ``.binary`` BRDF layout (Matusik et al. 2003): the writer.

The reader, shared with the library import, is
:func:`gonio.brdf.materials.merl.read_merl_values` (the layout's one owner).

Layout, as the MERL database's published reader expects it:

* three little-endian ``int32``: the dimensions ``90, 90, 180`` (theta_h, theta_d, phi_d);
* then ``3 x 90 x 90 x 180`` little-endian ``float64``: the red block, the green block, the
  blue block, each in C order over ``(i_theta_h, i_theta_d, i_phi_d)``;
* a stored number times the channel's scale (red ``1/1500``, green ``1.15/1500``, blue
  ``1.66/1500``) is the BRDF in 1/sr; negative numbers mark cells below the horizon.

Bins: ``i_theta_d = floor(theta_d / 1 deg)`` and ``i_phi_d = floor(phi_d / 1 deg)`` with
``phi_d`` in ``[0, 180)`` deg (reciprocity); ``theta_h`` is binned non-linearly,
``i_theta_h = floor(90 sqrt(theta_h / 90 deg))``, so bin ``i`` covers
``theta_h in [90 (i/90)^2, 90 ((i+1)/90)^2)`` deg, fine near the specular peak. gonio writes each
bin's value at its centre in index space (``theta_h = 90 ((i + 0.5)/90)^2`` deg,
``theta_d = i + 0.5`` deg, ``phi_d = i + 0.5`` deg).

MERL is isotropic: the writer averages a gonio table over ``phi_h`` first, and says so. The
format has no room for metadata, so :func:`write_merl` writes a sidecar ``<file>.json`` beside
it (:func:`sidecar_path`): the export provenance (:mod:`gonio.export.metadata`) plus
``merl``: the layout, ``azimuthally_averaged: true`` and ``anisotropy_lost``
(:func:`anisotropy_lost`: how far the table was from its azimuthal average).
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.atomicfile import write_atomically
from gonio.brdf.materials.merl import (
    DATA,
    HEADER,
    N_PHI_D,
    N_THETA_D,
    N_THETA_H,
    SCALES,
    SHAPE,
    MerlError,
)
from gonio.brdf.pictures.render import TableLookup
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics as tmetrics
from gonio.brdf.tables.table import BRDFTable
from gonio.export.metadata import TWOFOLD_WARN

#: Stored for bins whose light or view is below the horizon (or that hold no value).
BELOW_HORIZON = -1.0


def bin_centres() -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``theta_h``, ``theta_d``, ``phi_d`` (radians) at which each MERL bin is written."""
    u = (np.arange(N_THETA_H) + 0.5) / N_THETA_H
    theta_h = u * u * (np.pi / 2)
    theta_d = np.deg2rad(np.arange(N_THETA_D) + 0.5)
    phi_d = np.deg2rad(np.arange(N_PHI_D) + 0.5)
    return theta_h, theta_d, phi_d


#: ``anisotropy_lost`` above which the sidecar and the CLI warn that averaging changed the look.
ANISOTROPY_WARN = 0.01


def azimuthal_average(table: BRDFTable) -> BRDFTable:
    """The table averaged over the half vector's azimuth ``ph`` (NaN cells left out)."""
    with warnings.catch_warnings():  # an all-NaN column (an invalid cell) stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        iso = np.nanmean(np.asarray(table.values, dtype=float), axis=1, keepdims=True)
    return BRDFTable.trusted(
        np.ascontiguousarray(np.broadcast_to(iso, table.values.shape)), table.channels,
        table.name,
    )


def anisotropy_lost(table: BRDFTable) -> float:
    """How anisotropic ``table`` is: the cosine-weighted log RMSE
    (:func:`gonio.brdf.tables.metrics.log_rmse`, dimensionless) between the table and its
    azimuthal average, i.e. what the MERL layout cannot hold. 0 for an isotropic table; a
    reconstruction's own error is typically 0.01 to 0.06."""
    return tmetrics.log_rmse(azimuthal_average(table), table)


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The sidecar of a MERL file: ``<file>.json`` (``x.binary`` -> ``x.binary.json``)."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def merl_sidecar(table: BRDFTable, provenance: Mapping[str, Any]) -> dict[str, Any]:
    """The sidecar's content: ``provenance`` plus what the MERL file is and what it lost."""
    lost = anisotropy_lost(table)
    asym = (provenance.get("symmetry") or {}).get("twofold_asymmetry")
    # The glTF and MaterialX principled models are twofold symmetric: for a result that is
    # not, they lose what differs at a half turn too, and only the table and factored keep it.
    keep = ("use the 'table' or 'factored' export to keep it (the result is not twofold "
            f"symmetric, log RMSE {asym:.3f} to its half-turn average, which the glTF and mtlx "
            "principled models cannot show either)"
            if isinstance(asym, int | float) and asym > TWOFOLD_WARN else
            "use the gltf, glb, mtlx or table export to keep it")
    note = (f"the reconstruction is anisotropic (log RMSE {lost:.3f} to its azimuthal "
            "average); this MERL file holds only the azimuthal average, so a brushed or "
            f"woven look is gone: {keep}" if lost > ANISOTROPY_WARN else None)
    out = json.loads(json.dumps(dict(provenance), default=str))
    out["merl"] = {
        "layout": "MERL .binary (Matusik et al. 2003): int32 dims 90 90 180, then float64 R, G, "
                  "B blocks scaled by 1/1500, 1.15/1500, 1.66/1500; -1 below the horizon",
        "azimuthally_averaged": True,
        "anisotropy_lost": lost,
        "anisotropy_lost_meaning": "cosine-weighted log RMSE between the reconstruction and "
                                   "its average over the half vector's azimuth (0 = isotropic)",
    }
    if note:
        out.setdefault("warnings", []).append(note)
    return out


def merl_values(table: BRDFTable) -> NDArray[np.float64]:
    """(3, 90, 90, 180) BRDF in 1/sr on MERL's bins, from a gonio table averaged over ``ph``.

    Cells below the horizon, or with no valid gonio cell around them, hold NaN. Values
    between gonio's 5 degree nodes come from the pictures' lookup
    (:class:`gonio.brdf.pictures.render.TableLookup`: monotone cubic in log along ``th``, so
    MERL's fine bins near the peak keep its shape), clamped at 85 deg in ``th`` and ``td``.

    Raises
    ------
    MerlError
        The table does not have exactly three (R, G, B) channels.
    """
    if table.n_channels != 3:
        raise MerlError(
            f"MERL files hold three channels (R, G, B); table {table.name!r} has "
            f"{table.n_channels} ({', '.join(table.channels)})"
        )
    averaged = azimuthal_average(table)
    th, td, pd = np.meshgrid(*bin_centres(), indexing="ij")
    look = TableLookup(averaged)
    out = look.eval_half_diff(th.ravel(), np.zeros(th.size), td.ravel(), pd.ravel(),
                              empty=np.nan).reshape(*th.shape, -1)  # (90, 90, 180, 3)
    ci, co = geo.cell_cosines(th, td, pd)
    out[(ci <= 0) | (co <= 0)] = np.nan
    return np.moveaxis(out, -1, 0)


def write_merl(table: BRDFTable, path: str | os.PathLike[str],
               provenance: Mapping[str, Any] | None = None) -> Path:
    """Write a table as a MERL ``.binary`` file and, with ``provenance``, its sidecar
    (:func:`merl_sidecar`, at :func:`sidecar_path`); both atomically. Returns the MERL path."""
    vals = merl_values(table)
    stored = np.empty(vals.shape)
    for c, scale in enumerate(SCALES):
        stored[c] = np.where(np.isfinite(vals[c]), vals[c] / scale, BELOW_HORIZON)
    p = write_atomically(path, np.asarray(SHAPE, dtype=HEADER).tobytes()
                         + np.ascontiguousarray(stored, dtype=DATA).tobytes())
    if provenance is not None:
        write_atomically(sidecar_path(p), json.dumps(merl_sidecar(table, provenance), indent=2))
    return p
