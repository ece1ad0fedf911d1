"""The renderer against formulas: Lambert's cosine law, rotation of an anisotropic highlight,
the table lookup against BRDFTable.eval, sRGB encoding and figure layout."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from PIL import Image

from gonio.brdf.models import analytic as bm
from gonio.brdf.pictures import render as R  # noqa: N812 (short name for many calls)

ALBEDO = (0.8, 0.5, 0.2)


def _pixel_normals(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Normals of an orthographic unit sphere computed here from the documented convention:
    pixel centres span [-1, 1] (plus one pixel of margin), x right, y up, z to the camera."""
    c = ((np.arange(size) + 0.5) / size * 2.0 - 1.0) * (1.0 + 2.0 / size)
    x, y = np.meshgrid(c, -c)
    inside = x * x + y * y < 1.0
    z = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, None))
    return inside, np.stack([x, y, z], axis=-1)


@pytest.mark.parametrize("tabulated", [False, True])
def test_lambertian_sphere_follows_the_cosine_law(tabulated: bool) -> None:
    lam = bm.Lambert(ALBEDO)
    brdf = bm.tabulate(lam) if tabulated else lam
    light = R.PointLight(40.0, 30.0)
    t, p = math.radians(40.0), math.radians(30.0)
    ldir = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
    img = R.render_sphere(brdf, light, size=96)
    inside, n = _pixel_normals(96)
    assert (np.isfinite(img[..., 0]) == inside).all()  # background is NaN, sphere is drawn
    cos = np.clip(n @ ldir, 0.0, None)
    expected = np.asarray(ALBEDO)[None, None, :] / math.pi * cos[..., None]
    # The table has no valid cell at the very horizon: compare where light and view are
    # both at least 6 degrees above it, and everywhere for the analytic model.
    keep = inside & ((cos > math.sin(math.radians(6))) & (n[..., 2] > math.sin(math.radians(6)))
                     if tabulated else inside)
    np.testing.assert_allclose(img[keep], expected[keep], rtol=1e-6, atol=1e-9)
    assert np.all(img[inside & (cos == 0.0)] == 0.0)  # the unlit side is black



def test_a_small_views_kept_directions_survive_an_evaluator_that_writes_into_them() -> None:
    """Views of at most GEOMETRY_CACHE_SIZE pixels keep their direction pairs for the next
    rendering (the export's rendered fit renders the same views a thousand times): an
    evaluator that scribbles over its arguments changes no later rendering."""
    lam = bm.Lambert(ALBEDO)
    light = R.PointLight(40.0, 30.0)
    size = R.GEOMETRY_CACHE_SIZE // 2

    class Scribbler:
        channels = ("R", "G", "B")

        def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            out = lam.eval(wi, wo)
            wi *= -1.0
            wo[:] = 0.0
            return out

    sphere, swatch = R.render_sphere(lam, light, size), R.render_swatch(lam, size=size)
    scribbled = R.render_sphere(Scribbler(), light, size), R.render_swatch(Scribbler(), size=size)
    assert np.array_equal(scribbled[0], sphere, equal_nan=True)
    assert np.array_equal(scribbled[1], swatch)
    assert np.array_equal(R.render_sphere(lam, light, size), sphere, equal_nan=True)
    assert np.array_equal(R.render_swatch(lam, size=size), swatch)
    # and the kept directions are the right ones: Lambert's cosine law, as above
    inside, n = _pixel_normals(size)
    t, p = math.radians(40.0), math.radians(30.0)
    cos = np.clip(n @ [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)],
                  0.0, None)
    np.testing.assert_allclose(sphere[inside], np.asarray(ALBEDO) / math.pi * cos[inside][:, None],
                               rtol=1e-6, atol=1e-9)


def _long_axis_deg(img: np.ndarray) -> float:
    """Orientation (degrees in [0, 180), counter-clockwise from image right) of the bright
    region's principal axis, from intensity-weighted second moments."""
    lum = np.nan_to_num(img).sum(axis=-1)  # a sphere's background is NaN
    w = np.clip(lum - 0.5 * lum.max(), 0.0, None)  # the highlight: above half its peak
    size = img.shape[0]
    c = np.arange(size) - (size - 1) / 2
    x, y = np.meshgrid(c, -c)
    m = w.sum()
    mx, my = (w * x).sum() / m, (w * y).sum() / m
    cxx = (w * (x - mx) ** 2).sum() / m
    cyy = (w * (y - my) ** 2).sum() / m
    cxy = (w * (x - mx) * (y - my)).sum() / m
    return math.degrees(0.5 * math.atan2(2 * cxy, cxx - cyy)) % 180.0


def _angle_diff(a: float, b: float) -> float:
    return abs((a - b + 90.0) % 180.0 - 90.0)


@pytest.mark.parametrize("beta", [0.0, 30.0, 75.0, 120.0])
def test_rotated_anisotropic_highlight_turns_with_the_material(beta: float) -> None:
    # Smooth along x, rough along y: the flash highlight is long along the material's y
    # axis, i.e. at 90 deg + beta in the image once the specimen is turned by beta.
    ggx = bm.GGX(alpha_x=0.08, alpha_y=0.35, fresnel=bm.SchlickFresnel((0.9, 0.9, 0.9)))
    img = R.render_swatch(ggx, size=128, rotation_deg=beta)
    assert _angle_diff(_long_axis_deg(img), 90.0 + beta) < 2.0
    # Turning the model itself (an independent path: models.Rotated) gives the same picture.
    turned = R.render_swatch(bm.Rotated(ggx, math.radians(beta)), size=128)
    np.testing.assert_allclose(turned, img, rtol=1e-9, atol=1e-12)


def test_rotated_table_highlight_turns_on_the_sphere_too() -> None:
    ggx = bm.GGX(alpha_x=0.1, alpha_y=0.4, fresnel=bm.SchlickFresnel((0.9, 0.9, 0.9)))
    table = bm.tabulate(ggx)
    flat = R.render_swatch(table, size=96)
    turned = R.render_swatch(table.rotated(math.radians(45.0)), size=96)
    assert _angle_diff(_long_axis_deg(flat), 90.0) < 4.0
    assert _angle_diff(_long_axis_deg(turned), 135.0) < 4.0
    light = R.PointLight(0.0, 0.0)  # light at the view: highlight at the sphere's centre
    a = _long_axis_deg(R.render_sphere(table, light, size=96))
    b = _long_axis_deg(R.render_sphere(table, light, size=96, rotation_deg=45.0))
    assert _angle_diff(a, 90.0) < 5.0 and _angle_diff(b, 135.0) < 5.0


def test_table_lookup_matches_brdftable_eval() -> None:
    table = bm.tabulate(bm.LobeSum((bm.Lambert(0.3), bm.GGX(alpha_x=0.1, alpha_y=0.3))))
    rng = np.random.default_rng(3)

    def dirs(n: int) -> np.ndarray:
        v = rng.normal(size=(n, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    wi, wo = dirs(4000), dirs(4000)  # half of them below the horizon
    ref = np.nan_to_num(table.eval(wi, wo))
    np.testing.assert_allclose(R.TableLookup(table, "multilinear").eval(wi, wo), ref,
                               rtol=1e-5, atol=1e-6)


def test_srgb_transfer_and_exposure() -> None:
    # IEC 61966-2-1: linear 0.5 -> 0.7354 -> 188; 0.002 is on the linear toe (x 12.92).
    img = np.array([[[0.0, 0.5, 1.0], [0.002, 2.0, np.nan]]])
    out = R.to_srgb(img, exposure=1.0, background=(1, 2, 3))
    assert out[0, 0].tolist() == [0, 188, 255]
    assert out[0, 1].tolist() == [1, 2, 3]  # a NaN pixel is background
    assert R.to_srgb(np.array([[[0.002, 0.0, 0.0]]]), 1.0)[0, 0, 0] == round(0.002 * 12.92 * 255)
    assert R.exposure_for([np.array([[[1.0, 4.0, np.nan]]]), np.array([[[2.0, 0, 0]]])]) == 0.25


def test_environment_lights_a_diffuse_sphere_evenly_bright_on_top() -> None:
    img = R.render_sphere_env(bm.Lambert(0.5), size=64)
    lum = np.nan_to_num(img.sum(axis=-1))
    # The studio's sky and softboxes are above (image +y), its floor below.
    assert lum[8:24, 24:40].mean() > 2 * lum[44:58, 24:40].mean()
    assert np.isfinite(img[32, 32]).all() and np.isnan(img[0, 0]).all()


def test_figure_has_full_size_views_and_one_row_per_material() -> None:
    png = R.figure_png([("paper", bm.Lambert(0.7)), ("brushed", bm.GGX(0.1, 0.4))], size=96,
                       title="t")
    im = Image.open(io.BytesIO(png))
    assert im.width >= len(R.DEFAULT_VIEWS) * 96 and im.height >= 2 * 96
    with pytest.raises(R.RenderError, match="at least 64"):
        R.figure_png([("paper", bm.Lambert(0.7))], size=10)
    with pytest.raises(R.RenderError, match="at least one material"):
        R.figure_png([], size=96)


def test_labels_break_between_words_and_cut_only_a_word_too_long_for_a_line() -> None:
    def chars(t: str) -> float:  # a monospace font of 10 pixels per character
        return 10.0 * len(t)

    # "reconstruction" (14 characters) in a 140-pixel column stays whole; it was cut after
    # 13 characters whatever the column's width.
    assert R.label_lines("reconstruction (job 3)", chars, 140) == "reconstruction\n(job 3)"
    assert R.label_lines("truth", chars, 140) == "truth"
    assert R.label_lines("a b c", chars, 30) == "a b\nc"
    # A word wider than the column is cut at the column's width.
    assert R.label_lines("abcdefgh", chars, 30) == "abc\ndef\ngh"


def test_the_label_column_widens_for_the_longest_word() -> None:
    from io import BytesIO

    from PIL import Image, ImageFont

    short = R.figure_png([("paper", bm.Lambert(0.7))], size=96)
    name = "mi-blend-brushed-Al"  # a material's name: one word, wider than the column
    long = R.figure_png([(name, bm.Lambert(0.7))], size=96)
    w_short = Image.open(BytesIO(short)).size[0]
    w_long = Image.open(BytesIO(long)).size[0]
    # The column grew by what the word needs beyond it (the figure's 12-pixel font at 96).
    need = ImageFont.load_default(size=12).getlength(name)
    assert w_long - w_short == pytest.approx(need - 7 * 12, abs=1.0), (w_long, w_short, need)
