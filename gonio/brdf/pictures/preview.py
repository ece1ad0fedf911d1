"""PNG preview of a tabulated BRDF: a mosaic of half/difference slices.

Layout: one column per half-vector azimuth ``ph`` in {0, 45, 90, 135} deg (anisotropy shows as
differences between columns), one row per difference azimuth ``pd`` in {90, 0} deg. Each panel
is the ``(th, td)`` plane, ``th`` (0-85 deg) downwards and ``td`` (0-85 deg) to the right, so
the specular peak is the top-left corner and grazing retro/forward scattering the far edges.

Values are shown on one shared logarithmic scale (``log10`` of the BRDF, 1/sr, from
``LOG_SPAN`` decades below the maximum up to the maximum), with the channels mapped to RGB
(the first three channels; a one-channel table is shown in grey), so colour and relative
brightness stay comparable between panels. Cells below the horizon are hatched grey. The PNG
(:func:`preview_png`) has a colour bar with the BRDF value of each decade, drawn with the same
mapping as the panels: each height is the colour of a cell whose brightest channel has the value
beside it and whose other channels stand to it as they typically do in this table (the median
ratio over the valid cells), so a tinted material's bar is tinted as its panels are
(:func:`colour_bar`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable


class PreviewError(ValueError):
    """A preview that cannot be drawn as asked (scale, gap)."""


PH_DEG: tuple[int, ...] = (0, 45, 90, 135)
PD_DEG: tuple[int, ...] = (90, 0)
LOG_SPAN = 4.0  # decades of dynamic range shown
_INVALID_RGB = (40, 40, 40)
_HATCH_RGB = (150, 150, 150)
_GAP_RGB = (255, 255, 255)
PNG_MARGINS = (64, 18, 34, 150)
"""Left, top, bottom and right margins of :func:`preview_png` around the mosaic, pixels."""


def _levels(values: NDArray[np.floating], top: float) -> NDArray[np.uint8]:
    """The panels' mapping: BRDF values (1/sr) to 8-bit levels, log scale from ``LOG_SPAN``
    decades below ``10**top`` up to it, with display gamma 2.2; non-finite values give 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        lg = (np.log10(np.maximum(values, 1e-30)) - (top - LOG_SPAN)) / LOG_SPAN
    level = np.nan_to_num(np.clip(lg, 0.0, 1.0)) ** (1 / 2.2)  # display gamma
    return (255 * level).astype(np.uint8)


def _shown_channels(table: BRDFTable) -> NDArray[np.floating]:
    """The three channels the preview shows as R, G, B (a one-channel table three times)."""
    v = np.asarray(table.values, dtype=float)
    return v[[0, 0, 0]] if v.shape[0] < 3 else v[:3]


def typical_ratio(table: BRDFTable) -> NDArray[np.floating]:
    """Each shown channel over the brightest one, median over the valid cells, shape (3,).

    (1, 1, 1) for a grey (or one-channel) table; the colour bar is drawn with it.
    """
    rgb = _shown_channels(table).reshape(3, -1)
    ok = np.isfinite(rgb).all(axis=0) & (rgb.max(axis=0) > 0)
    if not ok.any():
        return np.ones(3)
    cells = rgb[:, ok]
    return np.asarray(np.median(cells / cells.max(axis=0), axis=1), dtype=float)


def colour_bar(table: BRDFTable, height: int, width: int = 16) -> NDArray[np.uint8]:
    """The preview's colour bar as an (height, width, 3) uint8 image, top = the maximum.

    Row ``y`` is the colour :func:`preview_image` gives a cell whose brightest channel is
    ``10 ** (top - LOG_SPAN * y / (height - 1))`` 1/sr and whose channels stand in the
    table's :func:`typical_ratio`: the panels' own mapping, tint included.
    """
    top = _top_log10(table)
    brightest = 10.0 ** (top - LOG_SPAN * np.linspace(0.0, 1.0, height))  # (height,)
    column = _levels(brightest[:, None] * typical_ratio(table)[None, :], top)  # (height, 3)
    return np.repeat(column[:, None, :], width, axis=1)


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
        raise PreviewError(f"preview scale must be >= 1 and gap >= 0, got {scale}, {gap}")
    rgb = _shown_channels(table)
    top = _top_log10(table)
    panel = geo.N_TH * scale
    h = len(PD_DEG) * panel + (len(PD_DEG) + 1) * gap
    w = len(PH_DEG) * panel + (len(PH_DEG) + 1) * gap
    img = np.empty((h, w, 3), dtype=np.uint8)
    img[:] = _GAP_RGB
    for r, pd in enumerate(PD_DEG):
        for c, ph in enumerate(PH_DEG):
            sl = rgb[:, int(ph // geo.STEP_DEG), :, :, int(pd // geo.STEP_DEG)]  # (3, th, td)
            tile = np.moveaxis(_levels(sl, top), 0, -1)  # (th, td, 3)
            invalid = ~np.isfinite(sl).all(axis=0)
            tile[invalid] = _INVALID_RGB
            tile = np.repeat(np.repeat(tile, scale, axis=0), scale, axis=1)
            _hatch(tile, np.repeat(np.repeat(invalid, scale, axis=0), scale, axis=1))
            y0 = gap + r * (panel + gap)
            x0 = gap + c * (panel + gap)
            img[y0 : y0 + panel, x0 : x0 + panel] = tile
    return img


def _hatch(tile: NDArray[np.uint8], invalid: NDArray[np.bool_]) -> None:
    """Diagonal stripes over invalid cells, so they cannot be mistaken for low values."""
    yy, xx = np.indices(invalid.shape)
    stripe = ((xx + yy) // 3) % 2 == 0
    tile[invalid & stripe] = _HATCH_RGB


def _top_log10(table: BRDFTable) -> float:
    rgb = _shown_channels(table)
    finite = rgb[np.isfinite(rgb)]
    return float(np.log10(max(float(finite.max()) if finite.size else 1.0, 1e-12)))


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
    left, top, bottom, right = PNG_MARGINS
    canvas = Image.new("RGB", (mosaic.shape[1] + left + right, mosaic.shape[0] + top + bottom),
                       _GAP_RGB)
    canvas.paste(Image.fromarray(mosaic), (left, top))
    draw = ImageDraw.Draw(canvas)
    ink = (30, 30, 30)
    # Colour bar: the panels' mapping at the table's typical tint, one tick per decade.
    x0, y0, bar_w, bar_h = colour_bar_box(mosaic.shape, left, top, gap)
    canvas.paste(Image.fromarray(colour_bar(table, bar_h, bar_w)), (x0, y0))
    draw.rectangle((x0 - 1, y0 - 1, x0 + bar_w, y0 + bar_h), outline=ink)
    top_log = _top_log10(table)
    for k in range(int(LOG_SPAN) + 1):
        y = y0 + round(k / LOG_SPAN * (bar_h - 1))
        draw.line((x0 + bar_w, y, x0 + bar_w + 4, y), fill=ink)
        draw.text((x0 + bar_w + 7, y - 6), f"{10 ** (top_log - k):.3g} 1/sr", fill=ink)
    sw = np.full((14, bar_w, 3), _INVALID_RGB, dtype=np.uint8)
    _hatch(sw, np.ones((14, bar_w), dtype=bool))
    canvas.paste(Image.fromarray(sw), (x0, y0 + bar_h + 14))
    draw.text((x0 + bar_w + 7, y0 + bar_h + 10), "invalid:\nbelow horizon", fill=ink)
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


def colour_bar_box(mosaic_shape: tuple[int, ...], left: int = PNG_MARGINS[0],
                   top: int = PNG_MARGINS[1], gap: int = 4) -> tuple[int, int, int, int]:
    """Where :func:`preview_png` puts the colour bar: ``(x0, y0, width, height)``, pixels.

    ``mosaic_shape`` is the shape of :func:`preview_image`'s mosaic; ``left``, ``top`` the
    PNG's margins (:data:`PNG_MARGINS`) and ``gap`` the mosaic's gap.
    """
    return left + mosaic_shape[1] + 12, top + gap, 16, mosaic_shape[0] - 2 * gap - 40


def save_preview(table: BRDFTable, path: str | os.PathLike[str], scale: int = 10) -> Path:
    """Write :func:`preview_png` of ``table``; returns the path."""
    p = Path(path)
    p.write_bytes(preview_png(table, scale))
    return p
