"""A PNG preview of a reconstructed BRDF for the lab page.

The image is the half-vector hemisphere seen from above: a pixel at radius ``sin(theta_h)``
and angle ``phi_h`` shows ``f(theta_h, phi_h, theta_d, phi_d)`` at a fixed difference angle.
The specular lobe is the bright centre and anisotropy shows as an elongated lobe, which is the
thing to check first after a scan. Values are shown on a log scale, all channels with one
range so colour is preserved.
"""

from __future__ import annotations

import io
import math

import numpy as np
from numpy.typing import NDArray
from PIL import Image

from gonio.brdf.table import BRDFTable

STEP_DEG = 5.0


def hemisphere_image(
    table: BRDFTable, theta_d_deg: float = 10.0, phi_d_deg: float = 90.0, size: int = 256
) -> NDArray[np.uint8]:
    """RGB image of the half-vector hemisphere at one difference angle.

    Parameters
    ----------
    table : BRDFTable
        C channels; 3 are shown as RGB, any other count as grey (channel mean).
    theta_d_deg, phi_d_deg : float, degrees
        The difference angle (nearest grid cell).
    size : int
        Image side, pixels.

    Returns
    -------
    (size, size, 3) uint8 array
        Black outside the hemisphere and where the cell is invalid.
    """
    i_td = round(theta_d_deg / STEP_DEG) % 18
    i_pd = round(phi_d_deg / STEP_DEG) % 36
    values = np.asarray(table.values[:, :, :, i_td, i_pd], dtype=float)  # (C, 72, 18)
    yy, xx = np.mgrid[0:size, 0:size]
    x = (xx + 0.5) / size * 2 - 1
    y = 1 - (yy + 0.5) / size * 2
    r = np.hypot(x, y)
    inside = r < 1.0
    th = np.degrees(np.arcsin(np.clip(r, 0, 1)))
    ph = np.degrees(np.arctan2(y, x)) % 360.0
    i_th = np.clip(np.rint(th / STEP_DEG).astype(int), 0, 17)
    i_ph = np.rint(ph / STEP_DEG).astype(int) % 72
    f = values[:, i_ph, i_th]  # (C, size, size)
    if f.shape[0] != 3:
        f = np.repeat(np.nanmean(f, axis=0, keepdims=True), 3, axis=0)
    valid = inside & np.all(np.isfinite(f), axis=0)
    log_f = np.log10(np.maximum(np.nan_to_num(f, nan=0.0), 1e-4))
    if valid.any():
        lo, hi = np.percentile(log_f[:, valid], [1, 99.5])
    else:
        lo, hi = -4.0, 0.0
    scaled = np.clip((log_f - lo) / max(hi - lo, 1e-6), 0, 1)
    img = np.where(valid[None], scaled, 0.0)
    return (np.moveaxis(img, 0, -1) * 255 + 0.5).astype(np.uint8)


def preview_png(table: BRDFTable, size: int = 256) -> bytes:
    """PNG bytes of :func:`hemisphere_image` at the default difference angle."""
    if size < 16 or size > 2048 or not math.isfinite(size):
        raise ValueError(f"preview size {size} px: use 16 to 2048")
    buf = io.BytesIO()
    Image.fromarray(hemisphere_image(table, size=size), mode="RGB").save(buf, format="PNG")
    return buf.getvalue()
