"""The one container behind gonio's ``.npz`` files (tables, bases, samples).

Each file holds a ``format`` name and a ``version`` beside its arrays, and a ``provenance``
JSON object, so any of them opens with ``numpy.load`` alone. Writes are atomic (a temporary
name, then a rename), so a crash never leaves a half-written file under the real name.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray


def write_npz(
    path: str | os.PathLike[str],
    format_name: str,
    version: int,
    provenance: Mapping[str, Any],
    **arrays: Any,
) -> Path:
    """Write ``arrays`` with the format header and provenance, compressed and atomically.

    Parameters
    ----------
    path : path of the file to write
    format_name, version : identify the layout for :func:`read_npz`
    provenance : JSON-serialisable mapping (non-JSON values are written with ``str``)
    **arrays : array_like values stored under their keyword names

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    # A temporary name of its own: two writers of one path (the daemon exporting the same job
    # twice at once) must not write into, or rename away, each other's temporary file.
    tmp = p.with_name(f"{p.name}.{uuid.uuid4().hex[:12]}.part")
    try:
        with open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                format=np.array(format_name),
                version=np.array(version),
                provenance=np.array(json.dumps(dict(provenance), default=str)),
                **arrays,
            )
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)
    return p


def read_npz(
    path: str | os.PathLike[str],
    *,
    format_name: str,
    version: int,
    required: Iterable[str],
    error: type[ValueError],
    kind: str,
    how_to_make: str = "",
) -> tuple[dict[str, NDArray[Any]], dict[str, Any]]:
    """Read a file written by :func:`write_npz`, checking its header and fields.

    Parameters
    ----------
    path : the file
    format_name, version : what the caller reads
    required : field names that must be present
    error : exception type raised on any problem (a ``ValueError`` subclass)
    kind : what the file is, for messages (``"table"``, ``"basis"``, ...)
    how_to_make : a hint appended when the file is not of this format

    Returns
    -------
    data : dict of field name to array
    provenance : dict, with ``"file"`` set to ``path``
    """
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(8)
    except FileNotFoundError:
        raise error(f"{p}: no such {kind} file") from None
    except IsADirectoryError:
        raise error(f"{p}: is a directory, not a {kind} file") from None
    except OSError as exc:
        raise error(f"{p}: cannot read the {kind} file: {exc.strerror}") from None
    if not head.startswith(ZIP_MAGIC):
        # Checked before numpy sees it: for anything but a zip archive numpy's own message
        # suggests allow_pickle=True, which is bad advice for a file of unknown origin.
        hint = f"; {how_to_make}" if how_to_make else ""
        raise error(f"{p}: not a readable gonio {kind} file: {_what_it_is(head)}, not a .npz (zip) "
                    f"archive{hint}")
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as exc:  # zip and npy errors come in many types
        reason = "it holds Python objects, which gonio files never do" if "pickle" in str(
            exc) else str(exc)
        raise error(f"{p}: not a readable gonio {kind} file ({reason})") from None
    if str(data.get("format", "")) != format_name:
        hint = f"; {how_to_make}" if how_to_make else ""
        raise error(f"{p}: not a gonio {kind} file (missing format={format_name!r}){hint}")
    found = int(data.get("version", -1))
    if found != version:
        raise error(f"{p}: {kind} format version {found}; this gonio reads version {version}")
    missing = set(required) - data.keys()
    if missing:
        raise error(f"{p}: missing fields {sorted(missing)}")
    try:
        provenance = json.loads(str(data.get("provenance", "{}")))
    except json.JSONDecodeError:
        provenance = {}
    if not isinstance(provenance, dict):
        provenance = {}
    return data, {**provenance, "file": str(p)}


ZIP_MAGIC = b"PK\x03\x04"
"""The first bytes of a zip archive (NumPy's .npz)."""
HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
"""The first bytes of an HDF5 file (a gonio result file)."""


def starts_with(path: str | os.PathLike[str], magic: bytes) -> bool:
    """Whether the file at ``path`` begins with ``magic`` (False when it cannot be read): what
    a file is, whatever its name says."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(magic)) == magic
    except OSError:
        return False


def _what_it_is(head: bytes) -> str:
    """A guess at a file's type from its first bytes, for error messages."""
    if not head:
        return "the file is empty"
    if head.startswith(HDF5_MAGIC):
        return "it is an HDF5 file (a gonio result file? read it with gonio.results.read_result)"
    if head.startswith(b"\x93NUMPY"):
        return "it is a single .npy array"
    if head.startswith(b"PK"):
        return "it is an empty or unusual zip archive"
    return f"it starts with the bytes {head[:8]!r}"
