"""Laws every analytic BRDF model must obey: reciprocity, energy, rotation, anisotropy."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import from_function

CONDUCTOR = bm.ConductorFresnel((0.2, 0.92, 1.1), (3.9, 2.45, 2.2))  # gold-like, per RGB channel

# Models with every reflectance parameter at its maximum: if any of these reflects more than
# it receives, so would some library material.
PHYSICAL: dict[str, bm.BRDFModel] = {
    "lambert": bm.Lambert(1.0),
    "ggx-mirror-correlated": bm.GGX(0.08, 0.08, bm.SchlickFresnel(1.0)),
    "ggx-aniso-separable": bm.GGX(0.05, 0.4, bm.SchlickFresnel(1.0), "separable"),
    "ggx-rough": bm.GGX(1.0, 1.0, bm.SchlickFresnel(1.0)),
    "ggx-conductor": bm.GGX(0.15, 0.3, CONDUCTOR),
    "ggx-dielectric": bm.GGX(0.2, 0.2, bm.DielectricFresnel(1.5)),
    "ward": bm.Ward(0.1, 0.3, 1.0),
    "ward-rough": bm.Ward(0.6, 0.6, 1.0),
    "ashikhmin-shirley": bm.AshikhminShirley(50.0, 800.0, 1.0, 0.0),
    "ashikhmin-shirley-diffuse": bm.AshikhminShirley(10.0, 10.0, 0.05, 1.0),
    "sheen": bm.Sheen(1.0, 0.3),
    "sheen-soft": bm.Sheen(1.0, 1.0),
    "retro": bm.RetroReflective(0.1, 1.0),
    "principled-metal": bm.principled((1.0, 0.8, 0.5), 1.0, 0.3),
    "paint": bm.LobeSum(
        (bm.Lambert((0.7, 0.2, 0.1)), bm.GGX(0.1, 0.1, bm.DielectricFresnel(1.5))),
        weights=((0.96,), (1.0,)),
    ),
    "tilted-lambert": bm.Tilted(bm.Lambert(1.0), 0.5, 0.3),
    "tilted-ggx": bm.Tilted(bm.GGX(0.1, 0.3, bm.SchlickFresnel(1.0)), 0.35, 2.0),
    "tilted-sheen": bm.Tilted(bm.Sheen(1.0, 0.5), 0.6, -1.0),
}

ALL: dict[str, bm.BRDFModel] = {
    **PHYSICAL,
    "principled-plastic": bm.principled((0.9, 0.2, 0.1), 0.0, 0.5),
    "rotated-ggx": bm.Rotated(bm.GGX(0.1, 0.5, CONDUCTOR), 0.7),
    "rotated-sum": bm.Rotated(bm.LobeSum((bm.Lambert(0.3), bm.Ward(0.05, 0.3, 0.2))), -2.0),
}


def random_upper(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) directions uniform on the upper hemisphere, kept off the exact horizon."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("name", sorted(ALL))
def test_reciprocity(name: str) -> None:
    model = ALL[name]
    rng = np.random.default_rng(1)
    wi, wo = random_upper(2000, rng), random_upper(2000, rng)
    a, b = model.eval(wi, wo), model.eval(wo, wi)
    assert a.shape == (2000, 3)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", sorted(ALL))
def test_values_finite_nonnegative_and_zero_below_horizon(name: str) -> None:
    model = ALL[name]
    rng = np.random.default_rng(2)
    wi, wo = random_upper(500, rng), random_upper(500, rng)
    f = model.eval(wi, wo)
    assert np.isfinite(f).all() and (f >= 0).all()
    below = wo * np.array([1.0, 1.0, -1.0])
    assert (model.eval(wi, below) == 0).all()
    assert (model.eval(below, wi) == 0).all()


@pytest.mark.parametrize("name", sorted(ALL))
def test_eval_keeps_leading_shape(name: str) -> None:
    model = ALL[name]
    wi = geo.spherical_to_direction(np.full((4, 5), 0.3), np.linspace(0, 6, 20).reshape(4, 5))
    wo = geo.spherical_to_direction(np.full((4, 5), 0.5), 1.0)
    f = model.eval(wi, wo)
    assert f.shape == (4, 5, 3)
    np.testing.assert_allclose(f.reshape(20, 3), model.eval(wi.reshape(20, 3), wo.reshape(20, 3)))


@pytest.mark.parametrize("name", sorted(PHYSICAL))
@pytest.mark.parametrize("theta_deg", [0.0, 40.0, 70.0, 85.0])
def test_energy_conservation(name: str, theta_deg: float) -> None:
    wi = geo.spherical_to_direction(np.deg2rad(theta_deg), 0.4)
    albedo = bm.directional_albedo(PHYSICAL[name], wi)
    assert (albedo <= 1.0 + 1e-2).all(), albedo
    assert (albedo > 0).all()


def test_principled_dielectric_conserves_energy_away_from_grazing() -> None:
    """The 004 mapping adds the diffuse term without taking the specular share out of it, so
    a bright dielectric exceeds 1 only near grazing incidence (documented in the docstring)."""
    model = bm.principled((0.9, 0.9, 0.9), 0.0, 0.5)
    for theta_deg in (0.0, 40.0, 60.0):
        wi = geo.spherical_to_direction(np.deg2rad(theta_deg), 0.0)
        assert (bm.directional_albedo(model, wi) <= 1.0).all()


def test_quadrature_agrees_with_monte_carlo() -> None:
    """The half-vector quadrature used above matches plain cosine-weighted Monte Carlo."""
    model = bm.GGX(0.4, 0.7, CONDUCTOR)
    wi = geo.spherical_to_direction(np.deg2rad(50.0), 1.0)
    rng = np.random.default_rng(7)
    u1, u2 = rng.random(400_000), rng.random(400_000)
    # Cosine-weighted hemisphere samples: pdf = cos / pi, so the estimator is pi * mean(f).
    wo = geo.spherical_to_direction(np.arcsin(np.sqrt(u1)), 2 * np.pi * u2)
    f = model.eval(np.broadcast_to(wi, wo.shape), wo)
    mc = np.pi * f.mean(axis=0)
    err = np.pi * f.std(axis=0) / math.sqrt(len(u1))
    quad = bm.directional_albedo(model, wi)
    assert (np.abs(quad - mc) < 4 * err + 1e-3).all(), (quad, mc, err)


@pytest.mark.parametrize("rho", [0.0, 0.18, 0.5, 0.97])
def test_lambert_albedo_equals_rho(rho: float) -> None:
    model = bm.Lambert((rho, rho / 2, 1.0 - rho))
    for theta in (0.0, 0.6, 1.3):
        albedo = bm.directional_albedo(model, geo.spherical_to_direction(theta, 2.0))
        np.testing.assert_allclose(albedo, [rho, rho / 2, 1.0 - rho], atol=2e-4)


def test_ward_albedo_bounded_by_rho_s() -> None:
    model = bm.Ward(0.2, 0.2, (0.3, 0.6, 0.9))
    for theta in (0.0, 0.7, 1.4):
        albedo = bm.directional_albedo(model, geo.spherical_to_direction(theta, 0.0))
        assert (albedo <= np.array([0.3, 0.6, 0.9]) + 1e-3).all()


@pytest.mark.parametrize(("ax", "ay"), [(0.1, 0.1), (0.05, 0.4), (0.6, 0.2)])
def test_ggx_distribution_is_normalised(ax: float, ay: float) -> None:
    """The projected microfacet area equals the macro surface: int D(h) cos th dh = 1."""
    n_t, n_p = 4000, 720
    t = (np.arange(n_t) + 0.5) * (np.pi / 2 / n_t)
    p = (np.arange(n_p) + 0.5) * (2 * np.pi / n_p)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    h = geo.spherical_to_direction(tt.ravel(), pp.ravel())
    integrand = bm.ggx_ndf(h, ax, ay) * h[:, 2] * np.sin(tt.ravel())
    total = integrand.sum() * (np.pi / 2 / n_t) * (2 * np.pi / n_p)
    assert total == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("name", sorted(ALL))
def test_rotation_law(name: str) -> None:
    """Turning the specimen by a equals evaluating the model at directions turned by -a."""
    model = ALL[name]
    rng = np.random.default_rng(3)
    wi, wo = random_upper(300, rng), random_upper(300, rng)
    for angle in (0.3, np.pi / 2, 4.0):
        turned = bm.Rotated(model, angle)
        np.testing.assert_allclose(
            turned.eval(geo.rotate_z(wi, angle), geo.rotate_z(wo, angle)),
            model.eval(wi, wo), rtol=1e-9, atol=1e-12,
        )


def test_rotated_matches_table_rotation_on_grid() -> None:
    model = bm.GGX(0.08, 0.35, CONDUCTOR)
    angle = np.deg2rad(35.0)
    a = bm.tabulate(bm.Rotated(model, angle), dtype=np.float64)
    b = bm.tabulate(model, dtype=np.float64).rotated(angle)
    np.testing.assert_allclose(a.values, b.values, rtol=1e-9, equal_nan=True)


@pytest.mark.parametrize(
    "model",
    [
        bm.GGX(0.1, 0.4, bm.SchlickFresnel(0.9)),
        bm.Ward(0.1, 0.4, 0.5),
        bm.AshikhminShirley(200.0, 12.5, 0.5),  # nu large = sharp along x, like alpha_x small
    ],
    ids=["ggx", "ward", "ashikhmin-shirley"],
)
def test_anisotropy_is_present(model: bm.BRDFModel) -> None:
    """With the narrow axis along x, a half vector tilted toward x is less likely than one
    tilted by the same angle toward y."""
    tilt = np.deg2rad(15.0)
    td, pd = np.deg2rad(20.0), 0.3
    wi_x, wo_x = geo.half_diff_to_directions(tilt, 0.0, td, pd)
    wi_y, wo_y = geo.half_diff_to_directions(tilt, np.pi / 2, td, pd)
    fx = model.eval(wi_x[None], wo_x[None])[0]
    fy = model.eval(wi_y[None], wo_y[None])[0]
    assert (fy > 2 * fx).all()
    assert not getattr(model, "isotropic", True)
    valid = bm.tabulate(model).values[:, :, geo.valid_mask()]  # (C, 72 ph, n_valid)
    spread = valid.max(axis=1) - valid.min(axis=1)
    assert spread.max() > 0.1 * valid.max()


def test_isotropic_models_have_no_ph_dependence() -> None:
    model = bm.GGX(0.2, 0.2, bm.DielectricFresnel(1.5))
    rng = np.random.default_rng(4)
    wi, wo = random_upper(200, rng), random_upper(200, rng)
    np.testing.assert_allclose(
        model.eval(geo.rotate_z(wi, 1.1), geo.rotate_z(wo, 1.1)), model.eval(wi, wo), rtol=1e-9
    )


@pytest.mark.parametrize(
    "model",
    [
        bm.principled((0.8, 0.5, 0.2), 0.3, 0.4),
        bm.Sheen((0.2, 0.3, 0.4), 0.4),
        bm.Rotated(bm.GGX(0.05, 0.3, CONDUCTOR), 0.4),
    ],
    ids=["principled", "sheen", "anisotropic"],
)
def test_fast_tabulation_matches_the_reference_tabulation(model: bm.BRDFModel) -> None:
    """The batched / single-slice shortcuts equal table.from_function cell by cell."""
    fast = bm.tabulate(model, dtype=np.float64)
    full = from_function(model.eval, model.channels, model.name, dtype=np.float64)
    np.testing.assert_allclose(fast.values, full.values, rtol=1e-9, atol=1e-12, equal_nan=True)
    assert json.loads(json.dumps(fast.provenance))["model"] == bm.to_dict(model)
    compact = bm.tabulate_valid(model)
    assert compact.shape[1] == (1 if getattr(model, "isotropic", False) else geo.N_PH)


def test_tabulate_returns_float32_table_named_after_model() -> None:
    table = bm.tabulate(bm.Lambert(0.4, name="grey"))
    assert table.values.dtype == np.float32
    assert table.name == "grey" and table.channels == ("R", "G", "B")
    np.testing.assert_allclose(table.values[:, :, geo.valid_mask()], 0.4 / np.pi, rtol=1e-6)


def test_fresnel_limits() -> None:
    c = np.array([1.0, 0.0])
    n = 1.5
    np.testing.assert_allclose(
        bm.DielectricFresnel(n).reflectance(c, 1)[:, 0], [((n - 1) / (n + 1)) ** 2, 1.0], atol=1e-12
    )
    eta, k = (0.2, 1.1), (3.9, 2.2)
    normal = [((e - 1) ** 2 + kk**2) / ((e + 1) ** 2 + kk**2) for e, kk in zip(eta, k, strict=True)]
    got = bm.ConductorFresnel(eta, k).reflectance(c, 2)
    np.testing.assert_allclose(got[0], normal, atol=1e-12)
    np.testing.assert_allclose(got[1], [1.0, 1.0], atol=1e-12)
    schlick = bm.SchlickFresnel((0.3, 0.7)).reflectance(c, 2)
    np.testing.assert_allclose(schlick, np.array([[0.3, 0.7], [1.0, 1.0]]))


def test_conductor_fresnel_matches_complex_fresnel_equations() -> None:
    eta, k = np.array([0.2, 1.5, 3.1]), np.array([3.9, 7.7, 3.3])
    cos_t = np.linspace(0.0, 1.0, 101)
    n = (eta + 1j * k)[None, :]
    c = cos_t[:, None]
    root = np.sqrt(n**2 - (1.0 - c**2))
    rs = np.abs((c - root) / (c + root)) ** 2
    rp = np.abs((n**2 * c - root) / (n**2 * c + root)) ** 2
    got = bm.ConductorFresnel(tuple(eta), tuple(k)).reflectance(cos_t, 3)
    np.testing.assert_allclose(got, 0.5 * (rs + rp), rtol=1e-10, atol=1e-12)


def test_principled_mapping() -> None:
    metal = bm.principled((0.9, 0.6, 0.3), 1.0, 0.5)
    diffuse, spec = metal.lobes
    assert diffuse.albedo == (0.0, 0.0, 0.0)  # metals have no diffuse term
    assert spec.fresnel.f0 == pytest.approx((0.9, 0.6, 0.3))
    assert spec.alpha_x == spec.alpha_y == pytest.approx(0.25)
    assert spec.masking == "separable"
    plastic = bm.principled((0.9, 0.6, 0.3), 0.0, 0.2)
    assert plastic.lobes[1].fresnel.f0 == pytest.approx((0.04,) * 3)
    assert plastic.lobes[0].albedo == pytest.approx((0.9, 0.6, 0.3))


@pytest.mark.parametrize("name", sorted(ALL))
def test_serialisation_round_trip(name: str) -> None:
    model = ALL[name]
    text = json.dumps(bm.to_dict(model))
    rebuilt = bm.from_dict(json.loads(text))
    assert rebuilt == model
    rng = np.random.default_rng(5)
    wi, wo = random_upper(50, rng), random_upper(50, rng)
    np.testing.assert_array_equal(rebuilt.eval(wi, wo), model.eval(wi, wo))


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: bm.Lambert(1.2), r"Lambert.albedo = 1.2 is outside"),
        (lambda: bm.Lambert((0.1, 0.2)), r"2 values given for 3 channels"),
        (lambda: bm.GGX(0.0, 0.1), r"GGX.alpha_x = 0.0 is outside"),
        (
            lambda: bm.GGX(0.1, 0.1, masking="smith"),  # type: ignore[arg-type]
            r"use 'correlated' or 'separable'",
        ),
        (lambda: bm.GGX(0.1, 0.1, bm.SchlickFresnel((0.1, 0.2))), r"2 values given for 3 channels"),
        (lambda: bm.ConductorFresnel((0.2, 0.3), (1.0,)), r"one \(eta, k\) pair per channel"),
        (lambda: bm.DielectricFresnel(0.5), r"DielectricFresnel.ior = 0.5"),
        (lambda: bm.Sheen(0.5, 0.0), r"Sheen.roughness = 0.0"),
        (lambda: bm.Ward(0.1, 0.1, -0.1), r"Ward.rho_s = -0.1"),
        (lambda: bm.AshikhminShirley(0.5, 10.0), r"AshikhminShirley.nu = 0.5"),
        (lambda: bm.LobeSum(()), r"at least one lobe"),
        (
            lambda: bm.LobeSum((bm.Lambert(0.5, channels=("Y",)),)),
            r"build every lobe with the same channels",
        ),
        (
            lambda: bm.LobeSum((bm.Lambert(0.5),), weights=((1.0,), (1.0,))),
            r"2 weights for 1 lobes",
        ),
        (lambda: bm.Rotated("lambert", 0.1), r"is not a BRDF model"),
        (lambda: bm.Rotated(bm.Lambert(0.5), math.inf), r"finite angle"),
        (lambda: bm.Tilted(bm.Lambert(0.5), 1.5, 0.0), r"Tilted.tilt = 1.5 is outside"),
        (lambda: bm.Tilted(bm.Lambert(0.5), 0.2, math.nan), r"finite angle"),
        (lambda: bm.Tilted("lambert", 0.2), r"is not a BRDF model"),
        (lambda: bm.Tilted(bm.Lambert(0.5), 0.2, 0.0, "bumps"),  # type: ignore[arg-type]
         r"use 'sawtooth' or 'none'"),
        (lambda: bm.principled(0.5, 1.5, 0.5), r"principled.metallic = 1.5"),
        (lambda: bm.from_dict({"type": "Phong"}), r"unknown model type 'Phong'"),
        (lambda: bm.from_dict({"type": "Lambert", "colour": 0.5}), r"bad parameters for Lambert"),
    ],
)
def test_bad_parameters_are_reported(build: object, message: str) -> None:
    with pytest.raises(bm.ModelError, match=message):
        build()  # type: ignore[operator]


@pytest.mark.parametrize(("t", "b"), [(0.3, 1.0), (1.1, -2.5), (0.05, 4.0), (0.7, 0.0)])
def test_facet_rotation_is_rodrigues_rotation_of_the_normal_onto_z(t: float, b: float) -> None:
    """Against Rodrigues' rotation written out for vectors, ``v cos t + (k x v) sin t +
    k (k . v)(1 - cos t)`` with ``k = n x z / |n x z|``, and against the composition
    ``Rz(b) Ry(-t) Rz(-b)`` (lean back about the level axis at right angles to ``b``)."""
    R = bm.facet_rotation(t, b)
    n = np.array([math.sin(t) * math.cos(b), math.sin(t) * math.sin(b), math.cos(t)])
    k = np.cross(n, [0.0, 0.0, 1.0])
    k /= np.linalg.norm(k)
    for j, v in enumerate(np.eye(3)):
        want = (v * math.cos(t) + np.cross(k, v) * math.sin(t)
                + k * float(k @ v) * (1.0 - math.cos(t)))
        np.testing.assert_allclose(R[:, j], want, atol=1e-14)
    np.testing.assert_allclose(R @ n, [0.0, 0.0, 1.0], atol=1e-14)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)

    def rz(a: float) -> np.ndarray:
        return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                         [0.0, 0.0, 1.0]])

    ry = np.array([[math.cos(t), 0.0, -math.sin(t)], [0.0, 1.0, 0.0],
                   [math.sin(t), 0.0, math.cos(t)]])  # Ry(-t)
    np.testing.assert_allclose(R, rz(b) @ ry @ rz(-b), atol=1e-14)
    assert np.array_equal(bm.facet_rotation(0.0, b), np.eye(3))


def test_tilted_facets_mirror_about_their_own_normal() -> None:
    """A narrow lobe on facets leaning 20 deg toward azimuth 1 rad peaks where the mirror law
    about the facet normal ``n' = (sin t cos p, sin t sin p, cos t)`` puts it."""
    t, p = np.deg2rad(20.0), 1.0
    model = bm.Tilted(bm.GGX(0.02, 0.02, bm.SchlickFresnel(1.0)), t, p)
    n = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    wi = geo.spherical_to_direction(np.deg2rad(30.0), 2.5)
    mirror = 2.0 * (wi @ n) * n - wi
    tt, pp = np.meshgrid(np.deg2rad(np.arange(0.25, 90, 0.5)), np.deg2rad(np.arange(0, 360, 0.5)))
    wo = geo.spherical_to_direction(tt.ravel(), pp.ravel())
    f = model.eval(np.broadcast_to(wi, wo.shape), wo)[:, 0]
    peak = wo[np.argmax(f)]
    assert np.degrees(np.arccos(np.clip(peak @ mirror, -1, 1))) < 1.0
    # and not at the mirror direction about the surface normal (the untilted lobe's peak)
    surface_mirror = wi * np.array([-1.0, -1.0, 1.0])
    assert np.degrees(np.arccos(np.clip(peak @ surface_mirror, -1, 1))) > 10.0


def test_untilted_facets_are_the_inner_model_and_tilted_ones_lack_twofold_symmetry() -> None:
    inner = bm.LobeSum((bm.Lambert(0.4), bm.GGX(0.1, 0.3, CONDUCTOR)))
    rng = np.random.default_rng(6)
    wi, wo = random_upper(400, rng), random_upper(400, rng)
    np.testing.assert_allclose(bm.Tilted(inner, 0.0, 1.3).eval(wi, wo), inner.eval(wi, wo),
                               rtol=1e-12)
    for model, same in ((bm.Rotated(inner, 0.7), True), (bm.Tilted(inner, 0.3, 0.7), False)):
        turned = model.eval(geo.rotate_z(wi, np.pi), geo.rotate_z(wo, np.pi))
        assert np.allclose(turned, model.eval(wi, wo), rtol=1e-9) is same
    assert not bm.Tilted(bm.Lambert(0.5), 0.2).isotropic
    assert bm.Tilted(bm.Lambert(0.5), 0.0).isotropic


def test_a_renderers_normal_map_weighs_the_view_by_its_facet_cosine() -> None:
    """``masking="none"``: a Lambert facet seen through a constant normal map reads
    ``rho / pi cos(to') / cos(to)``, ``to'`` the view's angle to the leaning normal, and 0 where
    either direction is behind the facets; the sawtooth form of the same facets is never
    brighter than ``rho / pi``."""
    t, p = 0.4, -0.8
    n = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    rng = np.random.default_rng(9)
    wi, wo = random_upper(500, rng), random_upper(500, rng)
    f = bm.Tilted(bm.Lambert(0.6), t, p, "none").eval(wi, wo)[:, 0]
    front = (wi @ n > 0) & (wo @ n > 0)
    expected = np.where(front, 0.6 / np.pi * (wo @ n) / wo[:, 2], 0.0)
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-15)
    saw = bm.Tilted(bm.Lambert(0.6), t, p).eval(wi, wo)[:, 0]
    assert (saw <= 0.6 / np.pi + 1e-12).all() and (saw[~front] == 0).all()
