"""PNG preview of a tabulated BRDF: a mosaic of half/difference slices.

Layout: one column per half-vector azimuth ``ph`` in {0, 45, 90, 135} deg (anisotropy shows as
differences between columns), one row per difference azimuth ``pd`` in {90, 0} deg. Each panel
is the ``(th, td)`` plane, ``th`` (0-85 deg) downwards and ``td`` (0-85 deg) to the right, so
the specular peak is the top-left corner and grazing retro/forward scattering the far edges.

Values are shown on one shared logarithmic scale (``log10`` of the BRDF, 1/sr, from
``LOG_SPAN`` decades below the maximum up to the maximum), with the channels mapped to RGB
(the first three channels; a one-channel table is shown in grey), so colour and relative
brightness stay comparable between panels. Cells below the horizon are dark grey.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from gonio.brdf import geometry as geo
from gonio.brdf.table import BRDFTable

PH_DEG: tuple[int, ...] = (0, 45, 90, 135)
PD_DEG: tuple[int, ...] = (90, 0)
LOG_SPAN = 4.0  # decades of dynamic range shown
_INVALID_RGB = (40, 40, 40)
_GAP_RGB = (255, 255, 255)


def preview_image(table: BRDFTable, scale: int = 10, gap: int = 4) -> NDArray[np.uint8]:
    """The preview mosaic as an (H, W, 3) uint8 image (layout in the module docstring).

    Parameters
    ----------
    table : BRDFTable
    scale : int
        Pixels per grid cell.
    gap : int
        Pixels between panels.
    """
    if scale < 1 or gap < 0:
        raise ValueError(f"preview scale must be >= 1 and gap >= 0, got {scale}, {gap}")
    v = np.asarray(table.values, dtype=float)
    rgb = v[[0, 0, 0]] if v.shape[0] < 3 else v[:3]
    finite = rgb[np.isfinite(rgb)]
    top = float(np.log10(max(float(finite.max()) if finite.size else 1.0, 1e-12)))
    panel = geo.N_TH * scale
    h = len(PD_DEG) * panel + (len(PD_DEG) + 1) * gap
    w = len(PH_DEG) * panel + (len(PH_DEG) + 1) * gap
    img = np.empty((h, w, 3), dtype=np.uint8)
    img[:] = _GAP_RGB
    for r, pd in enumerate(PD_DEG):
        for c, ph in enumerate(PH_DEG):
            sl = rgb[:, int(ph // geo.STEP_DEG), :, :, int(pd // geo.STEP_DEG)]  # (3, th, td)
            with np.errstate(divide="ignore", invalid="ignore"):
                lg = (np.log10(np.maximum(sl, 1e-30)) - (top - LOG_SPAN)) / LOG_SPAN
            level = np.nan_to_num(np.clip(lg, 0.0, 1.0)) ** (1 / 2.2)  # display gamma
            tile = np.moveaxis((255 * level).astype(np.uint8), 0, -1)  # (th, td, 3)
            tile[~np.isfinite(sl).all(axis=0)] = _INVALID_RGB
            tile = np.repeat(np.repeat(tile, scale, axis=0), scale, axis=1)
            y0 = gap + r * (panel + gap)
            x0 = gap + c * (panel + gap)
            img[y0 : y0 + panel, x0 : x0 + panel] = tile
    return img


def preview_png(table: BRDFTable, scale: int = 10, title: str | None = None) -> bytes:
    """PNG bytes of :func:`preview_image` with its key drawn around it.

    A heading names each column's ``ph`` and each row's ``pd``, and a footer states the axes
    and the log scale, so the image reads on its own (lab page, demo output, result viewers).

    Parameters
    ----------
    table : BRDFTable
    scale : int
        Pixels per grid cell.
    title : str, optional
        First line of the footer (default: the table's name).
    """
    import io

    from PIL import Image, ImageDraw

    gap = 4
    mosaic = preview_image(table, scale, gap)
    panel = geo.N_TH * scale
    left, top, bottom = 64, 18, 34
    canvas = Image.new("RGB", (mosaic.shape[1] + left, mosaic.shape[0] + top + bottom), _GAP_RGB)
    canvas.paste(Image.fromarray(mosaic), (left, top))
    draw = ImageDraw.Draw(canvas)
    ink = (30, 30, 30)
    for c, ph in enumerate(PH_DEG):
        draw.text((left + gap + c * (panel + gap) + 2, 3), f"phi_h = {ph} deg", fill=ink)
    for r, pd in enumerate(PD_DEG):
        y = top + gap + r * (panel + gap) + panel // 2 - 12
        draw.text((4, y), f"phi_d =\n{pd} deg", fill=ink)
    y = top + mosaic.shape[0] + 3
    name = table.name if title is None else title
    draw.text((left, y), f"{name}: log10 BRDF (1/sr), top {LOG_SPAN:g} decades", fill=ink)
    draw.text((left, y + 14), "each panel: theta_h 0-85 deg down, theta_d 0-85 deg right",
              fill=ink)
    buf = io.BytesIO()
    canvas.save(buf, format="PNG")
    return buf.getvalue()


def save_preview(table: BRDFTable, path: str | os.PathLike[str], scale: int = 10) -> Path:
    """Write :func:`preview_png` of ``table``; returns the path."""
    p = Path(path)
    p.write_bytes(preview_png(table, scale))
    return p
