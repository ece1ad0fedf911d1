"""The MERL ``.binary`` BRDF file layout (Matusik et al. 2003): one reader for gonio.

Layout, as the MERL database's published reader expects it:

* three little-endian ``int32``: the dimensions ``(n_th, n_td, n_pd)``, ``90, 90, 180`` in the
  database (theta_h, theta_d, phi_d);
* then ``3 n_th n_td n_pd`` little-endian ``float64``: the red block, the green block, the
  blue block, each in C order over ``(i_theta_h, i_theta_d, i_phi_d)``;
* a stored number times the channel's scale (red ``1/1500``, green ``1.15/1500``, blue
  ``1.66/1500``) is the BRDF in 1/sr; negative numbers mark cells below the horizon or not
  measured.

Bins: ``i_theta_d = floor(theta_d / (pi/2) n_td)``, ``i_phi_d = floor(phi_d / pi n_pd)`` with
``phi_d`` in ``[0, pi)`` (reciprocity); ``theta_h`` is binned non-linearly,
``i_theta_h = floor(n_th sqrt(theta_h / (pi/2)))``, fine near the specular peak.

The writer (:mod:`gonio.export.merl`) takes the layout from here, and everything that reads a
MERL file (the library import, :mod:`gonio.brdf.materials.imports`, and whatever reads an
exported file back) reads through :func:`read_merl_values`, so the layout lives here once.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180
SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D)
"""The database's dimensions (theta_h, theta_d, phi_d)."""
SCALES = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
"""Published per-channel scale factors (R, G, B): stored number x scale = BRDF (1/sr)."""
HEADER = np.dtype("<i4")
DATA = np.dtype("<f8")
MAX_CELLS = 10_000_000
"""Largest ``n_th n_td n_pd`` accepted from a header (the database has 1,458,000)."""


class MerlError(ValueError):
    """A table cannot be written as MERL, or a file is not a MERL binary."""


def read_merl_values(
    path: str | os.PathLike[str], shape: tuple[int, int, int] | None = SHAPE
) -> NDArray[np.float64]:
    """Read a MERL ``.binary`` file: ``(3, n_th, n_td, n_pd)`` BRDF in 1/sr, NaN where the
    file stores a negative number (below the horizon, not measured).

    Parameters
    ----------
    path : path of the file
    shape : the dimensions the header must have, or None to accept any plausible ones
        (at least 2 per axis, at most :data:`MAX_CELLS` cells), as downsampled MERL-layout
        files use.

    Raises
    ------
    MerlError
        Missing or unreadable file, wrong dimensions or wrong size, with what was found.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise MerlError(f"{p}: cannot be read ({exc.strerror})") from None
    if len(raw) < HEADER.itemsize * 3:
        raise MerlError(
            f"{p}: {len(raw)} bytes is too short for a MERL .binary file (no 12-byte header)"
        )
    dims = tuple(int(d) for d in np.frombuffer(raw[:12], dtype=HEADER))
    if shape is not None and dims != shape:
        raise MerlError(f"{p}: dimensions {dims}, expected {shape} (theta_h, theta_d, phi_d)")
    if min(dims) < 2 or int(np.prod(dims, dtype=np.int64)) > MAX_CELLS:
        raise MerlError(
            f"{p}: header dimensions {list(dims)} are not a MERL table (expected e.g. "
            "90 90 180); is it a MERL .binary file?"
        )
    want = 12 + 3 * int(np.prod(dims)) * DATA.itemsize
    if len(raw) != want:
        raise MerlError(
            f"{p}: {len(raw)} bytes, but the header {list(dims)} needs {want}; the file is "
            "truncated or not a MERL .binary file"
        )
    data: Any = np.frombuffer(raw[12:], dtype=DATA).reshape(3, *dims)
    out = np.array(data, dtype=float) * np.asarray(SCALES)[:, None, None, None]
    out[data < 0] = np.nan
    return out
