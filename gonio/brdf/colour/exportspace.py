"""Linear sRGB from XYZ, for exports that must state their colour space (glTF, MaterialX).

glTF's base colour and MaterialX's ``lin_rec709`` are linear Rec. 709 / sRGB primaries with a
D65 white (2 degree observer). XYZ computed under other conditions is first adapted to that
white (Bradford), then transformed by colour-science; nothing is clipped, so out-of-gamut
colours stay visible as values below 0 or above 1 to whoever reads the file.
"""

from __future__ import annotations

import warnings
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.conditions import ViewingConditions, library_version
from gonio.brdf.tables.table import BRDFTable

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour

FloatArray = NDArray[np.float64]

#: The colour space exports are written in and the adaptation used to reach it.
EXPORT_SPACE = "sRGB"
ADAPTATION = "Bradford"


def xyz_to_linear_srgb(xyz: ArrayLike, conditions: ViewingConditions) -> FloatArray:
    """(..., 3) linear sRGB (1 = perfect diffuser) of XYZ (perfect diffuser Y = 100)."""
    x = np.asarray(xyz, dtype=float) / 100.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rgb = colour.XYZ_to_RGB(x, colour.RGB_COLOURSPACES[EXPORT_SPACE], conditions.white_xy,
                                ADAPTATION, apply_cctf_encoding=False)
    return np.asarray(rgb, dtype=float)


def conversion_record(conditions: ViewingConditions, how: str) -> dict[str, Any]:
    """What an export states about its colour: space, source conditions, how channels became
    XYZ (``how``), the adaptation and the library that did it."""
    return {
        "space": "linear sRGB (Rec. 709 primaries, D65)", "from": "CIE XYZ",
        "xyz_conditions": conditions.label, "channels_to_xyz": how,
        "chromatic_adaptation": ADAPTATION,
        "library": f"colour-science {library_version()}",
    }


class _ToXYZ(Protocol):
    def to_xyz(self, values: ArrayLike, conditions: ViewingConditions) -> FloatArray: ...


def srgb_matrix(conversion: _ToXYZ, n_channels: int,
                conditions: ViewingConditions) -> FloatArray:
    """(3, C) matrix from a sensor's reflectance factors to linear sRGB.

    Every step (bands to spectrum, ASTM E308 weighting or a chart matrix, chromatic adaptation,
    XYZ to sRGB) is linear, so the composition is one matrix: obtained by passing each unit
    channel vector through colour-science's transforms.
    """
    xyz = conversion.to_xyz(np.eye(n_channels), conditions)  # (C, 3)
    return np.ascontiguousarray(xyz_to_linear_srgb(xyz, conditions).T)


def linear_srgb_table(table: BRDFTable, conversion: _ToXYZ,
                      conditions: ViewingConditions | None = None,
                      how: str = "") -> BRDFTable:
    """The table's BRDF in linear sRGB channels ``R, G, B`` (1/sr), clamped at 0.

    Out-of-gamut colours have negative components; BRDF tables hold none, so they are clamped
    and the provenance says so (``colour_space``: :func:`conversion_record` plus
    ``clamped_at_zero``).
    """
    cond = conditions or ViewingConditions()
    m = srgb_matrix(conversion, table.n_channels, cond)
    v = np.asarray(table.values, dtype=np.float64)
    flat = v.reshape(table.n_channels, -1)
    out = (m @ np.nan_to_num(flat)).reshape(3, *v.shape[1:])
    np.maximum(out, 0.0, out=out)
    out[:, np.isnan(v[0])] = np.nan
    record = {**conversion_record(cond, how), "clamped_at_zero": True}
    return BRDFTable.trusted(out.astype(np.float32), ("R", "G", "B"), table.name, None,
                             {**table.provenance, "colour_space": record})
