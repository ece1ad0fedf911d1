"""Import a lab's own measured BRDFs into the user library (``gonio library import``).

Accepted files
--------------
``.bsdf``
    RGL EPFL tensor files (isotropic RGB), read with :func:`gonio.brdf.materials.rgl.read_rgl`
    (needs the optional mitsuba package; a clear error says how to install it).
``.binary``
    MERL BRDF database files (Matusik et al. 2003), isotropic: a header of three int32
    ``(n_th, n_td, n_pd)`` (90, 90, 180 in the database), then ``3 n_th n_td n_pd`` float64
    values, channel-major (R, G, B), index ``i_pd + n_pd (i_td + n_td i_th)``. The half-angle
    index is non-linear, ``i_th = sqrt(th / (pi / 2)) n_th``; ``i_td = td / (pi / 2) n_td``;
    ``i_pd = pd / pi n_pd`` (``pd`` in ``[0, pi)`` by reciprocity). Values are scaled by
    ``1 / 1500``, ``1.15 / 1500``, ``1.66 / 1500`` per channel to give 1/sr; negative values
    mark unmeasured cells (NaN here, which the basis build treats as the median).
    Stored value ``i`` is a bin (the database's reader floors the index), so it sits at the bin
    centre ``i + 0.5``; grid cells are read by trilinear interpolation in that index space,
    clamped at the first and last centres, over the measured neighbours only (weights
    renormalised); a cell with no measured neighbour is NaN.
``.npz``
    gonio table files (:meth:`BRDFTable.save`), validated and copied.

Every table is written as a gonio table ``<name>.npz`` in
:func:`gonio.brdf.materials.measured.user_library_dir`;
:func:`gonio.brdf.reconstruction.basis.default_basis` trains on every table there from then on.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.ndimage import map_coordinates

from gonio.brdf.advice import AdvisedError
from gonio.brdf.materials.measured import CHANNELS, PREFIX, user_library_dir
from gonio.brdf.materials.merl import SCALES, MerlError, read_merl_values
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, TableError

#: MERL's per-channel scale factors (R, G, B) to 1/sr.
MERL_SCALE = SCALES


class TableImportError(AdvisedError):
    """A file cannot be imported; the message says why and what to do."""


def read_merl_table(path: str | os.PathLike[str], name: str | None = None) -> BRDFTable:
    """Tabulate a MERL ``.binary`` file on gonio's grid (layout in the module notes).

    Returns
    -------
    BRDFTable
        ``(3, 72, 18, 18, 36)`` float32, 1/sr, every ``ph`` slice the same (isotropic).
    """
    p = Path(path)
    try:
        values = read_merl_values(p, shape=None)
    except MerlError as exc:
        raise TableImportError(str(exc)) from None
    n_th, n_td, n_pd = values.shape[1:]
    dims = np.asarray(values.shape[1:])
    th, td, pd = geo.grid_angles()
    mask = geo.valid_mask()
    coords = np.stack([
        np.sqrt(np.clip(th[mask] / (np.pi / 2), 0, 1)) * n_th,
        td[mask] / (np.pi / 2) * n_td,
        np.mod(pd[mask], np.pi) / np.pi * n_pd,
    ]) - 0.5  # value i is the bin [i, i + 1), i.e. its centre i + 0.5
    # Clamped at the first and last bin centres.
    for axis, n in enumerate((n_th, n_td, n_pd)):
        coords[axis] = np.clip(coords[axis], 0, n - 1)
    out = np.full((3, *geo.SLICE_SHAPE), np.nan, dtype=np.float32)
    for c in range(3):
        vals = values[c]
        measured = np.isfinite(vals)
        # Unmeasured bins (negative) get weight 0 and the measured neighbours are
        # renormalised, so a cell next to the horizon still reads its measured neighbours.
        w = map_coordinates(measured.astype(float), coords, order=1, mode="nearest")
        v = map_coordinates(np.where(measured, vals, 0.0), coords, order=1, mode="nearest")
        with np.errstate(invalid="ignore", divide="ignore"):
            out[c][mask] = np.where(w > 1e-6, v / w, np.nan)
    if not np.isfinite(out[:, mask]).any():
        raise TableImportError(f"{p}: holds no measured (non-negative) value")
    full = np.ascontiguousarray(np.broadcast_to(out[:, None], (3, *geo.TABLE_SHAPE)))
    prov = {"source": "merl", "file": p.name, "isotropic": True, "dims": dims.tolist()}
    return BRDFTable(full, CHANNELS, name or p.stem, None, prov)


def read_any(path: str | os.PathLike[str], name: str | None = None) -> BRDFTable:
    """Read an RGL ``.bsdf``, MERL ``.binary`` or gonio ``.npz`` file as a table."""
    p = Path(path)
    if not p.is_file():
        raise TableImportError(f"{p}: no such file")
    suffix = p.suffix.lower()
    if suffix == ".bsdf":
        from gonio.brdf.materials.rgl import read_rgl

        t = read_rgl(p, name)  # RGLError (a ValueError) says how to get mitsuba
    elif suffix == ".binary":
        t = read_merl_table(p, name)
    elif suffix == ".npz":
        try:
            t = BRDFTable.load(p)
        except TableError as exc:
            raise TableImportError(f"{p}: not a gonio table ({exc})") from None
        if name:
            t = BRDFTable(t.values, t.channels, name, t.wavelengths_nm, t.provenance)
    else:
        raise TableImportError(
            f"{p}: unknown kind of file {suffix or '(no suffix)'!r}; gonio imports RGL .bsdf, "
            "MERL .binary and gonio table .npz files"
        )
    if tuple(t.channels) != CHANNELS:
        raise TableImportError(
            f"{p}: table has channels {t.channels}; the library holds {CHANNELS} tables"
        )
    return t


def import_files(
    paths: list[str | os.PathLike[str]], replace: bool = False
) -> list[Path]:
    """Convert files into the user library; returns the written table files.

    Every file is read and checked before anything is written, so one bad file leaves the
    library as it was.

    Raises
    ------
    TableImportError
        A file cannot be read, two files give the same name, a name is taken by the shipped
        measured materials, or (without ``replace``) a table of that name is already imported.
    """
    tables = [read_any(p) for p in paths]
    names = [_safe_name(t.name) for t in tables]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise TableImportError(f"several files would be imported as {dupes}; rename one")
    folder = user_library_dir()
    for n in names:
        if n.startswith(PREFIX):
            raise TableImportError(f"names starting with {PREFIX!r} are the shipped materials'; "
                               f"rename {n!r}")
        if (folder / f"{n}.npz").exists() and not replace:
            raise TableImportError(
                f"{n!r} is already in the library ({folder / (n + '.npz')})",
                "pass {replace} to overwrite it", words={"replace": "replace=True"},
            )
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TableImportError(
            f"cannot create the library folder {folder} ({exc.strerror}); set "
            "GONIO_LIBRARY_DIR to a writable folder"
        ) from None
    out = []
    for t, n in zip(tables, names, strict=True):
        t = BRDFTable(t.values, t.channels, n, t.wavelengths_nm, t.provenance)
        tmp = folder / f".{n}.{os.getpid()}.part.npz"
        t.save(tmp)
        final = folder / f"{n}.npz"
        os.replace(tmp, final)
        out.append(final)
    return out


def _safe_name(name: str) -> str:
    """A file-system-safe material name (letters, digits, ``-_.``)."""
    safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name).strip("._")
    if not safe:
        raise TableImportError(f"material name {name!r} has no usable character; pass another")
    return safe
