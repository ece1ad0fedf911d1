"""Linear sRGB from XYZ, for exports that must state their colour space (glTF, MaterialX).

glTF's base colour and MaterialX's ``lin_rec709`` are linear Rec. 709 / sRGB primaries with a
D65 white (2 degree observer). XYZ computed under other conditions is first adapted to that
white (Bradford), then transformed by colour-science; nothing is clipped, so out-of-gamut
colours stay visible as values below 0 or above 1 to whoever reads the file.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.colour.conditions import ViewingConditions, library_version

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
