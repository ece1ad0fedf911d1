"""The standard renderings' weighting of the grid's cells, as the design room reads it.

The expected-error design can weigh the grid's cells by how often the standard renderings
look them up (docs/science.md 7.2.2): ``design_pairs`` does so by default, with the share
:data:`DEFAULT_CELL_MIX`. The map is made by the renderer
(:func:`gonio.brdf.pictures.appearance.render_importance`), which the design room may not
import (the rooms of ``gonio.brdf`` do not import their siblings, pyproject's import
contracts). So the map ships as a small data file, ``data/render-importance.npz``, written by
``python -m gonio.brdf.pictures.designweight`` and checked against the renderer by
``tests/unit/brdf/pictures/test_designweight.py``: a change to the standard renderings that is
not written here fails the suite.

File layout (``numpy.savez``): ``format = "gonio-render-weight"``, ``version = 1``,
``shape = (18, 18, 36)`` (the ``(th, td, pd)`` nodes of the 5 degree grid), ``index`` (the
flat node indices with a non-zero count, int32, ascending) and ``value`` (their pixel
counts, float64), ``views`` (JSON: the views, size and light angles the counts were made with).
"""

from __future__ import annotations

import functools
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.design.errors import DesignError
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

FILE_NAME = "render-importance.npz"
"""The shipped map's file name in this package's ``data`` folder."""
FORMAT = "gonio-render-weight"
VERSION = 1

DEFAULT_CELL_MIX = 0.5
"""The share of the renderings' weighting in the default design's objective (``cell_mix``
of :func:`gonio.brdf.design.posterior.posterior_design`). Chosen on a choice set by mean
HDR-FLIP with ``log_rmse`` within 5 % of the unweighted design, then tested once on a test
set and once on a fresh set of specimens (docs/science.md 7.2.2)."""


def read_render_weight(path: str | None = None) -> FloatArray:
    """The pixel-count map in a render-weight file (module notes).

    Parameters
    ----------
    path : str, optional
        A file to read; the shipped map when omitted.

    Returns
    -------
    (18, 18, 36) float64 array, pixel counts per ``(th, td, pd)`` node (zero where no pixel
    looks).

    Raises
    ------
    DesignError
        When the file is missing, of another format or version, or its contents do not fit
        gonio's grid; the message says how to write it again.
    """
    again = "write it again with `python -m gonio.brdf.pictures.designweight`"
    def load(p: str | Path) -> dict[str, Any]:
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    try:
        if path is None:
            with resources.as_file(resources.files("gonio.brdf.design") / "data"
                                   / FILE_NAME) as shipped:
                data = load(shipped)
        else:
            data = load(path)
    except (OSError, ValueError) as exc:
        raise DesignError(f"cannot read the render-weight file {path or FILE_NAME}: {exc}; "
                          f"{again}") from exc
    if str(data.get("format", "")) != FORMAT or int(data.get("version", -1)) != VERSION:
        raise DesignError(f"{path or FILE_NAME} is not a {FORMAT} file of version {VERSION}; "
                          f"{again}")
    shape = tuple(int(s) for s in np.atleast_1d(data.get("shape", ())))
    if shape != geo.SLICE_SHAPE:
        raise DesignError(f"{path or FILE_NAME} holds a map of shape {shape}, gonio's grid has "
                          f"{geo.SLICE_SHAPE}; {again}")
    index = np.asarray(data.get("index", []), dtype=np.int64)
    value = np.asarray(data.get("value", []), dtype=np.float64)
    size = int(np.prod(shape))
    if (index.ndim != 1 or index.shape != value.shape or np.any(index < 0)
            or np.any(index >= size) or not np.all(np.isfinite(value)) or np.any(value < 0)
            or np.unique(index).size != index.size):
        raise DesignError(f"{path or FILE_NAME} has bad indices or counts (negative, not "
                          f"finite, repeated or outside the grid); {again}")
    out = np.zeros(size)
    out[index] = value
    return out.reshape(shape)


@functools.lru_cache(maxsize=1)
def _shipped() -> FloatArray:
    out = read_render_weight()
    out.setflags(write=False)  # shared by every design in the process
    return out


def render_weight() -> FloatArray:
    """The shipped map (read once per process, read-only): ``(18, 18, 36)`` pixel counts."""
    return _shipped()


def cell_weighting(mix: float | None) -> dict[str, Any]:
    """``design_pairs``' ``cell_weight`` / ``cell_mix`` for a share asked for by a user (the
    CLI's ``--render-mix``, the API's ``render_mix``): nothing for None (the design's own
    default), the unweighted design for 0, the shipped map at that share otherwise."""
    if mix is None:
        return {}
    if float(mix) == 0.0:
        return {"cell_mix": 0.0}
    return {"cell_weight": render_weight(), "cell_mix": float(mix)}
