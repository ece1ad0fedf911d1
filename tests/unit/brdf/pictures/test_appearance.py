"""The appearance metric (issue 23 item 1): standard renderings and their HDR-FLIP."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.models.principled import Principled
from gonio.brdf.pictures import appearance, render
from gonio.brdf.tables.table import BRDFTable

pytest.importorskip("flip_evaluator")

PLASTIC = Principled((0.45, 0.20, 0.10), 0.0, 0.5, 0.13, 0.13, 0.0).model()  # roughness 0.36


class HalfVectorLobe:
    """A test-side lobe: ``exp(-(theta_h / width)^2)`` with ``theta_h`` the half vector's angle
    from the normal; its highlight on a sphere sits where the normal is the half vector of the
    light and the view."""

    channels = ("R", "G", "B")
    name = "half-vector lobe"
    isotropic = True

    def __init__(self, width_deg: float) -> None:
        self.width = math.radians(width_deg)

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        h = np.asarray(wi) + np.asarray(wo)
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        th = np.arccos(np.clip(h[..., 2], -1, 1))
        v = np.exp(-(th / self.width) ** 2)
        v = np.where((np.asarray(wi)[..., 2] > 0) & (np.asarray(wo)[..., 2] > 0), v, 0.0)
        return np.repeat(v[..., None], 3, axis=-1)


def test_identical_images_have_zero_flip_and_a_known_perturbation_grows_it() -> None:
    table = bm.tabulate(PLASTIC, np.float64)
    ref = appearance.render_appearance(table)
    assert len(ref) == len(appearance.APPEARANCE_VIEWS) == 4
    same = appearance.rendered_flip(ref, ref)
    assert same.mean == pytest.approx(0.0, abs=1e-7)
    assert same.per_image == pytest.approx([0.0] * 4, abs=1e-7)
    # A brighter copy of the same material: a growing exposure error must read as a growing
    # difference, in every view.
    scores = []
    for scale in (1.05, 1.3, 2.0, 4.0):
        scaled = BRDFTable(np.asarray(table.values) * scale, table.channels, "scaled")
        scores.append(appearance.appearance_flip(table, scaled, ref))
    means = [s.mean for s in scores]
    assert 0 < means[0] < means[1] < means[2] < means[3] <= 1
    for a, b in itertools.pairwise(scores):
        assert all(pa < pb for pa, pb in zip(a.per_image, b.per_image, strict=True))


def test_flip_is_not_symmetric_as_flip_evaluator_documents() -> None:
    """HDR-FLIP takes its exposures from the reference, so swapping the arguments changes it."""
    table = bm.tabulate(PLASTIC, np.float64)
    a = appearance.render_appearance(table)
    b = [2.0 * im for im in a]
    ab, ba = appearance.rendered_flip(a, b).mean, appearance.rendered_flip(b, a).mean
    assert ab > 0 and ba > 0
    assert abs(ab - ba) > 1e-3 * max(ab, ba)


@pytest.mark.parametrize("light", appearance.APPEARANCE_LIGHTS[1:], ids=lambda lt: lt.label())
@pytest.mark.parametrize("tabulated", [False, True], ids=["model", "table lookup"])
def test_the_highlight_sits_where_the_half_vector_puts_it(light: render.PointLight,
                                                          tabulated: bool) -> None:
    lobe = HalfVectorLobe(6.0)
    brdf = bm.tabulate(lobe, np.float64) if tabulated else lobe  # type: ignore[arg-type]
    size = appearance.APPEARANCE_SIZE
    img = appearance.render_appearance(brdf, (render.View("sphere", light),))[0]
    lum = img.sum(axis=-1)
    row, col = np.unravel_index(int(np.argmax(lum)), lum.shape)
    # Orthographic unit sphere: the pixel whose normal is h = (l + v) / |l + v| is at image
    # (x, y) = (h_x, h_y); pixel centres are at ((k + 0.5) / size * 2 - 1) * (1 + 2 / size).
    t, p = math.radians(light.theta_deg), math.radians(light.phi_deg)
    h = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), 1 + math.cos(t)])
    h /= np.linalg.norm(h)
    scale = 1.0 + 2.0 / size
    col_expected = ((h[0] / scale) + 1) / 2 * size - 0.5
    row_expected = ((-h[1] / scale) + 1) / 2 * size - 0.5
    # The cos(theta_i) factor moves the peak a little towards the light; the table's 5 degree
    # cells move it by at most about half a cell (2.5 degrees: 2 pixels at this size).
    tol = 3.0 if tabulated else 1.5
    assert abs(col - col_expected) <= tol and abs(row - row_expected) <= tol


def test_mismatched_image_sets_are_refused_with_a_reason() -> None:
    a = [np.zeros((8, 8, 3))]
    with pytest.raises(appearance.AppearanceError, match="same views"):
        appearance.rendered_flip(a, a * 2)
    with pytest.raises(appearance.AppearanceError, match=r"\(H, W, 3\)"):
        appearance.rendered_flip(a, [np.zeros((8, 9, 3))])


@pytest.mark.parametrize("size", [48, 96])
def test_the_sphere_views_draw_the_disc_and_the_swatch_every_pixel(size: int) -> None:
    # The disc of radius 1 / (1 + 2 / size) in an image of side 2: its share of the pixels is
    # pi / 4 / (1 + 2 / size)^2, up to the pixels its edge cuts (a few per cent at 48 pixels).
    share = math.pi / 4 / (1 + 2 / size) ** 2
    for view in (*appearance.APPEARANCE_VIEWS, render.View("environment")):
        mask = render.drawn_mask(view, size)
        assert mask.shape == (size, size)
        assert mask.mean() == pytest.approx(share, rel=0.03)
        assert not mask[0].any() and not mask[:, 0].any()  # the one-pixel margin
    assert render.drawn_mask(render.View("swatch", render.PointLight(0.0, 0.0)), size).all()
    # Every pixel a sphere rendering lights lies in the disc.
    img = appearance.render_appearance(bm.tabulate(PLASTIC, np.float64))[0]
    disc = render.drawn_mask(appearance.APPEARANCE_VIEWS[0], appearance.APPEARANCE_SIZE)
    assert not (img.sum(axis=-1) > 0)[~disc].any()


def test_the_standard_flip_averages_flip_evaluators_error_map_over_the_disc() -> None:
    """The reference is flip-evaluator's own error map, averaged by hand over the disc."""
    import flip_evaluator

    table = bm.tabulate(PLASTIC, np.float64)
    ref = appearance.render_appearance(table)
    test = appearance.render_appearance(
        BRDFTable(np.asarray(table.values) * 1.5, table.channels, "brighter"))
    got = appearance.standard_flip(ref, test)
    whole = appearance.rendered_flip(ref, test)
    peak = max(float(r.max()) for r in ref)
    for k, (r, t) in enumerate(zip(ref, test, strict=True)):
        err, whole_mean, _ = flip_evaluator.evaluate(
            np.ascontiguousarray(r / peak, dtype=np.float32),
            np.ascontiguousarray(t / peak, dtype=np.float32), "HDR", applyMagma=False)
        err = np.asarray(err).reshape(r.shape[:2])
        disc = render.drawn_mask(appearance.APPEARANCE_VIEWS[k], appearance.APPEARANCE_SIZE)
        assert got.per_image[k] == pytest.approx(float(err[disc].mean()), rel=1e-5)
        assert whole.per_image[k] == pytest.approx(float(whole_mean), rel=1e-5)
        # The background only dilutes: both images are black there, and the filters' spill
        # over the silhouette is the only error outside the disc.
        assert got.per_image[k] > whole.per_image[k]
    assert got.mean == pytest.approx(float(np.mean(got.per_image)))


def test_pixel_masks_and_image_sets_that_do_not_fit_are_refused_with_a_reason() -> None:
    table = bm.tabulate(PLASTIC, np.float64)
    ref = appearance.render_appearance(table)
    masks = appearance.drawn_masks()
    with pytest.raises(appearance.AppearanceError, match="one per image"):
        appearance.rendered_flip(ref, ref, masks[:2])
    with pytest.raises(appearance.AppearanceError, match="image 1: its pixel mask"):
        appearance.rendered_flip(ref, ref, [masks[0], masks[1][:10], *masks[2:]])
    with pytest.raises(appearance.AppearanceError, match="select some pixels"):
        appearance.rendered_flip(ref, ref, [masks[0], np.zeros_like(masks[1]), *masks[2:]])
    small = appearance.render_appearance(table, size=48)
    with pytest.raises(appearance.AppearanceError, match="use rendered_flip for other views"):
        appearance.standard_flip(small, small)
    with pytest.raises(render.RenderError, match="unknown view kind"):
        render.drawn_mask(render.View("cylinder"))


def test_the_drawn_masks_are_the_pixels_the_renderer_draws() -> None:
    """Against the renderer itself: ``render_view`` leaves NaN where it draws nothing."""
    f = render.evaluator(bm.tabulate(PLASTIC, np.float64))
    size = 48
    for view in (*appearance.APPEARANCE_VIEWS, render.View("environment"),
                 render.View("swatch", render.PointLight(30.0, 0.0))):
        drawn = np.isfinite(render.render_view(f, view, size)).all(axis=-1)
        np.testing.assert_array_equal(render.drawn_mask(view, size), drawn)
