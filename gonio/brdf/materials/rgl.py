"""Read isotropic measured materials of the RGL database (``.bsdf`` tensor files) as tables.

The files of Dupuy & Jakob 2018 store each material as warped 2D tables per incidence angle
(a "tensor_file" container); evaluating a value needs the inverse of the stored warps. gonio
does not re-implement them: it evaluates the file with Mitsuba 3's ``measured`` plugin
(optional dependency, ``pip install 'gonio[rgl]'``), variant ``scalar_rgb``. Mitsuba trusts
the file and crashes the interpreter on a truncated one, so :func:`read_tensor_index` checks the
container's structure first and every problem surfaces as :class:`RGLError`.

Mitsuba returns ``f(wi, wo) cos(theta_o)``; the cosine is divided out here so the table holds
the BRDF in 1/sr. The RGL data are isotropic, so one ``ph`` slice is evaluated and copied to
all 72.

Grazing angles: the measurements cover elevations up to about 80-85 degrees, and the warped
interpolation near the horizon is noisy. Values there can come back negative (clamped to 0
here) or spuriously large once divided by a small ``cos(theta_o)``. The counts of clamped and
non-finite values are recorded in the table's provenance; treat cells with either elevation
above ~80 degrees as unreliable when comparing with real data.

Reciprocity: gonio's tables hold ``pd`` over half a turn, ``pd + 180 deg`` being the same pair
with light and view exchanged (docs/math.md 2). The files, evaluated by mitsuba, are not
reciprocal: the table holds the value with the file's incident direction as the light, and a
rendering of it shows ``f(v, l)`` where the true ``f(l, v)`` differs. How far apart they are is
recorded in the provenance (``reciprocity``, :func:`reciprocity_of`); on the eleven shipped
materials the median of ``|ln(f(l, v) / f(v, l))|`` is 0.015-0.28 and its 90th percentile
0.36-2.6 over the grid, 0.010-0.22 and 0.07-1.9 with light and view within 80 degrees of the
normal (grazing cells carry much of it). It is about half of the rendered difference between
the table and the file (docs/science.md 7.0.1).
"""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, TableError

MAGIC = b"tensor_file"
CHANNELS: tuple[str, ...] = ("R", "G", "B")
_INSTALL_HINT = "pip install 'gonio[rgl]'"


class RGLError(TableError):
    """An RGL file cannot be read; the message says why and what to do."""


# Element sizes of the tensor_file type codes (Mitsuba's Struct::Type numbering).
_TYPE_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 8, 8: 8, 9: 2, 10: 4, 11: 8}
#: Fields the ``measured`` plugin reads (plus ``rgb`` or ``spectra``).
REQUIRED_FIELDS = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "jacobian")


def read_tensor_index(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """Check a tensor_file's structure and list its fields, without Mitsuba.

    Mitsuba trusts the file and crashes the whole process on a truncated or damaged one, so
    gonio walks the header itself first: magic ``tensor_file\\0``, version (2 bytes), field
    count (u32), then per field its name (u16 length + bytes), ndim (u16), type code (u8),
    data offset (u64) and shape (ndim x u64), all little-endian; each field's data must lie
    inside the file.

    Returns
    -------
    dict
        ``{field: {"shape": tuple, "type": int, "offset": int}}``; the ``description`` field
        text, when present, under ``"description"`` -> ``"text"``.

    Raises
    ------
    RGLError
        The file is missing, unreadable, not a tensor file, truncated or lacks a field the
        ``measured`` plugin needs.
    """
    p = Path(path)
    if not p.exists():
        raise RGLError(f"{p}: no such RGL .bsdf file")
    if not p.is_file():
        raise RGLError(f"{p}: is not a file; give the path of an RGL .bsdf file")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise RGLError(f"{p}: cannot be read ({exc.strerror})") from None
    if not data.startswith(MAGIC):
        raise RGLError(
            f"{p}: not an RGL tensor_file (first bytes {data[:len(MAGIC)]!r}, expected "
            f"{MAGIC!r}); download the material's .bsdf file from the RGL material database"
        )
    damaged = f"{p}: damaged or truncated tensor_file"
    pos = len(MAGIC) + 1 + 2  # magic, its NUL, version

    def take(fmt: str) -> tuple[Any, ...]:
        nonlocal pos
        size = struct.calcsize(fmt)
        if pos + size > len(data):
            raise RGLError(f"{damaged} (header ends early at byte {pos})")
        out = struct.unpack_from(fmt, data, pos)
        pos += size
        return out

    (count,) = take("<I")
    if count > 1000:
        raise RGLError(f"{damaged} (claims {count} fields)")
    fields: dict[str, dict[str, Any]] = {}
    for _ in range(count):
        (name_len,) = take("<H")
        (raw_name,) = take(f"<{name_len}s")
        ndim, code, offset = take("<HBQ")
        shape = take(f"<{ndim}Q")
        name = raw_name.decode("utf-8", errors="replace")
        if code not in _TYPE_SIZES:
            raise RGLError(f"{damaged} (field {name!r} has unknown type code {code})")
        nbytes = int(np.prod(shape, dtype=np.uint64)) * _TYPE_SIZES[code]
        if offset + nbytes > len(data):
            raise RGLError(
                f"{damaged} (field {name!r} needs bytes {offset}-{offset + nbytes}, the file "
                f"has {len(data)}); download it again"
            )
        fields[name] = {"shape": tuple(int(v) for v in shape), "type": code, "offset": offset}
        if name == "description" and code in (1, 2):
            fields[name]["text"] = data[offset : offset + nbytes].decode("utf-8", "replace")
    missing = [f for f in REQUIRED_FIELDS if f not in fields]
    if "rgb" not in fields and "spectra" not in fields:
        missing.append("rgb")
    if missing:
        raise RGLError(
            f"{p}: tensor_file lacks the fields {missing} of a measured RGL BRDF; is it an "
            "RGL material file?"
        )
    return fields


def _mitsuba() -> Any:
    """The mitsuba module set to the ``scalar_rgb`` variant, or a clear error."""
    try:
        import mitsuba as mi
    except ImportError:
        raise RGLError(
            f"reading RGL .bsdf files needs the optional mitsuba package: {_INSTALL_HINT}"
        ) from None
    if "scalar_rgb" not in mi.variants():
        raise RGLError(
            f"this mitsuba build lacks the 'scalar_rgb' variant (has {mi.variants()}); "
            f"install the PyPI wheel: {_INSTALL_HINT}"
        )
    # The llvm_* variants crash on some LLVM installs; scalar_rgb is slow-ish but dependable.
    mi.set_variant("scalar_rgb")
    return mi


#: Elevation (degrees) above which the files' values are unreliable (module docstring): the
#: reciprocity record also gives its statistics over the pairs with both directions below it.
STEEP_LIMIT_DEG = 80.0


def reciprocity_of(forward: np.ndarray, exchanged: np.ndarray,
                   steep: np.ndarray | None = None) -> dict[str, Any]:
    """How far a BRDF is from reciprocal, for a table's provenance.

    Parameters
    ----------
    forward, exchanged : (N, C) arrays, 1/sr
        The BRDF at N direction pairs ``(l, v)`` and at the same pairs with light and view
        exchanged, ``(v, l)``.
    steep : (N,) bool, optional
        Pairs whose light and view are both within :data:`STEEP_LIMIT_DEG` of the normal.

    Returns
    -------
    dict
        ``median_abs_log_ratio`` and ``p90_abs_log_ratio`` of ``|ln(sum_c f(l, v) /
        sum_c f(v, l))|`` over the pairs where both sums are positive (None when there is
        none), ``pairs`` (how many), the same two over the ``steep`` pairs
        (``..._below_80deg``, when given), and ``meaning``.
    """
    a, b = np.asarray(forward).sum(axis=1), np.asarray(exchanged).sum(axis=1)
    ok = (a > 0) & (b > 0) & np.isfinite(a) & np.isfinite(b)
    ratio = np.abs(np.log(np.where(ok, a, 1.0) / np.where(ok, b, 1.0)))

    def stats(keep: np.ndarray) -> tuple[float | None, float | None]:
        if not keep.any():
            return None, None
        return (round(float(np.median(ratio[keep])), 4),
                round(float(np.percentile(ratio[keep], 90)), 4))

    median, p90 = stats(ok)
    out: dict[str, Any] = {
        "median_abs_log_ratio": median,
        "p90_abs_log_ratio": p90,
        "pairs": int(ok.sum()),
        "meaning": "|ln f(l, v) / f(v, l)| over the grid's valid cells (channels summed): 0 "
                   "for a reciprocal BRDF. gonio's table assumes reciprocity and holds f with "
                   "the file's incident direction as the light, so its renderings show "
                   "f(v, l) on the mirrored half of a view (docs/science.md 7.0.1)",
    }
    if steep is not None:
        keep = ok & np.asarray(steep, dtype=bool)
        out["median_abs_log_ratio_below_80deg"], out["p90_abs_log_ratio_below_80deg"] = (
            stats(keep))
    return out


def read_rgl(path: str | os.PathLike[str], name: str | None = None) -> BRDFTable:
    """Tabulate an RGL ``.bsdf`` file on gonio's grid.

    Parameters
    ----------
    path : path of a ``.bsdf`` tensor file (RGB variant)
    name : str, optional
        Table name; default the file name without suffix.

    Returns
    -------
    BRDFTable
        Float32 ``(3, 72, 18, 18, 36)`` in 1/sr (R, G, B), identical in every ``ph`` slice.
        Provenance: source file, reader, clamped and non-finite counts, how far the file is
        from reciprocal (:func:`reciprocity_of`), load seconds.

    Raises
    ------
    RGLError
        File missing, unreadable or not a tensor file; mitsuba missing; mitsuba rejects it.
    """
    p = Path(path)
    index = read_tensor_index(p)
    mi = _mitsuba()
    t0 = time.perf_counter()
    try:
        bsdf = mi.load_dict({"type": "measured", "filename": str(p)})
    except Exception as exc:  # mitsuba raises plain RuntimeError with its own text
        raise RGLError(f"{p}: mitsuba cannot load it as a measured BSDF ({exc})") from None

    th, td, pd = geo.grid_angles()
    mask = geo.valid_mask()
    wi, wo = geo.half_diff_to_directions(th[mask], 0.0, td[mask], pd[mask])
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    raw = np.empty((wi.shape[0], 3))
    raw_exchanged = np.empty((wi.shape[0], 3))
    # The scalar variant evaluates one direction pair per call; 2 x 7861 calls take ~0.2 s.
    for k in range(wi.shape[0]):
        si.wi = mi.Vector3f(*wi[k])  # light direction: the incidence axis of the RGL tables
        value = bsdf.eval(ctx, si, mi.Vector3f(*wo[k]))
        raw[k] = (value[0], value[1], value[2])
        si.wi = mi.Vector3f(*wo[k])  # the same pair with light and view exchanged
        value = bsdf.eval(ctx, si, mi.Vector3f(*wi[k]))
        raw_exchanged[k] = (value[0], value[1], value[2])
    brdf = raw / wo[:, 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        exchanged = raw_exchanged / wi[:, 2:3]
    nonfinite = ~np.isfinite(brdf)
    negative = brdf < 0
    brdf = np.where(nonfinite | negative, 0.0, brdf)
    if not (brdf > 0).any():
        raise RGLError(f"{p}: mitsuba returned no positive value; the file may be damaged")

    slice_ = np.full((3, *geo.SLICE_SHAPE), np.nan, dtype=np.float32)
    slice_[:, mask] = brdf.T
    values = np.broadcast_to(slice_[:, None], (3, *geo.TABLE_SHAPE)).copy()
    provenance = {
        "source": "rgl",
        "file": str(p),
        "reader": f"mitsuba {mi.__version__} scalar_rgb measured",
        "description": index.get("description", {}).get("text", ""),
        "isotropic": True,
        "negative_clamped": int(negative.sum()),
        "nonfinite_zeroed": int(nonfinite.sum()),
        "reciprocity": reciprocity_of(
            brdf, np.where(exchanged > 0, exchanged, 0.0),
            steep=np.minimum(wi[:, 2], wo[:, 2]) >= np.cos(np.deg2rad(STEEP_LIMIT_DEG))),
        "load_seconds": round(time.perf_counter() - t0, 3),
    }
    return BRDFTable(values, CHANNELS, name or p.stem, None, provenance)
