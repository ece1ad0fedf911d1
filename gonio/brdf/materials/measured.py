"""Measured materials shipped with gonio, and the user's own library folder.

Shipped: eleven isotropic materials of the RGL EPFL material database (Dupuy & Jakob 2018,
"An Adaptive Parameterization for Efficient Material Acquisition and Rendering", ACM TOG
37(6); data licensed CC0), evaluated once on gonio's grid with Mitsuba 3 by
``bench/make_measured_data.py`` and stored in ``gonio/brdf/materials/data/measured.npz`` (one ``ph``
slice per material: they are isotropic). Users need no Mitsuba to train on them.

User library: ``gonio library import FILE...`` converts a lab's own tables (RGL ``.bsdf``,
MERL ``.binary``, gonio ``.npz``) into gonio table files in :func:`user_library_dir`;
:func:`gonio.brdf.reconstruction.basis.default_basis` trains on every table found there.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import platformdirs
from numpy.typing import NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, TableError

DATA_FILE = Path(__file__).resolve().parent / "data" / "measured.npz"
CHANNELS: tuple[str, ...] = ("R", "G", "B")
#: Prefix of the shipped tables' names (keeps them apart from synthetic and user names).
PREFIX = "rgl-"
CREDIT = (
    "RGL EPFL material database (Dupuy & Jakob 2018, ACM TOG 37(6)), CC0; "
    "https://rgl.epfl.ch/materials"
)


class MeasuredDataError(ValueError):
    """The shipped measured data or the user library folder cannot be read."""


@functools.cache
def _raw() -> tuple[tuple[str, ...], tuple[str, ...], NDArray[np.float32]]:
    try:
        with np.load(DATA_FILE, allow_pickle=False) as z:
            names = tuple(PREFIX + str(n) for n in z["names"])
            descs = tuple(str(d) for d in z["descriptions"])
            values = np.asarray(z["values"], dtype=np.float32)
    except (OSError, KeyError, ValueError) as exc:
        raise MeasuredDataError(
            f"the shipped measured tables {DATA_FILE} cannot be read ({exc}); reinstall gonio"
        ) from None
    n_valid = int(geo.valid_mask().sum())
    if values.shape != (len(names), len(CHANNELS), n_valid):
        raise MeasuredDataError(f"{DATA_FILE} holds values of shape {values.shape}; reinstall")
    values.setflags(write=False)
    return names, descs, values


def measured_names() -> tuple[str, ...]:
    """Names of the shipped measured materials (``rgl-<material>``)."""
    return _raw()[0]


def measured_tables(exclude: Iterable[str] = ()) -> list[BRDFTable]:
    """The shipped measured materials as tables (isotropic: every ``ph`` slice equal).

    Parameters
    ----------
    exclude : iterable of str
        Names to leave out (with or without the ``rgl-`` prefix), for held-out studies.

    Returns
    -------
    list of BRDFTable
        ``(3, 72, 18, 18, 36)`` float32, 1/sr, NaN at invalid cells.
    """
    names, descs, values = _raw()
    drop = {e if e.startswith(PREFIX) else PREFIX + e for e in exclude}
    mask = geo.valid_mask()
    out = []
    for name, desc, v in zip(names, descs, values, strict=True):
        if name in drop:
            continue
        slice_ = np.full((len(CHANNELS), *geo.SLICE_SHAPE), np.nan, dtype=np.float32)
        slice_[:, mask] = v
        full = np.ascontiguousarray(np.broadcast_to(slice_[:, None], (3, *geo.TABLE_SHAPE)))
        prov = {"source": "rgl", "description": desc, "isotropic": True, "credit": CREDIT}
        out.append(BRDFTable.trusted(full, CHANNELS, name, None, prov))
    return out


def measured_digest() -> str:
    """Content hash of the shipped measured data (part of cached bases' keys)."""
    return hashlib.sha256(DATA_FILE.read_bytes()).hexdigest()


# ---------------------------------------------------------------------------- user library
#: The user library's own folder, when set.
LIBRARY_ENV = "GONIO_LIBRARY_DIR"
#: gonio's user data folder (the same variable as ``gonio.paths.DATA_ENV``; ``gonio.brdf``
#: imports nothing else from gonio, so the name is repeated and a test keeps the two equal).
DATA_ENV = "GONIO_DATA_DIR"


def user_library_dir() -> Path:
    """Folder of the user's imported tables: ``$GONIO_LIBRARY_DIR``, else ``library/`` in
    gonio's user data folder (``$GONIO_DATA_DIR``, else the platform's), where the scans'
    data directories also live: a lab that moves its data with ``GONIO_DATA_DIR`` moves its
    library with it."""
    env = os.environ.get(LIBRARY_ENV)
    if env:
        return Path(env)
    data = os.environ.get(DATA_ENV)
    return (Path(data) if data else Path(platformdirs.user_data_dir("gonio"))) / "library"


def user_table_files() -> list[Path]:
    """The ``.npz`` tables in :func:`user_library_dir` (sorted; empty when there is none)."""
    d = user_library_dir()
    return sorted(d.glob("*.npz")) if d.is_dir() else []


def user_table_provenance(name: str) -> dict[str, Any] | None:
    """The provenance stored in the user library's table ``name`` (``<name>.npz`` in
    :func:`user_library_dir`, as ``gonio library import`` names it), read without its values;
    None when there is no such table or it cannot be read. A table exported from a gonio
    result (``gonio export --format table``) names its ``specimen`` and ``job_id`` there."""
    path = user_library_dir() / f"{name}.npz"
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            text = str(z["provenance"]) if "provenance" in z.files else "{}"
        prov = json.loads(text)
    except Exception:  # zip, npy and JSON errors come in many types: nothing to say then
        return None
    return {**prov, "file": str(path)} if isinstance(prov, dict) else None


def user_tables() -> list[BRDFTable]:
    """Every table of the user library folder, checked to have the library's channels."""
    out = []
    for f in user_table_files():
        try:
            t = BRDFTable.load(f)
        except TableError as exc:
            raise MeasuredDataError(
                f"{f}: {exc}; remove or re-import it (gonio library import)"
            ) from None
        if tuple(t.channels) != CHANNELS:
            raise MeasuredDataError(
                f"{f}: table has channels {t.channels}, the library uses {CHANNELS}; remove it"
            )
        out.append(t)
    return out


def user_library_digest() -> str:
    """Hash of the user library's files (names and bytes); changes when a table is added."""
    h = hashlib.sha256()
    for f in user_table_files():
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()
