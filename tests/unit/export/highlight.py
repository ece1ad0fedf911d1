"""The shape of a highlight in a rendered image: its direction and its widths (test helper).

Written for the rendering tests of the exports: a strongly anisotropic GGX lobe under a light
at the camera makes an elliptical highlight at the centre of the sphere, whose long axis is the
tangent direction the renderer used (on the image, counter-clockwise from +x) and whose
widths follow the roughnesses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Highlight:
    direction_deg: float  # long axis, counter-clockwise from image +x, in [0, 180)
    major_px: float  # RMS extent along the long axis, pixels
    minor_px: float  # RMS extent across it, pixels


def highlight(img: NDArray[np.float64], level: float = 0.2) -> Highlight:
    """Intensity-weighted second moments of the pixels brighter than ``level`` x the peak.

    Parameters
    ----------
    img : (H, W, 3) linear radiance, row 0 at the top; NaN = background
    level : fraction of the brightest pixel's luminance that bounds the highlight
    """
    lum = np.nan_to_num(np.asarray(img, dtype=float)).mean(axis=-1)
    w = np.where(lum > level * lum.max(), lum, 0.0)
    rows, cols = np.indices(lum.shape)
    x, y = cols.astype(float), -rows.astype(float)  # y up, as the image shows it
    s = w.sum()
    mx, my = (w * x).sum() / s, (w * y).sum() / s
    sxx = (w * (x - mx) ** 2).sum() / s
    syy = (w * (y - my) ** 2).sum() / s
    sxy = (w * (x - mx) * (y - my)).sum() / s
    angle = 0.5 * math.degrees(math.atan2(2 * sxy, sxx - syy)) % 180.0
    ev = np.linalg.eigvalsh(np.array([[sxx, sxy], [sxy, syy]]))
    return Highlight(angle, float(math.sqrt(ev[1])), float(math.sqrt(max(ev[0], 0.0))))


def angle_between(a_deg: float, b_deg: float) -> float:
    """Smallest difference of two axis directions (defined modulo 180 degrees), degrees."""
    d = (a_deg - b_deg) % 180.0
    return min(d, 180.0 - d)
