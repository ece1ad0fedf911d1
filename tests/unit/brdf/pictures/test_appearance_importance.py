"""Which grid cells the standard renderings look at (appearance.render_importance)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.pictures import appearance, render
from gonio.brdf.tables import geometry as geo


def _centre_view(theta_deg: float, phi_deg: float) -> tuple[render.View, ...]:
    return (render.View("sphere", render.PointLight(theta_deg, phi_deg)),)


@pytest.mark.parametrize(("theta", "phi", "node"), [(40.0, 0.0, (4, 4, 0)),
                                                    (30.0, 90.0, (3, 3, 0)),
                                                    (70.0, 45.0, (7, 7, 0))])
def test_the_centre_pixel_sees_half_the_light_angle(theta: float, phi: float,
                                                    node: tuple[int, int, int]) -> None:
    """A one-pixel sphere is its centre (normal = view). The half vector lies halfway between
    view and light, so th = td = theta / 2, and view, light and normal share a plane, so the
    difference vector lies in the plane of incidence: pd = 0."""
    imp = appearance.render_importance(_centre_view(theta, phi), size=1)
    want = np.zeros(geo.SLICE_SHAPE)
    want[node] = 1.0
    np.testing.assert_allclose(imp, want, atol=1e-9)


def test_a_light_between_nodes_is_shared_by_their_multilinear_weights() -> None:
    """55 degrees: th = td = 27.5, halfway between the 25 and 30 degree nodes on both axes."""
    imp = appearance.render_importance(_centre_view(55.0, 0.0), size=1)
    want = np.zeros(geo.SLICE_SHAPE)
    for i in (5, 6):
        for j in (5, 6):
            want[i, j, 0] = 0.25
    np.testing.assert_allclose(imp, want, atol=1e-9)


def _tent(u: float, n: int, periodic: bool) -> np.ndarray:
    """1-D multilinear weights of a point ``u`` (in node units) on ``n`` nodes."""
    i = np.arange(n, dtype=float)
    d = np.abs(u - i)
    if periodic:
        d = np.minimum(d, n - d)
    w = np.maximum(0.0, 1.0 - d)
    if not periodic and u > n - 1:  # past the last node: the last node's value
        w[:] = 0.0
        w[-1] = 1.0
    return w


def _by_hand(size: int, theta_deg: float, phi_deg: float) -> np.ndarray:
    """The map from the scene's geometry, written with vectors in image space: each pixel
    centre's normal on the unit sphere (one pixel of margin), its tangent the image x axis
    projected on the tangent plane, light and view; the half vector; th, td from dot
    products; pd the angle of the light about the half vector from the (normal, half) plane."""
    out = np.zeros(geo.SLICE_SHAPE)
    v = np.array([0.0, 0.0, 1.0])
    th_l, ph_l = math.radians(theta_deg), math.radians(phi_deg)
    light = np.array([math.sin(th_l) * math.cos(ph_l), math.sin(th_l) * math.sin(ph_l),
                      math.cos(th_l)])
    scale = 1.0 + 2.0 / size
    for row in range(size):
        for col in range(size):
            x = ((col + 0.5) / size * 2 - 1) * scale
            y = -((row + 0.5) / size * 2 - 1) * scale
            if x * x + y * y >= 1.0:
                continue
            n = np.array([x, y, math.sqrt(1 - x * x - y * y)])
            if n @ light <= 0:
                continue
            h = (light + v) / np.linalg.norm(light + v)
            th = math.acos(np.clip(n @ h, -1, 1))
            td = math.acos(np.clip(light @ h, -1, 1))
            flat = h - (n @ h) * n  # the half vector's direction along the surface
            if np.linalg.norm(flat) < 1e-12:
                t = np.array([1.0, 0.0, 0.0]) - x * n
                flat = t / np.linalg.norm(t)
            else:
                flat = flat / np.linalg.norm(flat)
            xh = math.cos(th) * flat - math.sin(th) * n  # in the (normal, half) plane, _|_ h
            yh = np.cross(h, xh)
            pd = math.atan2(light @ yh, light @ xh) % math.pi
            w = np.einsum("i,j,k->ijk", _tent(math.degrees(th) / 5, geo.N_TH, False),
                          _tent(math.degrees(td) / 5, geo.N_TD, False),
                          _tent(math.degrees(pd) / 5, geo.N_PD, True))
            out += w
    return out


@pytest.mark.parametrize(("theta", "phi"), [(20.0, 135.0), (55.0, 0.0), (70.0, 45.0)])
def test_every_pixel_lands_where_the_geometry_puts_it(theta: float, phi: float) -> None:
    size = 12
    got = appearance.render_importance(_centre_view(theta, phi), size=size)
    want = _by_hand(size, theta, phi)
    assert want.sum() > 20  # the light reaches a good part of the small sphere
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_the_standard_map_counts_every_lit_pixel_of_the_four_views() -> None:
    size = appearance.APPEARANCE_SIZE
    _mask, normals = render.sphere_normals(size)
    lit = sum(int(np.sum(normals @ lt.direction() > 0)) for lt in appearance.APPEARANCE_LIGHTS)
    imp = appearance.render_importance()
    assert imp.shape == geo.SLICE_SHAPE and np.all(imp >= 0)
    assert imp.sum() == pytest.approx(lit, rel=1e-12)
