"""Fits judged by what they render: the rendered difference of a model from a BRDF table, and a
principled fit that minimises a rendered error.

A fit's error on the BRDF table (``log_rmse`` and friends) weighs every cell of the hemispheres
alike; a rendering is dominated by the specular highlight, which covers few cells. A principled
fit that is good on the table can lose a plastic's gloss or a metal's brightness (issue 26), and
its table error does not show it. So:

* :func:`rendered_difference` renders the reference and the model, both as tables on gonio's
  5 degree grid (:func:`on_grid`), in the same scenes with :mod:`gonio.brdf.pictures.render`
  (:data:`JUDGE_VIEWS`: the sphere under three point lights and the flat swatch under a
  flash, :data:`JUDGE_SIZE` pixels) and compares the images with
  HDR-FLIP (Andersson et al. 2021, the ``flip-evaluator`` package; the mean over pixels and
  views, 0 = identical, 1 = as different as can be) when it is installed, and always with the
  relative image error ``sum |model - ref| / sum |ref|`` (L1 over all pixels and channels).
  ``metric`` says which number is the headline.
* :func:`fit_principled_rendered` refines a principled fit on renderings: the residuals are
  ``sqrt(L_model / peak + eps) - sqrt(L_ref / peak + eps)`` per pixel and channel of
  :data:`FIT_VIEWS` (``peak`` the view's brightest reference pixel, ``eps = 1e-3``): the
  square root compresses like a display does, so the highlight's size, height and colour and
  the diffuse colour all count. Three candidates are fitted: metallic fixed at 0 (dielectric:
  a Lambert base under a specular layer of level ``0.08 specular`` in [0.02, 0.9], index of
  refraction 1.33 to 37.9, and weight in [0, 1], :data:`SPECULAR_MIN`, :data:`WEIGHT_MIN`;
  the layer reflects ``weight x level`` at normal incidence and ``weight`` at grazing angles,
  glTF's ``KHR_materials_specular``, so a diffuse colour under a bright white highlight, a
  coated or dusty metal, is a dielectric too), fixed at 1 (metal: ``F0`` = base colour, no
  diffuse), and fitted in [0, 1] (a blend, the dielectric part bounded as above). The
  better pure one is kept unless the blend's rendered difference is below
  :data:`BLEND_MARGIN` times its own: a real surface is one or the other
  (Burley 2012 keeps in-between values for blends, e.g. a metal under dirt or a diffuse
  layer), and a fractional metallic that does not clearly render better is a fitting artefact:
  fitted to a reconstruction of a brushed copper it was 0.97-0.998, which added a diffuse glow
  where the truth is black, and, with ``specular`` near 0, an index of refraction of 1.0003.
  The table-space fit itself, made pure (:func:`pure`), is judged beside them and kept when it
  renders closer than the refined candidates (a reconstruction with a spurious sharp spike
  drew the rendered fit onto the spike: a Beckmann copper, bench/bench_export.py). Last, the
  best pure candidate is refined once more on images blurred by :data:`BLUR_PX` pixels and
  replaces it when it renders clearly closer (:data:`BLUR_MARGIN`). Then the chosen
  candidate, when it renders farther than :data:`POLISH_ABOVE` from the table, is polished
  by Nelder-Mead on the HDR-FLIP of its renderings itself (:func:`_polish_flip`,
  :data:`POLISH_NFEV`) and replaced when that renders clearly closer
  (:data:`POLISH_MARGIN`): the square-root residuals settle where HDR-FLIP does not (a
  diffuse + brushed-aluminium blend: 0.365 from its truth, against 0.18 for the polished
  material; docs/export.md).
* :func:`fit_f82` adds OpenPBR's F82 tint per channel to a metal's fit (the
  ``open_pbr_surface`` of the MaterialX export; glTF has no such term, so the glTF and
  ``standard_surface`` keep the fit above). The tint is fitted on the table
  (:func:`gonio.brdf.models.principled.fit_f82_tint`), the other parameters held: the
  judge's views cannot see it (their light-view angles are at most 55 degrees, where the
  correction is at most 3.3e-5 of the dip at 82 degrees). It is kept when it lowers the
  table's ``log_rmse`` and the rendered difference is not above the Schlick fit's by more
  than :data:`F82_RENDER_SLACK`.
* An export warns (:func:`gonio.export.fit_warnings`) when the factored model's rendered
  difference is less than the principled one's over :data:`TWO_LOBE_RATIO`: a diffuse colour
  under a coloured highlight of another hue, or two highlights (two lobes), is out of reach of
  one principled material.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.models import analytic as bm
from gonio.brdf.models.factored import fit_metrics
from gonio.brdf.models.principled import ALPHA_MAX, ALPHA_MIN, Principled, fit_f82_tint
from gonio.brdf.pictures import appearance, render
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]

JUDGE_VIEWS: tuple[render.View, ...] = (
    *(render.View("sphere", lt) for lt in render.DEFAULT_SPHERE_LIGHTS),
    render.View("swatch", render.PointLight(0.0, 0.0)),
)
"""Scenes of the rendered difference: the preview's point-light views (the environment view
is left out: it costs a hundred lookups per pixel and shows the same lobes blurred)."""
JUDGE_SIZE = 96
"""Pixels per side of the judged images."""
FIT_VIEWS = JUDGE_VIEWS
FIT_SIZE = 48
"""Pixels per side of the images the rendered fit compares (the 5 degree table holds no
finer detail on a 48 pixel sphere)."""
#: Rendered difference (the headline metric) above which an export warns. A good principled
#: fit of a simulated brushed-metal scan differs from its reconstruction by HDR-FLIP 0.19 (the
#: reconstruction's own noise and ringing, which the model rightly leaves out; it is closer to
#: the truth than the reconstruction is); a fit that misses the lobe (brushed-metal-004) by
#: 0.52 (bench/bench_export.py --rendered, docs/export.md).
WARN_FLIP = 0.25
WARN_RELATIVE = 0.5
#: Dielectric specular bounds: F0 = 0.08 specular in [0.02, 0.9]. The lower bound keeps the
#: index of refraction at least 1.33 (a fit reached 1.0003, issue 26). Above Burley's F0 = 0.08
#: (IOR 1.79) the dielectric stands for a diffuse colour under a bright highlight (a coated or
#: dusty metal); glTF writes F0 up to 1 (``KHR_materials_specular``) and MaterialX through
#: ``specular_IOR``, which is infinite at F0 = 1: 0.9 keeps it at 37.9.
SPECULAR_MIN, SPECULAR_MAX = 0.25, 0.9 / 0.08
#: Lower bound of the dielectric's specular weight (glTF ``specularFactor``, MaterialX
#: ``specular``; the reflectance at grazing angles), whose range in both formats is [0, 1].
WEIGHT_MIN = 0.0
#: HDR-FLIP (or relative image error) by which the F82-tinted fit may render farther from the
#: table than the Schlick fit in the judge's views (where the tint changes the Fresnel factor
#: by at most 3.3e-5 of its dip; what is left is the lookup's blending of grid cells, which
#: reaches a few wider cells: 0.001 on a tinted metal's own table, test_fit_f82.py).
F82_RENDER_SLACK = 1e-3
_EPS = 1e-3


def flip_available() -> bool:
    """Whether HDR-FLIP (the ``flip-evaluator`` package) is installed."""
    return appearance.flip_module() is not None


def render_views(brdf: Any, views: tuple[render.View, ...] = JUDGE_VIEWS,
                 size: int = JUDGE_SIZE) -> list[FloatArray]:
    """Linear radiance images (size, size, 3) of ``brdf`` in ``views``, background 0
    (:func:`gonio.brdf.pictures.appearance.render_appearance`)."""
    return appearance.render_appearance(brdf, views, size)


@dataclass(frozen=True)
class RenderedDifference:
    """How different two BRDFs look in :data:`JUDGE_VIEWS`.

    Attributes
    ----------
    metric : str
        ``"HDR-FLIP"`` or ``"relative image error"``: which number ``value`` is.
    value : float
        The headline difference (``flip`` when available, else ``relative``).
    flip : float or None
        Mean HDR-FLIP over pixels and views, in [0, 1]; None without ``flip-evaluator``.
    relative : float
        ``sum |test - ref| / sum |ref|`` over all pixels, channels and views.
    per_view : list of float
        The headline metric per view, in the order of :data:`JUDGE_VIEWS`.
    """

    metric: str
    value: float
    flip: float | None
    relative: float
    per_view: list[float]

    @property
    def large(self) -> bool:
        """Above the warning threshold (:data:`WARN_FLIP` or :data:`WARN_RELATIVE`)."""
        return self.value > (WARN_FLIP if self.flip is not None else WARN_RELATIVE)

    def as_dict(self) -> dict[str, Any]:
        return {
            "metric": self.metric, "value": self.value, "flip": self.flip,
            "relative_image_error": self.relative, "per_view": self.per_view,
            "views": [v.title() for v in JUDGE_VIEWS], "size_px": JUDGE_SIZE,
            "meaning": "difference of renderings of the fitted model and of the reconstructed "
                       "BRDF (sphere under three point lights, swatch under a flash): "
                       "HDR-FLIP mean (0 identical, 1 maximal) when flip-evaluator is "
                       "installed, else sum|model-ref|/sum|ref|",
        }


def difference_of_images(ref: list[FloatArray], test: list[FloatArray]) -> RenderedDifference:
    """:class:`RenderedDifference` of two lists of linear images of the same views.

    HDR-FLIP is :func:`gonio.brdf.pictures.appearance.rendered_flip`: both are scaled by one
    exposure, the reference's brightest pixel to 1, so HDR-FLIP sees them as a viewer would see
    them side by side.
    """
    num = sum(float(np.abs(t - r).sum()) for r, t in zip(ref, test, strict=True))
    den = sum(float(np.abs(r).sum()) for r in ref) or 1.0
    rel_views = [float(np.abs(t - r).sum() / max(np.abs(r).sum(), 1e-30))
                 for r, t in zip(ref, test, strict=True)]
    if not flip_available():
        return RenderedDifference("relative image error", num / den, None, num / den, rel_views)
    flip = appearance.rendered_flip(ref, test)
    return RenderedDifference("HDR-FLIP", flip.mean, flip.mean, num / den, flip.per_image)


def on_grid(model: Any) -> BRDFTable:
    """``model`` as a table on gonio's 5 degree grid (a table stays as it is)."""
    if isinstance(model, BRDFTable):
        return model
    if hasattr(model, "to_table"):  # FactoredBRDF
        return model.to_table()
    return bm.tabulate(model, np.float64)


def rendered_difference(reference: Any, model: Any,
                        ref_images: list[FloatArray] | None = None) -> RenderedDifference:
    """Rendered difference of ``model`` from ``reference`` (module docstring).

    Both are rendered from tables on gonio's 5 degree grid (:func:`on_grid`): a reconstruction
    is such a table, and its rendering interpolates between the grid's nodes, which blurs and
    facets a sharp highlight (an exact GGX model against its own table differs by HDR-FLIP
    0.02 for a plastic of roughness 0.36 and 0.10 for a brushed copper with alphas 0.30 and
    0.06); on
    the same grid that is no difference, and what remains is the model's misfit.
    ``ref_images`` (from :func:`render_views` of ``on_grid(reference)``) saves rendering the
    reference again.
    """
    ref = ref_images if ref_images is not None else render_views(on_grid(reference))
    return difference_of_images(ref, render_views(on_grid(model)))


# --------------------------------------------------------------------------- the rendered fit
#: The rendered fit's candidates: metallic fixed at 0, fixed at 1, or fitted in [0, 1].
MODES = ("dielectric", "metal", "blend")
#: A blend is kept only when it renders this much better than the better pure candidate.
BLEND_MARGIN = 0.8
#: Standard deviation (pixels of the 48 pixel fit images) of the blur of the last candidate.
#: HDR-FLIP filters both images with contrast-sensitivity functions before comparing them, so
#: a few pixels of a sharp spike weigh less in it than in a per-pixel residual. 2 and 4
#: pixels were tried on the Beckmann copper (HDR-FLIP from the truth 0.58 and 0.54 against
#: 0.70 unblurred) and on brushed-metal-003 (0.096 and 0.105 against 0.091): 2 is kept.
BLUR_PX = 2.0
#: The blurred candidate replaces the best pure one only when its rendered difference is below
#: this fraction of it. Kept whenever it rendered closer to the reconstruction at all, it
#: moved brushed-metal-004 and metal-001 at most 0.001 HDR-FLIP closer to the reconstruction
#: and up to 0.005 farther from the truth (brushed-metal-012 0.02 closer to the truth); the
#: copper's difference from the reconstruction fell by 14 %.
BLUR_MARGIN = 0.95
#: The principled export warns that it cannot show the material (and points to the factored
#: one) when its rendered difference is above the warning threshold and this many times the
#: factored model's. On bench/bench_export.py's simulated scans the two diffuse + brushed
#: conductor blends were at 2.3x and 2.9x before the free specular strength and weight,
#: every other material at most 1.35x (docs/export.md).
TWO_LOBE_RATIO = 1.5
#: HDR-FLIP evaluations (each renders :data:`FIT_VIEWS` at :data:`FIT_SIZE`) of the last
#: step, the chosen candidate polished on the rendered difference itself
#: (:func:`_polish_flip`); 0 skips it. On the Al blend's reconstruction 300 took the export
#: from 0.380 to 0.201 from the truth (docs/export.md).
POLISH_NFEV = 120
#: The polished candidate replaces the chosen one only when its rendered difference is below
#: this fraction of it. Kept whenever it rendered closer to the reconstruction at all, it took
#: brushed-metal-004 (whose reconstruction is the worst of the library rows) 1.7 % closer to
#: its reconstruction and 0.018 HDR-FLIP farther from the truth; the Al blend's came 30 %
#: closer (docs/export.md). The same fraction as :data:`BLUR_MARGIN`.
POLISH_MARGIN = 0.95
#: The polish runs only when the chosen candidate's rendered difference is above this (the
#: warning threshold :data:`WARN_FLIP`): it costs about as much as the rest of the rendered
#: fit, and a fit that renders well already gains little (the six library rows it was run on
#: came 1.7-5.7 % closer to their reconstructions). The library rows' fits are at 0.047-0.191
#: but brushed-metal-004's 0.538; the Al blend's truth fit at 0.342 (docs/export.md).
POLISH_ABOVE = WARN_FLIP


def pure(p: Principled) -> Principled:
    """``p`` made a pure dielectric or metal, as the rendered fit's candidates are.

    Metallic at least 0.5: a metal with the same ``F0`` and no diffuse; else a dielectric with
    ``specular`` clipped to [:data:`SPECULAR_MIN`, :data:`SPECULAR_MAX`].
    """
    if p.metallic >= 0.5:
        return Principled(tuple(float(v) for v in np.clip(p.f0, 0.0, 1.0)), 1.0, 0.5,
                          p.alpha_t, p.alpha_b, p.direction_deg, p.channels)
    return Principled(p.base_color, 0.0, float(np.clip(p.specular, SPECULAR_MIN, SPECULAR_MAX)),
                      p.alpha_t, p.alpha_b, p.direction_deg, p.channels,
                      specular_weight=p.specular_weight)


def _params(x: FloatArray, mode: str, nc: int, channels: tuple[str, ...]) -> Principled:
    """Principled parameters from a candidate's vector ``[base (nc), (metallic), (specular,
    specular weight), log alpha_x, log alpha_y, angle]`` (metallic only for a blend, the
    specular pair not for a metal)."""
    base = tuple(float(b) for b in np.clip(x[:nc], 0.0, 1.0))
    k = nc
    metallic = {"dielectric": 0.0, "metal": 1.0}.get(mode)
    if metallic is None:
        metallic = float(np.clip(x[k], 0.0, 1.0))
        k += 1
    specular, weight = 0.5, 1.0  # unused by a pure metal; the dielectric default (F0 = 0.04)
    if mode != "metal":
        specular = float(np.clip(x[k], SPECULAR_MIN, SPECULAR_MAX))
        weight = float(np.clip(x[k + 1], WEIGHT_MIN, 1.0))
        k += 2
    ax = float(np.clip(math.exp(x[k]), ALPHA_MIN, ALPHA_MAX))
    ay = float(np.clip(math.exp(x[k + 1]), ALPHA_MIN, ALPHA_MAX))
    direction = math.degrees(float(x[k + 2]))
    if ay > ax:  # the tangent is the rougher axis
        ax, ay, direction = ay, ax, direction + 90.0
    return Principled(base, metallic, specular, ax, ay, direction, channels,
                      specular_weight=weight)


def _fit_candidate(start: Principled, mode: str, ref: list[FloatArray],
                   max_nfev: int, blur_px: float = 0.0) -> Principled:
    """One candidate of the rendered fit (module docstring); ``blur_px`` > 0 compares the
    images after a Gaussian blur of that standard deviation (pixels of :data:`FIT_SIZE`)."""
    from scipy.ndimage import gaussian_filter
    from scipy.optimize import least_squares

    def shown(img: FloatArray) -> FloatArray:
        return gaussian_filter(img, (blur_px, blur_px, 0.0)) if blur_px > 0 else img

    nc = len(start.base_color)
    peaks = [max(float(np.max(r)), 1e-30) for r in ref]
    masks = [np.any(r > 0, axis=-1) for r in ref]
    target = np.concatenate([np.sqrt(np.maximum(shown(r)[m], 0.0) / p + _EPS).ravel()
                             for r, m, p in zip(ref, masks, peaks, strict=True)])
    base0 = np.asarray(start.f0) if mode == "metal" else np.asarray(start.base_color)
    x0_parts: list[Any] = [np.clip(base0, 0.02, 0.98)]
    lo_parts: list[Any] = [np.zeros(nc)]
    hi_parts: list[Any] = [np.ones(nc)]
    if mode == "blend":
        x0_parts.append([float(np.clip(start.metallic, 0.05, 0.95))])
        lo_parts.append([0.0])
        hi_parts.append([1.0])
    if mode != "metal":
        x0_parts.append([float(np.clip(start.specular, SPECULAR_MIN + 1e-6,
                                       SPECULAR_MAX - 1e-6)),
                         float(np.clip(start.specular_weight, WEIGHT_MIN + 1e-6, 1.0 - 1e-6))])
        lo_parts.append([SPECULAR_MIN, WEIGHT_MIN])
        hi_parts.append([SPECULAR_MAX, 1.0])
    lo_a, hi_a = math.log(ALPHA_MIN), math.log(ALPHA_MAX)
    x0_parts.append([math.log(start.alpha_t), math.log(start.alpha_b),
                     math.radians(start.direction_deg)])
    lo_parts.append([lo_a, lo_a, -np.inf])
    hi_parts.append([hi_a, hi_a, np.inf])
    x0, lo, hi = (np.concatenate([np.asarray(v, dtype=float) for v in parts])
                  for parts in (x0_parts, lo_parts, hi_parts))
    x0 = np.clip(x0, lo + 1e-9, np.where(np.isfinite(hi), hi - 1e-9, hi))

    def resid(x: FloatArray) -> FloatArray:
        imgs = render_views(_params(x, mode, nc, start.channels).model(), FIT_VIEWS, FIT_SIZE)
        pred = np.concatenate([np.sqrt(np.maximum(shown(im)[m], 0.0) / p + _EPS).ravel()
                               for im, m, p in zip(imgs, masks, peaks, strict=True)])
        return np.asarray(pred - target, dtype=float)

    r = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", max_nfev=max_nfev,
                      diff_step=1e-3)
    return _params(r.x, mode, nc, start.channels)


def _vector(p: Principled, mode: str) -> FloatArray:
    """The inverse of :func:`_params`: ``p``'s vector for candidate ``mode``."""
    parts: list[float] = [float(v) for v in (p.f0 if mode == "metal" else p.base_color)]
    if mode == "blend":
        parts.append(float(p.metallic))
    if mode != "metal":
        parts += [float(p.specular), float(p.specular_weight)]
    parts += [math.log(p.alpha_t), math.log(p.alpha_b), math.radians(p.direction_deg)]
    return np.asarray(parts, dtype=float)


def _polish_flip(start: Principled, ref: list[FloatArray], max_nfev: int) -> Principled:
    """``start`` refined by Nelder-Mead on the HDR-FLIP of its :data:`FIT_VIEWS` renderings
    against ``ref`` (those of the table), in ``start``'s own mode (metallic 0, 1 or free).

    HDR-FLIP is not smooth enough for the least-squares fit's finite differences; a simplex
    needs no gradient. The model is rendered directly, not as a table (0.01 s a view against
    0.3 s): on the Al blend, polishing against tabulated renderings gave the same rendered
    difference from the truth within 0.01 (docs/export.md).
    """
    from scipy.optimize import minimize

    mode = {0.0: "dielectric", 1.0: "metal"}.get(float(start.metallic), "blend")
    nc = len(start.base_color)

    def cost(x: FloatArray) -> float:
        imgs = render_views(_params(x, mode, nc, start.channels).model(), FIT_VIEWS, FIT_SIZE)
        return float(appearance.rendered_flip(ref, imgs).mean)

    r = minimize(cost, _vector(start, mode), method="Nelder-Mead",
                 options={"maxfev": max_nfev, "xatol": 1e-3, "fatol": 1e-4})
    return _params(np.asarray(r.x, dtype=float), mode, nc, start.channels)


def fit_principled_rendered(table: BRDFTable, start: Principled, *, max_nfev: int = 60,
                            polish_nfev: int = POLISH_NFEV
                            ) -> tuple[Principled, RenderedDifference]:
    """Refine a principled fit so that it renders like ``table`` (module docstring).

    Parameters
    ----------
    table : BRDFTable, 1/sr, three channels (other channel counts are rendered as grey and
        are returned unchanged with their difference)
    start : Principled
        The table-space fit (:func:`gonio.brdf.models.principled.fit_principled`).
    max_nfev : int
        Residual evaluations per candidate (each renders :data:`FIT_VIEWS`).
    polish_nfev : int
        HDR-FLIP evaluations of the polish (:func:`_polish_flip`); 0 skips it.

    Returns
    -------
    (Principled, RenderedDifference)
        The best of the dielectric, the metal, the pure start (:func:`pure`) and the best
        of those refined on blurred images, or the blend when it renders clearly better
        (:data:`BLEND_MARGIN`), or that polished on HDR-FLIP when it renders clearly better
        (:data:`POLISH_MARGIN`), with ``metrics``:
        the table metrics of :func:`gonio.brdf.models.factored.fit_metrics`, ``seconds``,
        ``rendered`` (:meth:`RenderedDifference.as_dict`) and ``fit`` = "rendered".
    """
    t0 = time.perf_counter()
    looked_up = render.evaluator(table)  # the table's lookup is made once for both sizes
    ref_fit = render_views(looked_up, FIT_VIEWS, FIT_SIZE)
    ref_judge = render_views(looked_up)
    if table.n_channels != 3:
        diff = rendered_difference(table, start.model(), ref_judge)
        return start, diff
    judged = {}
    for mode in MODES:
        cand = _fit_candidate(start, mode, ref_fit, max_nfev)
        judged[mode] = (cand, rendered_difference(table, cand.model(), ref_judge))
    unrefined = pure(start)
    judged["start"] = (unrefined, rendered_difference(table, unrefined.model(), ref_judge))
    best_pure = min((judged["dielectric"], judged["metal"], judged["start"]),
                    key=lambda c: c[1].value)
    # The best pure candidate refined once more on blurred images (BLUR_PX): a highlight's
    # shape counts, a few pixels of a sharp spike less, as in HDR-FLIP's spatial filtering.
    kind = "metal" if best_pure[0].metallic == 1.0 else "dielectric"
    soft = _fit_candidate(best_pure[0], kind, ref_fit, max_nfev, BLUR_PX)
    judged["blurred"] = (soft, rendered_difference(table, soft.model(), ref_judge))
    if judged["blurred"][1].value < BLUR_MARGIN * best_pure[1].value:
        best_pure = judged["blurred"]
    blend = judged["blend"]
    p, diff = blend if blend[1].value < BLEND_MARGIN * best_pure[1].value else best_pure
    # Last, the chosen candidate polished on the rendered difference itself (POLISH_NFEV):
    # the square-root residuals weigh every pixel alike, HDR-FLIP does not (docs/export.md,
    # "The fitter, not the model": the Al blend's sharp streak).
    if flip_available() and polish_nfev > 0 and diff.value > POLISH_ABOVE:
        polished = _polish_flip(p, ref_fit, polish_nfev)
        polished_diff = rendered_difference(table, polished.model(), ref_judge)
        if polished_diff.value < POLISH_MARGIN * diff.value:
            p, diff = polished, polished_diff
    quality: dict[str, Any] = dict(fit_metrics(bm.tabulate(p.model(), np.float64), table))
    quality.update(seconds=round(time.perf_counter() - t0 + float(
        start.metrics.get("seconds", 0.0)), 3), rendered=diff.as_dict(), fit="rendered",
        table_fit_log_rmse=start.metrics.get("log_rmse"))
    return Principled(p.base_color, p.metallic, p.specular, p.alpha_t, p.alpha_b,
                      p.direction_deg, p.channels, quality, p.specular_weight), diff


def fit_f82(table: BRDFTable, fit: Principled) -> Principled:
    """``fit`` with OpenPBR's F82 tint per channel when it helps (module docstring).

    Parameters
    ----------
    table : BRDFTable, 1/sr, three channels
    fit : Principled
        The rendered fit (:func:`fit_principled_rendered`). A dielectric or a blend, or a
        table of other channels, is returned as it is: the tint bends a metal's curve.

    Returns
    -------
    Principled
        With ``f82_tint`` and its own ``metrics`` (as :func:`fit_principled_rendered`'s,
        ``fit`` = "rendered+f82", ``schlick_rendered`` and ``schlick_log_rmse`` the fit's
        without it), or ``fit`` itself when the tint does not help (module docstring).
    """
    if fit.metallic < 1.0 or table.n_channels != 3:
        return fit
    t0 = time.perf_counter()
    cand = Principled(fit.base_color, 1.0, fit.specular, fit.alpha_t, fit.alpha_b,
                      fit.direction_deg, fit.channels, {}, 1.0, fit_f82_tint(table, fit))
    table_metrics: dict[str, Any] = dict(fit_metrics(bm.tabulate(cand.model(), np.float64),
                                                     table))
    before_log = fit.metrics.get("log_rmse")
    if before_log is None:
        before_log = fit_metrics(bm.tabulate(fit.model(), np.float64), table)["log_rmse"]
    ref_judge = render_views(table)
    diff = rendered_difference(table, cand.model(), ref_judge)
    before = fit.metrics.get("rendered", {}).get("value")
    if before is None:
        before = rendered_difference(table, fit.model(), ref_judge).value
    if table_metrics["log_rmse"] >= before_log or diff.value > before + F82_RENDER_SLACK:
        return fit
    table_metrics.update(seconds=round(time.perf_counter() - t0, 3), rendered=diff.as_dict(),
                         fit="rendered+f82", schlick_rendered=before,
                         schlick_log_rmse=before_log)
    return Principled(cand.base_color, 1.0, cand.specular, cand.alpha_t, cand.alpha_b,
                      cand.direction_deg, cand.channels, table_metrics, 1.0, cand.f82_tint)
