"""How a BRDF looks: standard renderings and their HDR-FLIP difference (issue 23 item 1).

``log_rmse`` (:mod:`gonio.brdf.tables.metrics`) weighs every cell of the hemispheres alike;
a picture is dominated by the specular highlight, which covers few cells. A reconstruction that
is good on the table can still lose a highlight's height or shape. This module is the one
implementation of "what it looks like" that the benches and the exports share:

* :data:`APPEARANCE_VIEWS`: the unit sphere seen orthographically along the normal at its
  centre, the holder mark (specimen ``x``) running left-right over the front (the conventions
  of :mod:`gonio.brdf.pictures.render`), under four directional lights at 20, 55, 55 and 70
  degrees from the view. The azimuths (135, 0, 90, 45 degrees in the image) put the two 55
  degree lights along and across the holder mark, so a brushed highlight stretches one way
  under one and the other way under the other; the 70 degree light on the diagonal breaks the
  mirror symmetry of an aligned specimen.
* :func:`render_appearance`: linear radiance images of a BRDF in those views, a table looked
  up with gonio's own multilinear lookup (:class:`~gonio.brdf.pictures.render.TableLookup`),
  a model through its ``eval``.
* :func:`rendered_flip`: HDR-FLIP (Andersson et al. 2021, the ``flip-evaluator`` package) of a
  test against a reference, per image and mean: 0 = identical, 1 = as different as can be;
  averaged over every pixel of an image, or over the pixels a view draws (``drawn``).
* :func:`standard_flip`: the appearance metric itself, HDR-FLIP of two sets of standard
  renderings averaged **over the sphere's pixels** (its disc, lit or not), as issue 23 defines
  it. Averaged over the whole square image instead, the black background around the disc
  (a quarter of the pixels, where both images are 0) dilutes every number; the benches
  used that whole-image mean until 2026-11-27 (docs/science.md section 7 says which tables).
* :func:`render_importance`: how many pixels of those renderings look up each cell of gonio's
  grid, the weights a design can give the cells a picture sees (docs/science.md 7.2.2).

Exposure: both images of a view are divided by the reference's brightest pixel over all views,
so FLIP sees them as a viewer would side by side (one exposure for the whole set). HDR-FLIP is
not symmetric: flip-evaluator's README and the paper (Sec. 5) take the range of exposures it
tone-maps at from the *reference* image, and the exposure above is the reference's too, so
``rendered_flip(a, b)`` and ``rendered_flip(b, a)`` differ in general; always pass the truth as
the reference.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.pictures import render
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

APPEARANCE_LIGHTS: tuple[render.PointLight, ...] = (
    render.PointLight(20.0, 135.0),
    render.PointLight(55.0, 0.0),
    render.PointLight(55.0, 90.0),
    render.PointLight(70.0, 45.0),
)
"""Directional lights of the standard renderings (polar angle from the view, image azimuth)."""
APPEARANCE_VIEWS: tuple[render.View, ...] = tuple(
    render.View("sphere", lt) for lt in APPEARANCE_LIGHTS)
"""The standard renderings: the sphere under each of :data:`APPEARANCE_LIGHTS`."""
APPEARANCE_SIZE = 96
"""Pixels per side of a standard rendering: the sphere's 1 pixel spans about 1.2 degrees of
normal at its centre, finer than the 5 degree table holds."""


class AppearanceError(ValueError):
    """Images that cannot be compared (different counts or shapes, no flip-evaluator)."""


def flip_module() -> Any:
    """The ``flip_evaluator`` module, or None when it is not installed."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    return flip_evaluator


@functools.cache
def _openmp_controller() -> Any:
    """threadpoolctl's controller of the libraries loaded once flip-evaluator is (its OpenMP
    runtime among them; scanning the loaded libraries takes ~10 ms, so once per process)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def render_appearance(brdf: Any, views: tuple[render.View, ...] = APPEARANCE_VIEWS,
                      size: int = APPEARANCE_SIZE) -> list[FloatArray]:
    """Linear radiance images of ``brdf`` in ``views``.

    Parameters
    ----------
    brdf : BRDFTable (looked up multilinearly on its grid), anything with ``eval(wi, wo)``
        returning (N, C) values in 1/sr, or a :func:`~gonio.brdf.pictures.render.evaluator`
    views : tuple of View
    size : int, pixels per side

    Returns
    -------
    list of (size, size, 3) float arrays, ``sum f cos(theta_i) E`` per pixel for irradiance
    ``E = 1`` (units of the BRDF, 1/sr for a calibrated one); 0 outside the sphere.
    """
    f = render.evaluator(brdf)
    return [np.nan_to_num(render.render_view(f, v, size)) for v in views]


@dataclass(frozen=True)
class FlipResult:
    """HDR-FLIP of a test set of images against a reference set.

    Attributes
    ----------
    per_image : list of float
        Mean HDR-FLIP over each image's pixels (or the pixels its view draws), in [0, 1], in
        the order of the views.
    mean : float
        Mean of ``per_image``.
    """

    per_image: list[float]
    mean: float


def _check_pairs(reference: list[FloatArray], test: list[FloatArray]) -> None:
    if len(reference) != len(test) or not reference:
        raise AppearanceError(
            f"cannot compare {len(test)} test images with {len(reference)} reference images; "
            "render both with the same views")
    for k, (r, t) in enumerate(zip(reference, test, strict=True)):
        if r.shape != t.shape or r.ndim != 3 or r.shape[-1] != 3:
            raise AppearanceError(
                f"image {k}: reference {r.shape} and test {t.shape} must both be (H, W, 3)")


def reference_peak(reference: list[FloatArray]) -> float:
    """The brightest reference pixel over all images (1 when all are black): the exposure."""
    peak = max(float(np.max(r)) for r in reference)
    return peak if peak > 0 and np.isfinite(peak) else 1.0


def drawn_masks(views: tuple[render.View, ...] = APPEARANCE_VIEWS,
                size: int = APPEARANCE_SIZE) -> list[NDArray[np.bool_]]:
    """(size, size) bool per view: the pixels it draws (:func:`render.drawn_mask`)."""
    return [render.drawn_mask(v, size) for v in views]


def rendered_flip(reference: list[FloatArray], test: list[FloatArray],
                  drawn: list[NDArray[np.bool_]] | None = None) -> FlipResult:
    """Per-image and mean HDR-FLIP of ``test`` against ``reference`` (module docstring).

    Parameters
    ----------
    reference, test : lists of (H, W, 3) linear radiance images of the same views (e.g. from
        :func:`render_appearance`); negative values are clipped to 0.
    drawn : list of (H, W) bool, optional
        Per image, the pixels to average the error map over (:func:`drawn_masks`); None:
        every pixel. HDR-FLIP itself always sees the whole image (its filters and its range
        of exposures); only the average is restricted.

    Returns
    -------
    FlipResult

    Raises
    ------
    AppearanceError
        When the lists differ in length or shapes, or flip-evaluator is not installed.
    """
    _check_pairs(reference, test)
    if drawn is not None:
        if len(drawn) != len(reference):
            raise AppearanceError(f"{len(drawn)} pixel masks for {len(reference)} images; "
                                  "give one per image")
        for k, (m, r) in enumerate(zip(drawn, reference, strict=True)):
            if m.shape != r.shape[:2] or not m.any():
                raise AppearanceError(f"image {k}: its pixel mask {m.shape} must be the "
                                      f"image's {r.shape[:2]} and select some pixels")
    flip = flip_module()
    if flip is None:
        raise AppearanceError("HDR-FLIP needs the flip-evaluator package: "
                              "pip install flip-evaluator")
    peak = reference_peak(reference)
    per: list[float] = []
    # One OpenMP thread: flip-evaluator's threads spin-wait, and on a shared 2-core machine
    # four 96 pixel images took 0.9-2.5 s of CPU on its default two threads against 0.33 s
    # on one, with the same result (docs/export.md, "What the fits cost").
    with _openmp_controller().limit(limits=1, user_api="openmp"):
        for k, (r, t) in enumerate(zip(reference, test, strict=True)):
            error_map, mean, _ = flip.evaluate(
                np.ascontiguousarray(np.clip(np.nan_to_num(r) / peak, 0, None),
                                     dtype=np.float32),
                np.ascontiguousarray(np.clip(np.nan_to_num(t) / peak, 0, None),
                                     dtype=np.float32),
                "HDR", applyMagma=False)
            if drawn is not None:
                err = np.asarray(error_map, dtype=float).reshape(r.shape[:2])
                mean = float(np.mean(err[drawn[k]]))
            per.append(float(mean))
    return FlipResult(per, float(np.mean(per)))


def standard_flip(reference: list[FloatArray], test: list[FloatArray]) -> FlipResult:
    """The appearance metric: HDR-FLIP of two sets of standard renderings
    (:func:`render_appearance` with the default views and size), averaged over the sphere's
    pixels (:func:`drawn_masks`; module docstring).

    Raises
    ------
    AppearanceError
        When the images are not the standard renderings' count and size, or as
        :func:`rendered_flip`.
    """
    _check_pairs(reference, test)
    want = (len(APPEARANCE_VIEWS), APPEARANCE_SIZE)
    if (len(reference), reference[0].shape[0]) != want:
        raise AppearanceError(
            f"standard_flip compares the {want[0]} standard renderings of {want[1]} pixels; "
            f"got {len(reference)} images of {reference[0].shape[0]}: use rendered_flip for "
            "other views")
    return rendered_flip(reference, test, drawn_masks())


def appearance_flip(reference: Any, test: Any, ref_images: list[FloatArray] | None = None
                    ) -> FlipResult:
    """HDR-FLIP of two BRDFs in the standard renderings (:data:`APPEARANCE_VIEWS`), averaged
    over the sphere's pixels (:func:`standard_flip`).

    ``ref_images`` (from :func:`render_appearance` of ``reference``) saves rendering the
    reference again when many tests are compared with one truth.
    """
    ref = ref_images if ref_images is not None else render_appearance(reference)
    return standard_flip(ref, render_appearance(test))


class _CellCounter:
    """An ``eval(wi, wo)`` that renders black and counts which grid cells it was asked for.

    Each asked direction pair adds its multilinear (trilinear over th, td, pd) weights to the
    eight surrounding grid nodes: a smooth share of attention per cell, not the weights of the
    lookup the pictures render with (log-pchip by default), which reaches further nodes.
    """

    def __init__(self) -> None:
        self.counts = np.zeros(geo.N_ROWS)

    def eval(self, wi: FloatArray, wo: FloatArray) -> FloatArray:
        th, _ph, td, pd = geo.directions_to_half_diff(wi, wo)
        axes = []
        for x, n, wrap in ((th, geo.N_TH, False), (td, geo.N_TD, False), (pd, geo.N_PD, True)):
            u = np.asarray(x, dtype=float) / geo.STEP
            lo = np.floor(u).astype(np.intp)
            frac = u - lo
            if wrap:  # pd is periodic over 180 deg: past the last node comes the first
                lo, hi = np.mod(lo, n), np.mod(lo + 1, n)
            else:  # past the last node (85 deg) the lookup holds the last node's value
                hi = np.minimum(lo + 1, n - 1)
                lo = np.minimum(lo, n - 1)
            axes.append((lo, hi, frac))
        for idx, w in geo.lattice_corners(axes):
            self.counts += np.bincount(geo.flat_row(*idx), weights=w, minlength=geo.N_ROWS)
        return np.zeros((np.asarray(wi).shape[0], 3))


def render_importance(views: tuple[render.View, ...] = APPEARANCE_VIEWS,
                      size: int = APPEARANCE_SIZE) -> FloatArray:
    """How many pixels of the standard renderings look up each cell of gonio's grid.

    Every lit pixel of a sphere view under a point light is one ``(wi, wo)`` pair (the same
    pairs :func:`render_appearance` evaluates, taken from the same renderer); it counts 1,
    shared among the eight ``(th, td, pd)`` nodes around it by their multilinear weights (how
    a lookup between nodes blends them). ``ph`` is summed over: a specimen sits at any
    holder angle, so the renderings see every ``ph`` of a cell alike on average. This is the
    map of the grid the pictures (and so HDR-FLIP) look at; the expected-error design can weigh
    cells by it (:func:`gonio.brdf.design.posterior.posterior_design`'s ``cell_weight``).

    Parameters
    ----------
    views : tuple of View
        Sphere views under point lights (other kinds count their lookups alike).
    size : int, pixels per side

    Returns
    -------
    (18, 18, 36) float64, pixel counts per ``(th, td, pd)`` node, summed over the views (the
    total is the number of lit pixels).
    """
    counter = _CellCounter()
    for v in views:
        render.render_view(counter, v, size)
    return counter.counts.reshape(geo.SLICE_SHAPE)
