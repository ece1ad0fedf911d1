"""Tests of the slice preview image and its PNG with a key (gonio.brdf.pictures.preview)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.pictures.preview import PreviewError, preview_image, save_preview
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
