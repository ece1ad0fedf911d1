"""Tests of the slice preview image and its PNG with a key (gonio.brdf.pictures.preview)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.pictures.preview import PreviewError, preview_image, save_preview
from gonio.brdf.tables.table import BRDFTable
from tests.unit.brdf.tables.test_metrics import constant


def test_preview_png(tmp_path: Path) -> None:
    t = constant(0.2)
    img = preview_image(t, scale=2, gap=1)
    assert img.dtype == np.uint8 and img.shape == (2 * 36 + 3, 4 * 36 + 5, 3)
    # Constant table: every valid cell shows the maximum level. At pd = 90 deg (first row)
    # every cell is valid; at pd = 0 (second row) large th + td fall below the horizon.
    first = img[1 : 1 + 36, 1 : 1 + 36]
    assert (first == 255).all()
    second = img[38 : 38 + 36, 1 : 1 + 36]
    assert (second == 255).all(axis=-1).any() and (second == 40).all(axis=-1).any()
    p = save_preview(t, tmp_path / "p.png", scale=2)
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(PreviewError, match="scale"):
        preview_image(t, scale=0)


def test_preview_png_carries_its_key() -> None:
    import io

    from PIL import Image

    from gonio.brdf.pictures.preview import preview_png

    t = constant(0.2)
    mosaic = preview_image(t, scale=3)
    img = np.asarray(Image.open(io.BytesIO(preview_png(t, scale=3, title="felt"))))
    # The mosaic sits inside a larger canvas whose margins hold text (dark pixels on white).
    assert img.shape[0] > mosaic.shape[0] and img.shape[1] > mosaic.shape[1]
    heading, footer, side = img[:15], img[-30:], img[:, :50]
    for band in (heading, footer, side):
        assert (band.sum(axis=-1) < 300).any()


def _tinted(ratio: tuple[float, float, float]) -> BRDFTable:
    """A table whose channels stand in ``ratio`` everywhere, its brightness running over five
    decades along theta_h (so every level of the colour bar's range occurs in the panels)."""
    from gonio.brdf.tables import geometry as geo

    scale = 10.0 ** np.linspace(1.0, -4.0, geo.N_TH)  # 1/sr, along theta_h
    v = np.broadcast_to(scale[None, None, :, None, None], (1, *geo.TABLE_SHAPE))
    return BRDFTable(np.asarray(ratio)[:, None, None, None, None] * v, ("R", "G", "B"))


def test_the_colour_bar_shows_the_colours_the_panels_use() -> None:
    """A tinted material's panels are tinted: its colour bar must be too (issue 27 item 6; it
    was a grey ramp). Every valid panel colour is a colour of the bar (within rounding), and
    the bar's top is the panels' brightest colour, whatever the code's mapping is."""
    import io

    from PIL import Image

    from gonio.brdf.pictures.preview import colour_bar_box, preview_png

    t = _tinted((1.0, 0.45, 0.12))
    mosaic = preview_image(t, scale=3)
    img = np.asarray(Image.open(io.BytesIO(preview_png(t, scale=3)))).astype(int)
    x0, y0, w, h = colour_bar_box(mosaic.shape)
    bar = img[y0 : y0 + h, x0 + w // 2]  # (h, 3): one column down the bar
    assert (bar[:, 0] - bar[:, 2]).max() > 60, "the bar is grey while the panels are tinted"
    # The panels' colours, without the gaps, the invalid cells and their hatching.
    cells = mosaic.reshape(-1, 3).astype(int)
    keep = ~((cells == 255).all(axis=1) | (cells == 40).all(axis=1) | (cells == 150).all(axis=1))
    colours = np.unique(cells[keep], axis=0)
    # Colours below the bar's range (more than LOG_SPAN decades down) are black in both.
    nearest = np.abs(colours[:, None, :] - bar[None, :, :]).max(axis=-1).min(axis=1)
    assert nearest.max() <= 8, colours[nearest.argmax()]
    assert np.abs(bar[0] - colours.max(axis=0)).max() <= 1


def test_a_grey_tables_bar_stays_grey() -> None:
    import io

    from PIL import Image

    from gonio.brdf.pictures.preview import colour_bar_box, preview_png

    t = _tinted((0.3, 0.3, 0.3))
    img = np.asarray(Image.open(io.BytesIO(preview_png(t, scale=3))))
    x0, y0, w, h = colour_bar_box(preview_image(t, scale=3).shape)
    bar = img[y0 : y0 + h, x0 : x0 + w].astype(int)
    assert (bar.max(axis=-1) - bar.min(axis=-1) == 0).all()
    assert bar[0].min() == 255 and bar[-1].max() == 0  # the full range, top to bottom
