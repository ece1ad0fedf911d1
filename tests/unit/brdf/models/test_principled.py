"""Principled parameters fitted to tables: library materials with known parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.models import principled as pr


def _known(name: str) -> tuple[float, float]:
    """Burley roughness and rough-axis direction (deg, mod 180) of a library GGX material,
    from its recipe: r = (ax ay)^(1/4); the rough axis is x turned by the material's angle,
    or y when alpha_y is the larger."""
    mat = library.get_material(name)
    assert isinstance(mat, bm.Rotated) and isinstance(mat.model, bm.GGX)
    ax, ay = mat.model.alpha_x, mat.model.alpha_y
    return (ax * ay) ** 0.25, (math.degrees(mat.angle) + (90.0 if ay > ax else 0.0)) % 180.0


@pytest.mark.parametrize("name", ["brushed-metal-003", "metal-007", "brushed-metal-012"])
def test_library_roughness_and_direction(name: str) -> None:
    r_true, dir_true = _known(name)
    fit = pr.fit_principled(bm.tabulate(library.get_material(name), dtype=np.float64))
    assert fit.roughness == pytest.approx(r_true, rel=0.10)
    diff = (fit.direction_deg - dir_true + 90.0) % 180.0 - 90.0
    assert abs(diff) <= 5.0
    assert fit.metallic > 0.9  # conductors
    assert {"rel_mse", "mape", "psnr", "log_rmse", "seconds"} <= set(fit.metrics)


def test_recovers_its_own_model() -> None:
    truth = pr.Principled((0.6, 0.3, 0.1), 0.0, 0.5, 0.30, 0.12, 40.0)
    fit = pr.fit_principled(bm.tabulate(truth.model(), dtype=np.float64))
    np.testing.assert_allclose(fit.base_color, truth.base_color, atol=0.03)
    assert fit.metallic == pytest.approx(0.0, abs=0.05)
    assert fit.alpha_t == pytest.approx(0.30, rel=0.05)
    assert fit.alpha_b == pytest.approx(0.12, rel=0.05)
    assert abs((fit.direction_deg - 40.0 + 90) % 180 - 90) < 2.0
    assert fit.metrics["log_rmse"] < 0.01


def test_parameters_and_round_trip() -> None:
    p = pr.Principled((0.5, 0.5, 0.5), 1.0, 0.5, 0.4, 0.1, 200.0)
    assert p.direction_deg == pytest.approx(20.0)
    assert p.roughness == pytest.approx((0.4 * 0.1) ** 0.25)
    # Burley: alpha_b / alpha_t = aspect^2 = 1 - 0.9 anisotropy
    assert p.anisotropy == pytest.approx((1 - 0.25) / 0.9)
    assert p.f0 == pytest.approx((0.5, 0.5, 0.5))
    assert pr.Principled.from_dict(p.as_dict()) == p
    with pytest.raises(pr.PrincipledError, match="rougher axis"):
        pr.Principled((0.5, 0.5, 0.5), 0.0, 0.5, 0.1, 0.4, 0.0)
    with pytest.raises(pr.PrincipledError, match="metallic"):
        pr.Principled((0.5, 0.5, 0.5), 1.5, 0.5, 0.4, 0.1, 0.0)
    with pytest.raises(pr.PrincipledError, match="malformed"):
        pr.Principled.from_dict({"base_color": [0.5]})


def test_specular_strength_and_weight_round_trip_and_bounds() -> None:
    p = pr.Principled((0.4, 0.1, 0.1), 0.0, 11.0, 0.3, 0.06, 20.0, specular_weight=0.6)
    assert p.dielectric_f0 == pytest.approx(0.6 * 0.08 * 11.0)
    assert pr.Principled.from_dict(p.as_dict()) == p
    old = p.as_dict()
    del old["specular_weight"]  # a result stored before the weight existed
    assert pr.Principled.from_dict(old).specular_weight == 1.0
    with pytest.raises(pr.PrincipledError, match="specular ="):
        pr.Principled((0.5, 0.5, 0.5), 0.0, 13.0, 0.2, 0.2, 0.0)  # F0 = 1.04
    with pytest.raises(pr.PrincipledError, match="specular_weight"):
        pr.Principled((0.5, 0.5, 0.5), 0.0, 0.5, 0.2, 0.2, 0.0, specular_weight=1.2)


@pytest.mark.parametrize("metallic", [0.0, 0.3, 1.0])
def test_model_is_gltfs_metallic_roughness_brdf(metallic: float) -> None:
    """gonio's principled model is glTF 2.0's BRDF (Appendix B) with
    ``KHR_materials_specular``, written here from the specification:
    ``mix(dielectric_brdf, metal_brdf, metallic)``, ``dielectric_brdf = fresnel_mix(...) =
    weight fr S + (1 - weight max_value(fr)) base / pi`` with ``fr = f0 + (1 - f0)(1 -
    v.h)^5``, ``f0 = min(0.04 specularColor, 1)``, and ``metal_brdf = (base + (1 - base)(1 -
    v.h)^5) S``, ``S`` the GGX lobe without Fresnel."""
    base, level, weight = np.array([0.5, 0.2, 0.1]), 0.88, 0.6
    p = pr.Principled(tuple(base), metallic, level / 0.08, 0.3, 0.06, 20.0,
                      specular_weight=weight)
    rng = np.random.default_rng(3)
    w = rng.normal(size=(2, 500, 3))
    w[..., 2] = np.abs(w[..., 2]) + 0.05
    wi, wo = w / np.linalg.norm(w, axis=-1, keepdims=True)
    lobe = bm.Rotated(bm.GGX(0.3, 0.06, bm.SchlickFresnel((1.0, 1.0, 1.0)), "separable"),
                      math.radians(20.0))
    s = lobe.eval(wi, wo)[:, 0:1]
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    k = (1.0 - np.sum(wo * h, axis=-1, keepdims=True)) ** 5
    fr = level + (1.0 - level) * k
    dielectric = weight * fr * s + (1.0 - weight * fr) * base / np.pi
    metal = (base + (1.0 - base) * k) * s
    expected = (1.0 - metallic) * dielectric + metallic * metal
    np.testing.assert_allclose(p.model().eval(wi, wo), expected, rtol=1e-9, atol=1e-12)
